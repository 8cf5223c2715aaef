"""``prepare_casia_b``: silhouette folders -> GEI cache, report, skip_bad, sizes and workers."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from mocapkit.datasets.casia_b.cache import GEICache
from mocapkit.datasets.casia_b.gei import GaitSequenceError, gait_energy_images
from mocapkit.datasets.casia_b.prepare import parse_gei_size, prepare_casia_b
from mocapkit.datasets.formats.casia_b import (
    GaitSequenceKey,
    SilhouetteFormatError,
    list_casia_b,
    read_sequence,
)
from tests.datasets.test_gei import walking_silhouettes

FRAMES = 60
#: The tiny data set: sequence -> gait cycle in frames (stick walkers, see ``walking_silhouettes``).
CYCLES = {
    GaitSequenceKey(1, "nm", 1, 90): 24,
    GaitSequenceKey(1, "nm", 1, 72): 24,
    GaitSequenceKey(1, "nm", 2, 90): 27,
    GaitSequenceKey(1, "bg", 1, 90): 22,
    GaitSequenceKey(2, "nm", 1, 90): 29,
    GaitSequenceKey(2, "cl", 2, 108): 20,
}


def write_sequence(root: Path, key: GaitSequenceKey, frames: np.ndarray) -> Path:
    folder = root / key.name
    folder.mkdir(parents=True, exist_ok=True)
    for t, mask in enumerate(frames, start=1):
        Image.fromarray(mask, mode="L").save(folder / key.frame_name(t))
    return folder


@pytest.fixture(scope="module")
def casia_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("casia_b")
    for i, (key, cycle) in enumerate(CYCLES.items()):
        speed = (-1.0) ** i
        write_sequence(
            root,
            key,
            walking_silhouettes(FRAMES, cycle, x0=80.0 - 30 * speed, speed=speed, scale=1.0 + 0.1 * i, phase=0.4 * i),
        )
    (root / "002" / "notes.doc").write_text("not a walk")  # a listing problem, reported
    return root


@pytest.fixture()
def bad_root(casia_root, tmp_path) -> tuple[Path, Path, GaitSequenceKey]:
    """The tiny set plus one sequence with a corrupt PNG (frame 7) and one shorter than a cycle."""
    root = tmp_path / "bad"
    shutil.copytree(casia_root, root)
    corrupt = GaitSequenceKey(1, "nm", 2, 90)
    broken = root / corrupt.name / corrupt.frame_name(7)
    broken.write_bytes(b"\x89PNG\r\n\x1a\n this is not a PNG any more")
    write_sequence(root, GaitSequenceKey(2, "nm", 3, 90), walking_silhouettes(12, 25))
    return root, broken, corrupt


def test_the_cache_holds_one_gei_per_whole_cycle_with_its_index(casia_root, tmp_path):
    report = prepare_casia_b(casia_root, tmp_path / "cache", size=(64, 44), per="cycle", progress=False)
    cache = GEICache(tmp_path / "cache")
    expected_cycles = {key.name: FRAMES // cycle for key, cycle in CYCLES.items()}
    assert len(cache) == sum(expected_cycles.values()) == report.geis_written
    assert (cache.height, cache.width) == (64, 44)
    assert cache.meta["per"] == "cycle" and cache.meta["size"] == [64, 44]
    assert cache.meta["source"] == str(casia_root.resolve())
    assert cache.meta["counts"]["geis_written"] == len(cache)
    assert report.sequences_found == report.sequences_written == len(CYCLES) and not report.skipped

    by_name = {key.name: key for key in CYCLES}
    assert sorted(set(cache.names)) == sorted(by_name)
    for name, key in by_name.items():
        rows = np.flatnonzero(cache.names == name)
        assert len(rows) == expected_cycles[name]
        np.testing.assert_array_equal(cache.cycles[rows], np.arange(len(rows)))
        assert (cache.subjects[rows] == key.subject).all() and (cache.views[rows] == key.view).all()
        assert (cache.conditions[rows] == key.condition_label).all()
        assert (cache.sequences[rows] == key.sequence).all()
        assert np.abs(cache.frames[rows] - CYCLES[key]).max() <= 1  # one detected period's silhouettes

    # The stored GEIs are the builder's, as uint8.
    listing = list_casia_b(casia_root)
    seq = next(s for s in listing.sequences if s.key == GaitSequenceKey(2, "nm", 1, 90))
    geis, info = gait_energy_images(read_sequence(seq), size=(64, 44))
    rows = np.flatnonzero(cache.names == seq.key.name)
    np.testing.assert_array_equal(cache.all_geis[rows], np.round(geis * 255).astype(np.uint8))
    np.testing.assert_array_equal(cache.frames[rows], info.frames_per_gei)
    assert cache.gei(int(rows[0])).dtype == np.float32

    # The report lists the listing's problem and the sequences the protocols will miss.
    saved = json.loads((tmp_path / "cache" / "report.json").read_text())
    assert saved["totals"]["geis_written"] == len(cache)
    assert any("notes.doc" in p for p in saved["listing_problems"])
    assert "001/cl-01/090" in saved["missing"] and "002/bg-01/072" in saved["missing"]
    assert "001/nm-01/090" not in saved["missing"]
    assert len(saved["missing"]) == 2 * 10 * 11 - len(CYCLES)
    text = (tmp_path / "cache" / "report.txt").read_text()
    assert "001/cl-01/090" in text and "notes.doc" in text


def test_thesis_size_with_one_gei_per_sequence(casia_root, tmp_path):
    report = prepare_casia_b(casia_root, tmp_path / "cache", size=(124, 124), per="sequence", progress=False)
    cache = GEICache(tmp_path / "cache")
    assert len(cache) == len(CYCLES) == report.geis_written
    assert cache.all_geis.shape == (len(CYCLES), 124, 124)
    assert (cache.cycles == 0).all() and (cache.frames == FRAMES).all()
    assert cache.meta["per"] == "sequence"
    assert "124x124" in report.summary()


def test_skip_bad_reports_a_corrupt_png_and_a_short_sequence_and_goes_on(bad_root, tmp_path):
    root, broken, corrupt = bad_root
    report = prepare_casia_b(root, tmp_path / "cache", skip_bad=True, no_period="error", progress=False)
    skipped = {s["sequence"]: s for s in report.skipped}
    assert set(skipped) == {corrupt.name, "002/nm-03/090"}
    assert skipped[corrupt.name]["reason"] == "unreadable"
    assert broken.name in skipped[corrupt.name]["message"] and "frame 7" in skipped[corrupt.name]["message"]
    assert skipped["002/nm-03/090"]["reason"] in ("too_short", "no_period")
    cache = GEICache(tmp_path / "cache")
    assert corrupt.name not in set(cache.names) and "002/nm-03/090" not in set(cache.names)
    assert report.sequences_written == len(CYCLES) - 1
    assert len(cache) == sum(FRAMES // c for k, c in CYCLES.items() if k != corrupt)
    text = (tmp_path / "cache" / "report.txt").read_text()
    assert broken.name in text and "[unreadable]" in text
    totals = json.loads((tmp_path / "cache" / "report.json").read_text())["totals"]
    assert totals["skipped_unreadable"] == 1


def test_without_skip_bad_the_first_bad_sequence_raises_naming_it(bad_root, tmp_path):
    root, broken, corrupt = bad_root
    with pytest.raises(SilhouetteFormatError, match=broken.name):
        prepare_casia_b(root, tmp_path / "cache", progress=False)
    assert not (tmp_path / "cache" / "meta.json").exists()
    shutil.rmtree(root / corrupt.name)
    with pytest.raises(GaitSequenceError, match="nm-03"):  # strict: a sequence without a period is bad
        prepare_casia_b(root, tmp_path / "cache", no_period="error", progress=False)


def test_by_default_a_sequence_without_a_period_gives_one_gei_over_the_whole_sequence(bad_root, tmp_path):
    """The documented command must not stop on sequences whose period is not detected (0° / 180° views)."""
    root, _, corrupt = bad_root
    shutil.rmtree(root / corrupt.name)
    short = "002/nm-03/090"  # 12 frames: too short to find a 25-frame cycle
    report = prepare_casia_b(root, tmp_path / "cache", progress=False)
    assert not report.skipped and report.whole_sequence == [short] and not report.fallback_period
    cache = GEICache(tmp_path / "cache")
    rows = np.flatnonzero(cache.names == short)
    assert len(rows) == 1 and cache.cycles[rows[0]] == 0 and cache.frames[rows[0]] == 12
    seq = next(s for s in list_casia_b(root).sequences if s.key.name == short)
    whole, _ = gait_energy_images(read_sequence(seq), per="sequence")
    np.testing.assert_array_equal(cache.all_geis[rows], np.round(whole * 255).astype(np.uint8))
    for key, cycle in CYCLES.items():  # the others still give one GEI per cycle
        if key != corrupt:
            assert (cache.names == key.name).sum() == FRAMES // cycle
    assert report.totals()["one_gei_per_sequence_no_period"] == 1 and cache.meta["options"]["no_period"] == "sequence"
    text = (tmp_path / "cache" / "report.txt").read_text()
    assert f"One GEI per sequence (no period detected) (1):\n  {short}\n" in text
    assert json.loads((tmp_path / "cache" / "report.json").read_text())["whole_sequence"] == [short]
    assert "1 without a detectable period, one GEI over the whole sequence" in report.summary()


def test_no_period_options_from_the_command_line(bad_root, tmp_path, capsys):
    from mocapkit.cli import main

    root, _, corrupt = bad_root
    shutil.rmtree(root / corrupt.name)
    assert main(["prepare", "casia-b", "--src", str(root), "--out", str(tmp_path / "a"), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "1 without a detectable period" in out and len(out.splitlines()) <= 4
    assert (
        main(
            ["prepare", "casia-b", "--src", str(root), "--out", str(tmp_path / "b"), "--quiet", "--no-period", "error"]
        )
        == 2
    )
    assert "nm-03" in capsys.readouterr().err
    assert (
        main(
            [
                "prepare",
                "casia-b",
                "--src",
                str(root),
                "--out",
                str(tmp_path / "c"),
                "--quiet",
                "--no-period",
                "error",
                "--skip-bad",
            ]
        )
        == 0
    )
    assert json.loads((tmp_path / "c" / "report.json").read_text())["skipped"][0]["reason"] == "no_period"
    assert (
        main(
            [
                "prepare",
                "casia-b",
                "--src",
                str(root),
                "--out",
                str(tmp_path / "d"),
                "--quiet",
                "--no-period",
                "error",
                "--fallback-period",
                "10",
            ]
        )
        == 2
    )
    assert "contradicts" in capsys.readouterr().err


def test_workers_give_the_same_cache(casia_root, tmp_path):
    prepare_casia_b(casia_root, tmp_path / "one", workers=1, progress=False)
    prepare_casia_b(casia_root, tmp_path / "two", workers=2, progress=False)
    one, two = GEICache(tmp_path / "one"), GEICache(tmp_path / "two")
    np.testing.assert_array_equal(one.all_geis, two.all_geis)
    for key in ("names", "subjects", "conditions", "sequences", "views", "cycles", "frames"):
        np.testing.assert_array_equal(getattr(one, key), getattr(two, key))


def test_subjects_filter_and_a_fallback_period(casia_root, tmp_path):
    root = tmp_path / "still"
    shutil.copytree(casia_root / "002", root / "002")
    still = np.repeat(walking_silhouettes(1, 25), FRAMES, axis=0)  # no leg motion: no period
    write_sequence(root, GaitSequenceKey(2, "nm", 4, 90), still)
    report = prepare_casia_b(root, tmp_path / "cache", fallback_period=25, subjects=[2], progress=False)
    assert report.fallback_period == ["002/nm-04/090"]
    cache = GEICache(tmp_path / "cache")
    assert set(cache.subjects) == {2}
    assert (cache.frames[cache.names == "002/nm-04/090"] == 25).all()
    with pytest.raises(GaitSequenceError, match="no gait period"):
        prepare_casia_b(root, tmp_path / "cache2", no_period="error", progress=False)
    report = prepare_casia_b(root, tmp_path / "cache3", subjects=[2], progress=False)  # the default
    assert report.whole_sequence == ["002/nm-04/090"] and not report.fallback_period
    assert (
        GEICache(tmp_path / "cache3").frames[GEICache(tmp_path / "cache3").names == "002/nm-04/090"] == FRAMES
    ).all()


def test_everything_skipped_is_an_error_after_the_report(tmp_path):
    write_sequence(tmp_path / "src", GaitSequenceKey(1, "nm", 1, 90), walking_silhouettes(10, 25))
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "meta.json").write_text("{}")  # an older cache there must not look finished
    with pytest.raises(RuntimeError, match="no GEI could be built"):
        prepare_casia_b(tmp_path / "src", tmp_path / "out", skip_bad=True, no_period="error", progress=False)
    assert json.loads((tmp_path / "out" / "report.json").read_text())["skipped"][0]["sequence"] == "001/nm-01/090"
    assert not (tmp_path / "out" / "meta.json").exists()


def test_bad_arguments_and_empty_sources_are_clear_errors(tmp_path):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        prepare_casia_b(tmp_path / "nowhere", tmp_path / "out", progress=False)
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no CASIA-B sequence"):
        prepare_casia_b(tmp_path / "empty", tmp_path / "out", progress=False)
    for kwargs, match in (
        ({"per": "frame"}, "per must be"),
        ({"size": (64,)}, "size"),
        ({"workers": 0}, "workers"),
        ({"no_period": "skip"}, "no_period must be"),
        ({"no_period": "fallback"}, "needs fallback"),
        ({"no_period": "error", "fallback_period": 25}, "contradicts"),
        ({"fallback_period": 0}, "fallback_period must be"),
    ):
        with pytest.raises(ValueError, match=match):
            prepare_casia_b(tmp_path / "empty", tmp_path / "out", progress=False, **kwargs)


def test_parse_gei_size():
    assert parse_gei_size("64x44") == (64, 44) and parse_gei_size("124X124") == (124, 124)
    for bad in ("64", "64x", "x44", "0x44", "64x-4", "axb"):
        with pytest.raises(ValueError, match="HEIGHTxWIDTH"):
            parse_gei_size(bad)
