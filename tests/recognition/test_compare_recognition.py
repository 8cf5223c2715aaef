"""Action recognition through the comparison runner: the NTU benchmark and the pooled-statistics baseline."""

from __future__ import annotations

import json

import numpy as np
import pytest
from omegaconf import OmegaConf

from mocapkit.cli import main
from mocapkit.datasets.ntu.cache import NTUCache
from mocapkit.datasets.ntu.splits import split_indices
from mocapkit.evaluation.compare.base import indices_sha1
from mocapkit.features.pooled import PooledJointStatistics

TINY = ["--classes", "4", "--subjects", "4", "--setups", "1", "--replications", "1", "--seed", "3", "--quiet"]


def test_pooled_statistics_by_hand():
    seq = np.zeros((2, 3, 2, 3))  # [bodies, T, joints, 3]
    seq[0, :, 0] = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]  # body 0's root moves along x
    seq[0, :, 1] = seq[0, :, 0] + [0, 1, 0]  # joint 1 one metre above it
    features = PooledJointStatistics(bodies=2).fit([seq]).transform([seq, seq[0]])
    assert features.shape == (2, 2 * 4 * 2 * 3)
    body0 = features[0, :24].reshape(4, 2, 3)  # mean, std, min, max of [joints, 3]
    np.testing.assert_allclose(body0[:, 1], [[0, 1, 0], [0, 0, 0], [0, 1, 0], [0, 1, 0]])
    np.testing.assert_allclose(body0[:, 0], 0.0)  # the root, centred on itself
    assert not features[0, 24:].any()  # body 1 absent: zeros
    np.testing.assert_allclose(features[1], features[0])  # [T, J, 3] is body 0 alone
    with pytest.raises(ValueError, match=r"\[T, J, 3\] or \[M, T, J, 3\]"):
        PooledJointStatistics().fit([np.zeros((3, 2))])


@pytest.fixture(scope="module")
def ntu_cache(tmp_path_factory):
    root = tmp_path_factory.mktemp("ntu")
    assert main(["synth", "ntu", "--out", str(root / "synth"), *TINY]) == 0
    assert main(["prepare", "ntu", "--src", str(root / "synth"), "--out", str(root / "cache"), "--quiet"]) == 0
    return root / "cache"


@pytest.mark.slow
def test_ntu_learned_run_and_baseline_score_the_same_subjects(ntu_cache, tmp_path):
    out = tmp_path / "cmp"
    assert (
        main(
            [
                "compare",
                "ntu_recognition",
                f"benchmark.root={ntu_cache}",
                f"out={out}",
                "seeds=[0]",
                "only=[energy_vgg,pooled_logreg]",
                (
                    "learned_overrides=['trainer.max_epochs=1','trainer.enable_progress_bar=false','data.batch_size=8',"
                    "'model.energy.size=32']"
                ),
            ]
        )
        == 0
    )
    saved = json.loads((out / "results.json").read_text())
    cells = {c["method"]: c for c in saved["cells"]}
    _, test = split_indices(NTUCache(ntu_cache), "ntu60_xsub")
    assert cells["energy_vgg"]["test_sha1"] == cells["pooled_logreg"]["test_sha1"] == indices_sha1(test)
    assert cells["pooled_logreg"]["metrics"]["accuracy"] > 0.25  # 4 classes: chance 25 %
    assert {"accuracy", "top5", "mean_class_accuracy"} <= set(cells["energy_vgg"]["metrics"])
    assert "pooled joint statistics" in (out / "results.md").read_text()


@pytest.mark.slow
def test_methods_differing_only_in_evaluation_share_one_run(ntu_cache, tmp_path):
    from mocapkit.evaluation.compare import (
        Comparison,
        ComparisonError,
        compose,
        run_comparison,
    )

    out = tmp_path / "cmp"
    cfg = compose(
        [
            "ntu_recognition",
            f"benchmark.root={ntu_cache}",
            f"out={out}",
            "seeds=[0]",
            (
                "learned_overrides=['trainer.max_epochs=1','trainer.enable_progress_bar=false',"
                "'data.batch_size=8','model.energy.size=32']"
            ),
        ]
    )
    plain = OmegaConf.to_container(cfg, resolve=True)
    vgg = plain["methods"]["energy_vgg"]
    plain["methods"] = {
        "energy_vgg": vgg,
        "energy_vgg_identity_view": {
            "label": "one identity view",
            "learned": {**vgg["learned"], "eval_overrides": ["eval.views={crops:[1.0],rotate_deg:[0]}"]},
        },
        "energy_vgg_views": {
            "label": "12 views",
            "learned": {**vgg["learned"], "eval_overrides": ["eval.views={crops:[1.0,0.9],rotate_deg:[0,-10,10]}"]},
        },
    }
    saved = run_comparison(plain)
    cells = {c["method"]: c for c in saved["cells"]}
    assert [cells[k]["shared_run"] for k in plain["methods"]] == [False, True, True]
    assert len({c["run_dir"] for c in cells.values()}) == 1
    assert len(list((out / "runs").glob("*/*/last.ckpt"))) == 1  # trained once
    # the identity view scores exactly what the plain evaluation scored; the 12 views were really applied
    assert cells["energy_vgg_identity_view"]["metrics"] == cells["energy_vgg"]["metrics"]
    views = json.loads(
        (
            out / "runs" / "ntu_energy_vgg" / "energy_vgg_ntu60_xsub_seed0" / "eval_energy_vgg_views" / "metrics.json"
        ).read_text()
    )["views"]
    assert views["n_views"] == 12
    plain["methods"]["energy_vgg"]["learned"]["eval_overrides"] = "eval.views=x"
    with pytest.raises(ComparisonError, match="eval_overrides"):
        Comparison(plain)
