"""pyskl / MMAction2 annotation pickles: export an NTU cache, import it back, refuse bad or unsafe pickles."""

from __future__ import annotations

import collections
import json
import os
import pickle

import numpy as np
import pytest

from mocapkit.cli import main
from mocapkit.datasets.interop.pyskl import (
    PYSKL_SPLIT_FILE,
    PysklFormatError,
    export_pyskl,
    import_pyskl,
    load_pyskl,
)
from mocapkit.datasets.ntu.cache import NTUCache
from mocapkit.datasets.ntu.prepare import INDEX_KEYS, prepare_ntu
from mocapkit.datasets.ntu.splits import split_indices
from mocapkit.datasets.synthetic.ntu import NTUSynthConfig, synthesize_ntu

CACHE_FILES = {"meta.json", "index.npz", "positions.npy", "report.json", "report.txt"}


@pytest.fixture(scope="module")
def prepared(tmp_path_factory):
    """A small synthetic NTU cache (10 actions incl. the two-person A010, 3 subjects, 2 cameras) and its export."""
    root = tmp_path_factory.mktemp("pyskl")
    config = NTUSynthConfig(
        num_classes=10, num_subjects=3, setups=(1,), cameras=(1, 2), replications=(1,), length_scale=0.3
    )
    synthesize_ntu(root / "synth", config, progress=False)
    prepare_ntu(root / "synth", root / "cache", progress=False)
    summary = export_pyskl(root / "cache", root / "ntu.pkl")
    return root, summary


def load(path):
    with open(path, "rb") as f:
        return pickle.load(f)


def annotation(name: str, frames: int = 6, persons: int = 1, seed: int = 0, **changes) -> dict:
    rng = np.random.default_rng(seed)
    action = int(name[-3:])
    item = {
        "frame_dir": name,
        "label": action - 1,
        "total_frames": frames,
        "keypoint": (rng.normal(size=(persons, frames, 25, 3)) + [0, 0, 3]).astype(np.float32),
    }
    item.update(changes)
    return item


def write_pickle(path, data, protocol: int = 4):
    with open(path, "wb") as f:
        pickle.dump(data, f, protocol=protocol)
    return path


NAMES = ["S001C001P001R001A001", "S001C002P003R001A010", "S018C001P044R002A100"]


def small_pickle(tmp_path, items=None, **top):
    items = (
        [annotation(n, seed=k, persons=2 if n.endswith("A010") else 1) for k, n in enumerate(NAMES)]
        if items is None
        else items
    )
    data = {"split": {"xsub_train": NAMES[:2], "xsub_val": NAMES[2:]}, "annotations": items, **top}
    return write_pickle(tmp_path / "small.pkl", data)


# --------------------------------------------------------------------------- export


def test_export_has_the_pyskl_structure(prepared):
    root, summary = prepared
    cache = NTUCache(root / "cache")
    data = load(root / "ntu.pkl")
    assert type(data) is dict and set(data) == {"split", "annotations"}
    split = data["split"]
    assert list(split) == ["xsub_train", "xsub_val", "xview_train", "xview_val"]
    for prefix, protocol in (("xsub", "ntu60_xsub"), ("xview", "ntu60_xview")):
        train, test = split_indices(cache, protocol)
        assert split[f"{prefix}_train"] == cache.names[train].tolist()
        assert split[f"{prefix}_val"] == cache.names[test].tolist()
        assert all(type(n) is str for n in split[f"{prefix}_train"])
    assert summary["protocols"] == {"xsub": "ntu60_xsub", "xview": "ntu60_xview"}
    annotations = data["annotations"]
    assert type(annotations) is list and len(annotations) == len(cache) == summary["num_samples"]
    persons = collections.Counter()
    for i, item in enumerate(annotations):
        assert list(item) == ["frame_dir", "label", "keypoint", "total_frames"]
        assert type(item["frame_dir"]) is str and item["frame_dir"] == cache.names[i]
        assert type(item["label"]) is int and item["label"] == cache.labels[i]
        assert type(item["total_frames"]) is int and item["total_frames"] == cache.lengths[i]
        keypoint, block = item["keypoint"], cache.positions(i)
        assert type(keypoint) is np.ndarray and keypoint.dtype == np.float32 and keypoint.flags.c_contiguous
        m = keypoint.shape[0]
        assert keypoint.shape == (m, cache.lengths[i], 25, 3) and m in (1, 2)
        np.testing.assert_array_equal(keypoint, block[:m])
        assert not block[m:].any() and keypoint[-1].any()  # trailing empty bodies dropped, present ones kept
        persons[m] += 1
    assert persons[2] >= 3 and persons[1] > 0  # A010 (handshake) has two persons in every view
    assert summary["persons"] == dict(sorted(persons.items()))
    # numpy's reconstructor under the name numpy 1.x (pyskl's) and 2.x both load
    raw = (root / "ntu.pkl").read_bytes()
    assert b"numpy.core.multiarray" in raw and b"numpy._core" not in raw


# --------------------------------------------------------------------------- round trip


def test_round_trip_is_exact(prepared, tmp_path):
    root, _ = prepared
    original = NTUCache(root / "cache")
    report = import_pyskl(root / "ntu.pkl", tmp_path / "back", class_names=root / "synth" / "classes.txt")
    assert CACHE_FILES | {PYSKL_SPLIT_FILE} <= {p.name for p in (tmp_path / "back").iterdir()}
    back = NTUCache(tmp_path / "back")
    back.verify()
    for key in INDEX_KEYS:
        np.testing.assert_array_equal(getattr(back, key), getattr(original, key), err_msg=key)
    np.testing.assert_array_equal(np.asarray(back.all_positions), np.asarray(original.all_positions))
    assert back.all_positions.dtype == np.float32 and back.max_bodies == 2
    assert back.class_names == original.class_names and back.num_classes == original.num_classes == 10
    assert report.samples_written == report.annotations_found == len(original) and not report.skipped
    assert report.total_frames == int(original.lengths.sum())

    # the pickle's split is kept verbatim and compared with mocapkit's protocols
    data = load(root / "ntu.pkl")
    assert json.loads((tmp_path / "back" / PYSKL_SPLIT_FILE).read_text()) == data["split"]
    meta = json.loads((tmp_path / "back" / "meta.json").read_text())
    assert meta["pyskl_split"]["file"] == PYSKL_SPLIT_FILE
    assert meta["pyskl_split"]["lists"]["xsub_train"] == {"count": len(data["split"]["xsub_train"]), "not_imported": []}
    assert "ntu60_xsub" in meta["pyskl_split"]["agrees_with"]["xsub"]
    assert meta["pyskl_split"]["agrees_with"]["xview"] == ["ntu60_xview"]
    assert meta["options"]["imported_from"] == "pyskl" and meta["source"] == str((root / "ntu.pkl").resolve())

    # export again: the same pickle, byte for byte
    export_pyskl(tmp_path / "back", tmp_path / "again.pkl")
    assert (tmp_path / "again.pkl").read_bytes() == (root / "ntu.pkl").read_bytes()
    again = load(tmp_path / "again.pkl")
    assert again["split"] == data["split"]
    for a, b in zip(again["annotations"], data["annotations"]):
        assert a.keys() == b.keys() and np.array_equal(a["keypoint"], b["keypoint"])
        assert (a["frame_dir"], a["label"], a["total_frames"]) == (b["frame_dir"], b["label"], b["total_frames"])


def test_imported_cache_trains(prepared, tmp_path):
    from mocapkit.datasets.ntu.datamodule import NTUDataModule

    root, _ = prepared
    import_pyskl(root / "ntu.pkl", tmp_path / "back")
    assert NTUCache(tmp_path / "back").num_classes == 60  # pyskl holds no class names: NTU-60's count
    dm = NTUDataModule(str(tmp_path / "back"), split="ntu60_xview", val_fraction=0.2, batch_size=4)
    batch = next(iter(dm.train_dataloader()))
    assert batch["skeletons"].shape[:2] == (4, 2) and batch["skeletons"].shape[3:] == (25, 3)


def test_cli_round_trip(prepared, tmp_path, capsys):
    root, _ = prepared
    pkl, back = tmp_path / "cli.pkl", tmp_path / "back"
    assert main(["pyskl", "export", "--cache", str(root / "cache"), "--out", str(pkl)]) == 0
    assert "xsub_train" in capsys.readouterr().out
    assert pkl.read_bytes() == (root / "ntu.pkl").read_bytes()
    assert (
        main(
            ["pyskl", "import", "--pkl", str(pkl), "--out", str(back), "--classes", str(root / "synth" / "classes.txt")]
        )
        == 0
    )
    assert "samples_written" in capsys.readouterr().out
    np.testing.assert_array_equal(
        np.asarray(NTUCache(back).all_positions), np.asarray(NTUCache(root / "cache").all_positions)
    )
    assert main(["pyskl", "export", "--cache", str(back), "--out", str(tmp_path / "again.pkl")]) == 0
    assert (tmp_path / "again.pkl").read_bytes() == pkl.read_bytes()
    # errors are one line naming the file
    bad = write_pickle(tmp_path / "bad.pkl", {"annotations": []})
    assert main(["pyskl", "import", "--pkl", str(bad), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mocapkit: error: ") and str(bad) in err and "split" in err


# --------------------------------------------------------------------------- NTU-120, splits, variants


def test_ntu120_cache_gets_pyskl_ntu120_splits(tmp_path):
    import_pyskl(small_pickle(tmp_path), tmp_path / "c120")
    cache = NTUCache(tmp_path / "c120")
    assert cache.num_classes == 120 and cache.setups.tolist() == [1, 1, 18]
    summary = export_pyskl(tmp_path / "c120", tmp_path / "out.pkl")
    split = load(tmp_path / "out.pkl")["split"]
    assert summary["protocols"] == {"xsub": "ntu120_xsub", "xset": "ntu120_xset"}
    assert split == {"xsub_train": NAMES[:1], "xsub_val": NAMES[1:], "xset_train": NAMES[2:], "xset_val": NAMES[:2]}
    export_pyskl(tmp_path / "c120", tmp_path / "60.pkl", splits="ntu60")  # NTU-60 lists skip setup S018
    assert load(tmp_path / "60.pkl")["split"] == {
        "xsub_train": NAMES[:1],
        "xsub_val": NAMES[1:2],
        "xview_train": NAMES[1:2],
        "xview_val": NAMES[:1],
    }
    export_pyskl(tmp_path / "c120", tmp_path / "own.pkl", splits={"cs": "ntu120_xsub"})
    assert list(load(tmp_path / "own.pkl")["split"]) == ["cs_train", "cs_val"]
    for splits in ("ntu90", {"xsub": "custom"}, {"xsub": "nope"}):
        with pytest.raises(ValueError, match="splits"):
            export_pyskl(tmp_path / "c120", tmp_path / "no.pkl", splits=splits)
    assert not (tmp_path / "no.pkl").exists()


@pytest.mark.parametrize("protocol", [2, 3, 5])
def test_other_pickle_protocols_and_pyskl_variants_import(tmp_path, protocol):
    """mmcv writes protocol 2; labels may be numpy integers, dicts OrderedDicts, keypoints float64
    with keypoint_score; zero-frame samples survive."""
    items = [
        annotation(NAMES[0], keypoint_score=np.ones((1, 6, 25), np.float32), label=np.int64(0)),
        collections.OrderedDict(annotation(NAMES[1], persons=2, total_frames=np.int32(6))),
        annotation(NAMES[2], frames=0),
    ]
    items[1]["keypoint"] = items[1]["keypoint"].astype(np.float64)
    data = {"split": {"xsub_train": NAMES + ["S001C001P001R001A002"]}, "annotations": items}
    report = import_pyskl(write_pickle(tmp_path / "p.pkl", data, protocol), tmp_path / "c")
    cache = NTUCache(tmp_path / "c")
    assert cache.names.tolist() == NAMES and cache.lengths.tolist() == [6, 6, 0]
    np.testing.assert_array_equal(cache.positions(1), items[1]["keypoint"].astype(np.float32))
    np.testing.assert_array_equal(cache.positions(0)[0], items[0]["keypoint"][0])
    assert not cache.positions(0)[1].any()
    assert report.ignored_keys == {"keypoint_score": 1} and report.persons == {1: 2, 2: 1}
    on_disk = json.loads((tmp_path / "c" / "report.json").read_text())
    assert on_disk["ignored_keys"] == {"keypoint_score": 1}
    assert on_disk["pyskl_split"]["lists"]["xsub_train"]["not_imported"] == ["S001C001P001R001A002"]


def test_more_bodies_than_max_bodies(tmp_path):
    pkl = small_pickle(tmp_path, [annotation(NAMES[0], persons=3)])
    with pytest.raises(PysklFormatError, match=r"annotations\[0\].*S001C001P001R001A001.*M=3.*max_bodies=2"):
        import_pyskl(pkl, tmp_path / "c")
    import_pyskl(pkl, tmp_path / "c", max_bodies=3)
    assert NTUCache(tmp_path / "c").max_bodies == 3
    export_pyskl(tmp_path / "c", tmp_path / "out.pkl")
    assert load(tmp_path / "out.pkl")["annotations"][0]["keypoint"].shape == (3, 6, 25, 3)


# --------------------------------------------------------------------------- malformed pickles


def _set(key, value):
    def change(item):
        item[key] = value(item) if callable(value) else value
        return item

    return change


def _drop(key):
    def change(item):
        del item[key]
        return item

    return change


BAD_ITEMS = {
    "not a dict": (lambda item: [item], "expected a dict, found list"),
    "missing keypoint": (_drop("keypoint"), "missing key keypoint"),
    "missing label": (_drop("label"), "missing key label"),
    "bad name": (_set("frame_dir", "video_0001"), "not an NTU sample name"),
    "label mismatch": (_set("label", 3), "label 3 does not match the action A010"),
    "label as text": (_set("label", "9"), "does not match"),
    "3 axes": (_set("keypoint", lambda it: it["keypoint"][0]), "expected 4 axes"),
    "17 joints": (_set("keypoint", lambda it: it["keypoint"][:, :, :17]), "expected [M, T, 25, 3]"),
    "2D pickle": (_set("keypoint", lambda it: it["keypoint"][..., :2]), "only 3D pickles"),
    "C=4": (_set("keypoint", lambda it: np.concatenate([it["keypoint"]] * 2, -1)[..., :4]), "expected [M, T, 25, 3]"),
    "NaN": (
        _set("keypoint", lambda it: np.where(np.arange(6)[None, :, None, None] == 4, np.nan, it["keypoint"])),
        "NaN or Inf (first in frame 4)",
    ),
    "Inf": (_set("keypoint", lambda it: it["keypoint"] * np.float32(np.inf)), "NaN or Inf"),
    "integers": (_set("keypoint", lambda it: it["keypoint"].astype(np.int32)), "expected floats"),
    "a list": (_set("keypoint", lambda it: it["keypoint"].tolist()), "expected a numpy array"),
    "no person": (_set("keypoint", lambda it: it["keypoint"][:0]), "M=0"),
    "3 persons": (_set("keypoint", lambda it: np.concatenate([it["keypoint"], it["keypoint"][:1]])), "M=3"),
    "total_frames": (_set("total_frames", 7), "total_frames 7 differs from the 6 frames"),
    "duplicate": (_set("frame_dir", NAMES[0]), "appears twice"),
}


@pytest.mark.parametrize("case", sorted(BAD_ITEMS))
def test_bad_annotation_is_named(tmp_path, case):
    change, message = BAD_ITEMS[case]
    items = [annotation(n, seed=k, persons=2 if n.endswith("A010") else 1) for k, n in enumerate(NAMES)]
    items[1] = change(items[1])
    if case == "duplicate":
        items[1]["label"] = 0
    frame_dir = items[1]["frame_dir"] if isinstance(items[1], dict) else None
    pkl = small_pickle(tmp_path, items)
    (tmp_path / "c").mkdir()
    (tmp_path / "c" / "keep.txt").write_text("an older cache")
    with pytest.raises(PysklFormatError) as caught:
        import_pyskl(pkl, tmp_path / "c")
    text = str(caught.value)
    assert text.startswith(str(pkl)) and message in text
    if case != "not a dict":
        assert f"annotations[1] (frame_dir {frame_dir!r})" in text
    assert [p.name for p in (tmp_path / "c").iterdir()] == ["keep.txt"]  # nothing written


@pytest.mark.parametrize(
    "data, message",
    [
        (["not", "a", "dict"], "expected a dict with 'split' and 'annotations', found list"),
        ({"annotations": []}, "missing top-level key split"),
        ({"split": {}}, "missing top-level key annotations"),
        ({"split": [], "annotations": []}, "'split' is a list"),
        ({"split": {"xsub_train": "S001C001P001R001A001"}, "annotations": []}, "split['xsub_train'] must be a list"),
        ({"split": {"xsub_train": [1, 2]}, "annotations": []}, "split['xsub_train'] must be a list"),
        ({"split": {}, "annotations": {}}, "'annotations' is a dict"),
        ({"split": {}, "annotations": []}, "'annotations' is empty"),
    ],
)
def test_bad_pickle_structure(tmp_path, data, message):
    pkl = write_pickle(tmp_path / "bad.pkl", data)
    with pytest.raises(PysklFormatError, match=None) as caught:
        import_pyskl(pkl, tmp_path / "c")
    assert str(caught.value).startswith(str(pkl)) and message in str(caught.value)
    assert not (tmp_path / "c").exists()


def test_unreadable_files(tmp_path):
    good = small_pickle(tmp_path).read_bytes()
    (tmp_path / "text.pkl").write_text("annotations: []\n")
    (tmp_path / "cut.pkl").write_bytes(good[: len(good) // 2])
    for name in ("text.pkl", "cut.pkl"):
        with pytest.raises(PysklFormatError, match="not a readable pickle"):
            import_pyskl(tmp_path / name, tmp_path / "c")
    with pytest.raises(PysklFormatError, match="cannot read file"):
        import_pyskl(tmp_path / "absent.pkl", tmp_path / "c")
    with pytest.raises(PysklFormatError, match="refusing to read a directory"):
        import_pyskl(tmp_path, tmp_path / "c")
    assert not (tmp_path / "c").exists()


def test_skip_bad_lists_every_skipped_annotation(tmp_path):
    items = [
        annotation("S001C001P001R001A001"),
        annotation("S001C001P001R001A002", label=5),
        ["not", "a", "dict"],
        annotation("S001C001P003R001A001", frames=4, total_frames=9),
        annotation("S001C001P001R001A001"),
        annotation("S001C002P001R001A001"),
    ]
    report = import_pyskl(small_pickle(tmp_path, items), tmp_path / "c", skip_bad=True)
    assert [(s["index"], s["frame_dir"], s["reason"]) for s in report.skipped] == [
        (1, "S001C001P001R001A002", "bad_label"),
        (2, None, "not_a_dict"),
        (3, "S001C001P003R001A001", "bad_total_frames"),
        (4, "S001C001P001R001A001", "duplicate_name"),
    ]
    assert NTUCache(tmp_path / "c").names.tolist() == ["S001C001P001R001A001", "S001C002P001R001A001"]
    assert report.samples_written == 2 and report.annotations_found == 6
    on_disk = json.loads((tmp_path / "c" / "report.json").read_text())
    assert on_disk["skipped"] == report.skipped and on_disk["totals"]["skipped_bad_label"] == 1
    assert "annotations[3] (S001C001P003R001A001)" in (tmp_path / "c" / "report.txt").read_text()
    with pytest.raises(PysklFormatError, match=r"none of the 1 annotations.*not an NTU sample name"):
        import_pyskl(
            small_pickle(tmp_path, [annotation("S001C001P001R001A001", frame_dir="x")]), tmp_path / "d", skip_bad=True
        )


# --------------------------------------------------------------------------- unsafe pickles


class _System:
    def __init__(self, command):
        self.command = command

    def __reduce__(self):
        return (os.system, (self.command,))


class _Eval:
    def __reduce__(self):
        return (eval, ("__import__('pathlib').Path('VICTIM').touch()",))


@pytest.mark.parametrize(
    "payload, refused",
    [
        (lambda victim: _System(f"touch {victim}"), "system"),
        (lambda victim: _Eval(), "builtins.eval"),
        (lambda victim: NTUCache, "mocapkit.datasets.ntu.cache.NTUCache"),
    ],
)
def test_malicious_pickle_is_refused(tmp_path, monkeypatch, capsys, payload, refused):
    monkeypatch.chdir(tmp_path)
    victim = tmp_path / "VICTIM"
    for where in ("top", "nested"):
        data = (
            payload(victim)
            if where == "top"
            else {"split": {}, "annotations": [annotation(NAMES[0], keypoint_score=payload(victim))]}
        )
        pkl = write_pickle(tmp_path / f"{where}.pkl", data)
        with pytest.raises(PysklFormatError, match=f"refused to load the global .*{refused}") as caught:
            import_pyskl(pkl, tmp_path / "c")
        assert str(caught.value).startswith(str(pkl))
        with pytest.raises(PysklFormatError, match="refused"):
            load_pyskl(pkl)
        assert main(["pyskl", "import", "--pkl", str(pkl), "--out", str(tmp_path / "c")]) == 2
        assert "refused to load the global" in capsys.readouterr().err
    assert not victim.exists() and not (tmp_path / "c").exists()
