"""The refinement benchmark of the comparison runner (mocapkit/refinement/benchmark.py) on real HDM05 clips.

``configs/compare/refine_quick.yaml`` (2 test clips per held-out performer, every performer in turn, 2 seeds) with
one extra data-driven method, :class:`RecordingRefiner`, that records the clips it was fitted on: every
method × protocol × seed cell is written, no fit ever sees a clip of the performer it is tested on, the report and
the plots are written. Plus: linear interpolation is exact on linear trajectories through the whole pipeline
(corrupt → refine → score), and malformed protocols / empty folders fail with messages that name them.
"""

from __future__ import annotations

import importlib
import json

import numpy as np
import pytest
from omegaconf import open_dict

from mocapkit.evaluation.compare import ComparisonError, compose, run_comparison
from mocapkit.refinement.base import MotionRefiner
from mocapkit.refinement.benchmark import RefinementBenchmark, parse_protocol
from mocapkit.refinement.gap_filling import LinearInterpolation
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"

#: ``(performers of the fitted clips, clip names)`` of every ``RecordingRefiner.fit`` call in this process.
FITS: list[tuple[set, list]] = []


def recorded_fits() -> list[tuple[set, list]]:
    """:data:`FITS` of the module Hydra instantiates the refiner from (``tests.refinement.test_compare_refinement``, which
    pytest may have imported under another name)."""
    return importlib.import_module("tests.refinement.test_compare_refinement").FITS


class RecordingRefiner(MotionRefiner):
    """A data-driven stand-in: ``fit`` records the performers of its training clips; refines by linear
    interpolation (holding the ends)."""

    requires_fit = True

    def __init__(self, tag: str = "spy"):
        self.tag = tag

    def fit(self, motions=None, y=None):
        motions = list(motions or [])
        FITS.append(({m.name.split("_")[1] for m in motions}, [m.name for m in motions]))
        self.fitted_performers_ = {m.name.split("_")[1] for m in motions}
        return super().fit(motions, y)

    def _refine_matrix(self, X, observed):
        return LinearInterpolation(extrapolate="hold")._refine_matrix(X, observed)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("refine_quick")
    cfg = compose(["refine_quick", f"out={out}", f"benchmark.root={HDM05}"])
    with open_dict(cfg):
        cfg.methods["spy"] = {
            "label": "recording",
            "estimator": {"_target_": "tests.refinement.test_compare_refinement.RecordingRefiner"},
            "reseed": False,
        }
        # the same behind the median outlier screen: the wrapper's fit must follow the folds too
        cfg.methods["spy_screened"] = {
            "label": "recording, screened",
            "reseed": False,
            "estimator": {
                "_target_": "mocapkit.refinement.screening.MedianScreen",
                "refiner": {"_target_": "tests.refinement.test_compare_refinement.RecordingRefiner", "tag": "screened"},
            },
        }
    recorded_fits().clear()
    results = run_comparison(cfg)
    return out, results


@needs(HDM05)
def test_every_cell_is_written(quick):
    out, _ = quick
    saved = json.loads((out / "results.json").read_text())
    protocols = ["random_missing@0.2", "random_missing@0.4", "continuous_missing@20", "continuous_missing@40"]
    assert saved["protocols"] == protocols and saved["seeds"] == [0, 1]
    cells = {(c["method"], c["protocol"], c["seed"]) for c in saved["cells"]}
    assert cells == {
        (m, p, s) for m in ("linear", "pchip", "trnn", "spy", "spy_screened") for p in protocols for s in (0, 1)
    }
    for cell in saved["cells"]:
        detail = cell["detail"]
        assert set(detail["folds"]) == {"bd", "bk", "dg", "mm"}
        assert len(detail["clips"]) == 8 and all(f["n_test"] == 2 for f in detail["folds"].values())
        assert cell["metrics"]["coverage"] == pytest.approx(1.0)
        assert np.isfinite(cell["metrics"]["rmse_cm"]) and cell["metrics"]["rmse_cm"] >= 0
        assert cell["metrics"]["seconds"] >= 0 and cell["metrics"]["n_failed"] == 0
        assert detail["curve"]["frames"] == len(detail["curve"]["rmse_cm"])
    # every method of a (protocol, seed) saw the same clips with the same corruption seeds
    for protocol in protocols:
        for seed in (0, 1):
            seen = {
                c["method"]: [(r["clip"], r["corruption_seed"]) for r in c["detail"]["clips"]]
                for c in saved["cells"]
                if c["protocol"] == protocol and c["seed"] == seed
            }
            assert len({tuple(v) for v in seen.values()}) == 1
    # the recording refiner is linear interpolation: identical numbers
    by = {(c["method"], c["protocol"], c["seed"]): c["metrics"]["rmse_cm"] for c in saved["cells"]}
    assert all(by[("spy", p, s)] == pytest.approx(by[("linear", p, s)]) for p in protocols for s in (0, 1))


@needs(HDM05)
def test_data_driven_fits_never_see_the_test_performer(quick):
    _, results = quick
    fits = recorded_fits()
    assert fits, "the data-driven method was never fitted"
    assert len(fits) == 8  # one fit per held-out performer and method, cached across cells
    for cell in (c for c in results["cells"] if c["method"] in ("spy", "spy_screened")):
        for fold, info in cell["detail"]["folds"].items():
            assert fold not in info["fit_groups"] and info["fit_groups"] == sorted({"bd", "bk", "dg", "mm"} - {fold})
            tested = {r["clip"].split("_")[1] for r in cell["detail"]["clips"] if r["fold"] == fold}
            assert tested == {fold}
    for performers, names in fits:
        assert len(performers) == 3
        held_out = ({"bd", "bk", "dg", "mm"} - performers).pop()
        assert not any(f"HDM_{held_out}_" in n for n in names)
    for cell in (c for c in results["cells"] if c["method"] not in ("spy", "spy_screened")):
        assert all(f["fit_groups"] == [] for f in cell["detail"]["folds"].values())


@needs(HDM05)
def test_report_and_plots_are_written(quick):
    out, _ = quick
    text = (out / "results.md").read_text()
    assert "## Refinement: methods × protocols" in text
    table = text.split("## Refinement: methods × protocols")[1]
    header = "| method | random_missing@0.2 | random_missing@0.4 | continuous_missing@20 | continuous_missing@40 |"
    assert header in table
    assert table.count("**") >= 8  # a bold winner per protocol in each table
    assert "Against the interpolation baselines" in text and "TrNN beats linear interpolation on gaps" in text
    for name in ("rmse_vs_mr.png", "rmse_vs_ml.png", "rmse_curves.png", "summary.png"):
        assert (out / name).stat().st_size > 5000, name


@needs(HDM05)
def test_interpolation_is_exact_on_linear_trajectories():
    bench = RefinementBenchmark(
        "hdm05",
        str(HDM05),
        ["continuous_missing@30", "rgloss@10x60"],
        clips_per_fold=1,
        clips_per_performer=2,
        max_frames=120,
    )
    rng = np.random.default_rng(0)
    for i, motion in enumerate(bench.motions):  # every clip becomes straight lines at constant speed
        frames, joints = motion.positions.shape[:2]
        start, velocity = rng.normal(size=(1, joints, 3)), rng.normal(scale=0.01, size=(1, joints, 3))
        bench.motions[i].positions = (start + velocity * np.arange(frames)[:, None, None]).astype(np.float32)
    bench._test_cache.clear()
    for protocol in bench.protocols:
        split = bench.split(protocol, seed=3)
        scores = bench.evaluate_estimator(LinearInterpolation(), split)
        assert scores["metrics"]["coverage"] == 1.0
        assert scores["metrics"]["rmse_cm"] < 1e-4 and scores["metrics"]["mje_mm"] < 1e-3
        assert all(r["corrupted"] > 0 for r in scores["detail"]["clips"])


def test_malformed_protocols_list_the_known_ones():
    with pytest.raises(ComparisonError, match=r"known .*continuous_missing@20\|30\|40\|50\|60"):
        parse_protocol("continuous_missing")
    with pytest.raises(ComparisonError, match="'holes@3'.*random_missing@"):
        parse_protocol("holes@3")
    with pytest.raises(ComparisonError, match="random_missing@1.5"):
        parse_protocol("random_missing@1.5")
    assert parse_protocol("long_gaps@5x2s") == ("long_gaps", "5x2s")
    assert parse_protocol("continuous_missing@40") == ("continuous_missing", 40)


def test_empty_or_unreadable_data_folder_is_named(tmp_path):
    with pytest.raises(ComparisonError, match=f"{tmp_path}.*no hdm05 clip"):
        RefinementBenchmark("hdm05", str(tmp_path), ["rgloss@10x60"])
    with pytest.raises(ComparisonError, match="is not a folder"):
        RefinementBenchmark("cmu", str(tmp_path / "absent"), ["rgloss@10x60"])
    bad = tmp_path / "bd" / "HDM_bd_squat1Reps_001_120.amc"
    bad.parent.mkdir()
    bad.write_text("not an amc file\n")
    with pytest.raises(ComparisonError, match="cannot read .*HDM_bd_squat1Reps_001_120.amc"):
        RefinementBenchmark("hdm05", str(tmp_path), ["rgloss@10x60"])
