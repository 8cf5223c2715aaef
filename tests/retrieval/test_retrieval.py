"""Retrieval: the normalised landmark skeleton, the metrics, DTW, the index / search commands, the benchmark."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mocapkit.cli import main as cli
from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import LANDMARK_NAMES, find_landmarks
from mocapkit.retrieval import (
    MotionIndex,
    RetrievalIndexError,
    SkeletonInputError,
    build_index,
    normalised_landmarks,
    search_index,
)
from mocapkit.retrieval.dtw import DTWRetrieval
from mocapkit.retrieval.metrics import retrieval_metrics, tp_ratio
from tests.shared_data import SHARED, needs, synthetic_hdm05_folder

HDM05 = SHARED / "data" / "hdm05_cuts11"
BANDAI_JOINTS = (
    "joint_Root",
    "Hips",
    "Spine",
    "Chest",
    "Neck",
    "Head",
    "Shoulder_L",
    "UpperArm_L",
    "LowerArm_L",
    "Hand_L",
    "Shoulder_R",
    "UpperArm_R",
    "LowerArm_R",
    "Hand_R",
    "UpperLeg_L",
    "LowerLeg_L",
    "Foot_L",
    "Toes_L",
    "UpperLeg_R",
    "LowerLeg_R",
    "Foot_R",
    "Toes_R",
)


@pytest.fixture(scope="module")
def hdm05_folder(tmp_path_factory) -> Path:
    """A synthetic HDM05-format folder: 3 classes × 2 actors × 3 takes, 120 fps."""
    return synthetic_hdm05_folder(
        tmp_path_factory, ("walk2StepsLstart", "hopBothLegs1hops", "squat1Reps"), clips_per_actor=3, max_frames=240
    )


def _walker(frames: int = 90, fps: float = 30.0, seed: int = 0) -> Motion:
    """A Bandai-rig skeleton (BVH joint names) swinging its limbs, 1 m pelvis height, metres."""
    rng = np.random.default_rng(seed)
    offsets = {
        "joint_Root": (0, 0, 0),
        "Hips": (0, 1.0, 0),
        "Spine": (0, 0.1, 0),
        "Chest": (0, 0.2, 0),
        "Neck": (0, 0.25, 0),
        "Head": (0, 0.15, 0),
        "Shoulder_L": (0.05, 0.2, 0),
        "UpperArm_L": (0.12, 0, 0),
        "LowerArm_L": (0.28, 0, 0),
        "Hand_L": (0.25, 0, 0),
        "Shoulder_R": (-0.05, 0.2, 0),
        "UpperArm_R": (-0.12, 0, 0),
        "LowerArm_R": (-0.28, 0, 0),
        "Hand_R": (-0.25, 0, 0),
        "UpperLeg_L": (0.1, -0.05, 0),
        "LowerLeg_L": (0, -0.42, 0),
        "Foot_L": (0, -0.41, 0),
        "Toes_L": (0, -0.05, 0.12),
        "UpperLeg_R": (-0.1, -0.05, 0),
        "LowerLeg_R": (0, -0.42, 0),
        "Foot_R": (0, -0.41, 0),
        "Toes_R": (0, -0.05, 0.12),
    }
    parents = (-1, 0, 1, 2, 3, 4, 3, 6, 7, 8, 3, 10, 11, 12, 1, 14, 15, 16, 1, 18, 19, 20)
    t = np.arange(frames) / fps
    positions = np.zeros((frames, len(BANDAI_JOINTS), 3))
    for j, (name, parent) in enumerate(zip(BANDAI_JOINTS, parents)):
        offset = np.array(offsets[name], dtype=float)
        swing = (
            0.1 * np.sin(2 * np.pi * t + j)[:, None] * np.array([0, 0, 1.0])
            if name.startswith(("Lower", "Hand", "Foot"))
            else 0
        )
        positions[:, j] = (positions[:, parent] if parent >= 0 else 0) + offset + swing
    positions += rng.normal(scale=0.002, size=positions.shape)
    return Motion(positions, BANDAI_JOINTS, fps, parents=parents, name="walker")


# ------------------------------------------------------------------------------------------ skeleton
def test_landmarks_of_a_bvh_rig_and_known_layouts():
    found = find_landmarks(BANDAI_JOINTS)
    assert set(found) == set(LANDMARK_NAMES)
    assert BANDAI_JOINTS[found["l_elbow"]] == "LowerArm_L" and BANDAI_JOINTS[found["r_hip"]] == "UpperLeg_R"
    assert find_landmarks(["Hips", "LeftUpLeg", "RightUpLeg", "Head"])["l_hip"] == 1


CMU_BVH = SHARED / "samples" / "bvh" / "cmu_131_01.bvh"


def test_landmarks_of_the_cmu_bvh_rig():
    """The CMU BVH rig names its hip joints LeftHip / RightHip (below LHipJoint / RHipJoint, the pelvis bones)."""
    names = ["Hips", "LHipJoint", "LeftHip", "LeftKnee", "LeftAnkle", "LeftToe", "RHipJoint", "RightHip"]
    names += ["RightKnee", "RightAnkle", "RightToe", "lowerback", "Chest", "Chest2", "lowerneck", "Neck", "Head"]
    names += ["LeftCollar", "LeftShoulder", "LeftElbow", "LeftWrist", "RightCollar", "RightShoulder"]
    names += ["RightElbow", "RightWrist"]
    found = {lm: names[j] for lm, j in find_landmarks(names).items()}
    assert set(found) == set(LANDMARK_NAMES)
    assert (found["l_hip"], found["r_hip"], found["pelvis"]) == ("LeftHip", "RightHip", "Hips")
    assert (found["l_knee"], found["l_shoulder"], found["r_elbow"]) == ("LeftKnee", "LeftShoulder", "RightElbow")


@needs(CMU_BVH)
def test_a_cmu_bvh_file_is_normalised_facing_forward():
    from mocapkit.datasets import read_motion

    p = normalised_landmarks(read_motion(CMU_BVH))
    assert p.shape[1:] == (20, 3) and np.isfinite(p).all()
    lm = LANDMARK_NAMES.index
    assert p[:, lm("l_hip"), 0].mean() > 0.03  # the left hip on +x: it faces +z
    assert (p[:, lm("l_foot"), 2] - p[:, lm("l_ankle"), 2]).mean() > 0.05  # toes ahead of the ankle
    assert p[:, lm("head"), 1].mean() > 0.4


def test_normalisation_removes_translation_heading_and_size():
    motion = _walker()
    base = normalised_landmarks(motion)
    angle = 1.1
    rot = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    moved = replace(motion, positions=1.3 * motion.positions @ rot.T + np.array([2.0, 0.5, -3.0]))
    assert np.allclose(normalised_landmarks(moved), base, atol=1e-4)
    # pelvis at the origin; template bone lengths; facing +z (left hip at +x)
    assert np.allclose(base[:, 0], 0)
    l_hip, r_hip = LANDMARK_NAMES.index("l_hip"), LANDMARK_NAMES.index("r_hip")
    assert (base[:, l_hip, 0] > 0).all() and (base[:, r_hip, 0] < 0).all()
    assert np.allclose(
        np.linalg.norm(base[:, LANDMARK_NAMES.index("l_knee")] - base[:, l_hip], axis=-1), 0.42, atol=1e-5
    )


def test_normalisation_fills_gaps_and_names_bad_input():
    motion = _walker()
    positions = motion.positions.copy()
    positions[10:20, 9] = np.nan  # the left hand lost for 10 frames
    gappy = normalised_landmarks(replace(motion, positions=positions, missing=None))
    assert np.isfinite(gappy).all()
    with pytest.raises(SkeletonInputError, match="walker.*frames"):
        normalised_landmarks(replace(motion, positions=motion.positions[:1], missing=None))
    with pytest.raises(SkeletonInputError, match="walker: no landmark is observed"):
        normalised_landmarks(replace(motion, positions=np.full_like(motion.positions, np.nan), missing=None))
    markers = Motion(np.zeros((20, 4, 3)), ["M1", "M2", "M3", "M4"], 100.0, source="markers.c3d")
    with pytest.raises(SkeletonInputError, match="markers.c3d.*landmarks"):
        normalised_landmarks(markers)


# ------------------------------------------------------------------------------------------ metrics
def test_metrics_on_a_hand_made_ranking():
    # both queries see the database ranked A, B, A: query A → AP = (1/1 + 2/3) / 2; query B → AP = 1/2
    d = np.array([[0.1, 0.2, 0.3], [0.1, 0.2, 0.3]])
    scores = retrieval_metrics(d, ["A", "B"], ["A", "B", "A"], ks=(1, 2))["metrics"]
    assert scores["map"] == pytest.approx(((1 + 2 / 3) / 2 + 1 / 2) / 2)
    assert scores["p@1"] == pytest.approx(0.5) and scores["nn_accuracy"] == pytest.approx(0.5)
    assert scores["p@2"] == pytest.approx((1 / 2 + 1 / 2) / 2)
    with pytest.raises(ValueError, match="NaN"):
        retrieval_metrics(np.array([[np.nan]]), ["A"], ["A"])


def test_tp_ratio_counts_the_top_lists_agreement():
    labels = np.array(["A", "A", "A", "B", "B"])
    pos = np.array([0.0, 0.1, 5.0, 0.2, 0.3])  # clip 2 is an A far from the others
    d = np.abs(pos[:, None] - pos[None, :])
    out = tp_ratio(d, labels, [0], k=2)
    # query 0: mixed top-2 = {1, 3}; own class top-2 = {1, 2}: one shared of 2
    assert out["tp_ratio"] == pytest.approx(0.5) and out["k_used"] == {"A": 2}


# ------------------------------------------------------------------------------------------ DTW
def test_dtw_finds_the_time_warped_copy():
    a, b = _walker(seed=1), _walker(frames=60, seed=2)
    slow = replace(a, positions=np.repeat(a.positions, 2, axis=0)[::1][:150], missing=None, name="slow")
    other = replace(b, positions=b.positions[:, ::-1].copy(), missing=None)  # joints scrambled: a different pose
    method = DTWRetrieval().fit([other, slow])
    assert method.search([a], k=1)[0][0, 0] == 1
    restored = DTWRetrieval()
    restored._set_state(method._state())
    assert np.allclose(restored.distances([a]), method.distances([a]))


def test_mutual_proximity_demotes_a_hub():
    from mocapkit.retrieval.hubness import (
        database_statistics,
        mutual_proximity,
        reference_indices,
    )

    # database clip 0 is a hub, 0.8-1.1 from every other clip; clips 1-4 are 3.0 apart from each other. The query
    # is 0.95 from the hub and 1.0 from clip 1, its true neighbour, and 3.0 from the rest: by raw distance the hub
    # comes first; for the hub a distance of 0.95 is its average, for clip 1 a distance of 1.0 is rare.
    n = 5
    database = np.full((n, n), 3.0)
    database[0, 1:] = database[1:, 0] = [0.8, 0.9, 1.0, 1.1]
    np.fill_diagonal(database, 0.0)
    query = np.array([[0.95, 1.0, 3.0, 3.0, 3.0]])
    mean, std = database_statistics(database, reference_indices(n, 512))
    assert mean[0] == pytest.approx(0.95) and mean[1] == pytest.approx((0.8 + 3 + 3 + 3) / 4)  # itself left out
    assert np.argmin(query[0]) == 0
    mp = mutual_proximity(query, mean, std)
    assert np.argmin(mp[0]) == 1 and (mp >= 0).all()
    # -log of the product of the two normal tails
    from scipy.stats import norm

    expected = -np.log(norm.sf(1.0, query.mean(), query.std()) * norm.sf(1.0, mean[1], std[1]))
    assert mp[0, 1] == pytest.approx(expected)
    assert reference_indices(10, 4).tolist() == [0, 3, 6, 9]


def test_dtw_with_two_features_scales_and_sums_them():
    clips = [_walker(frames=60 + 10 * i, seed=i) for i in range(4)]
    query = _walker(frames=70, seed=9)
    both = DTWRetrieval(features=["positions", "relational"]).fit(clips)
    singles = [DTWRetrieval(features=f).fit(clips) for f in ("positions", "relational")]
    among = [s.distances(clips) for s in singles]
    off = ~np.eye(len(clips), dtype=bool)
    assert both.scales_ == pytest.approx([np.median(d[off]) for d in among])
    expected = sum(s.distances([query]) / scale for s, scale in zip(singles, both.scales_))
    assert np.allclose(both.distances([query]), expected)
    with pytest.raises(ValueError, match="features"):
        DTWRetrieval(features=["positions", "speed"]).fit(clips)
    with pytest.raises(ValueError, match="hubness"):
        DTWRetrieval(hubness="snn").fit(clips)
    hub = DTWRetrieval(features=["positions", "relational"], hubness="mutual_proximity").fit(clips)
    restored = DTWRetrieval(features=["positions", "relational"], hubness="mutual_proximity")
    restored._set_state(hub._state())
    assert np.allclose(restored.distances([query]), hub.distances([query]))
    assert not np.allclose(hub.distances([query]), both.distances([query]))


def test_landmark_speeds_read_no_frame_path_or_heading():
    """``speeds``: each landmark's speed in the body's frame, [T, 20] m/s. The same movement turned and walking
    sideways has the same speeds; a still pose has none; the swinging hands move at about their swing's speed."""
    from dataclasses import replace

    from mocapkit.motion.geometry import landmark_track
    from mocapkit.retrieval.dtw import frame_features
    from tests.retrieval.test_world_frame import _turned

    walker = _walker(frames=120, seed=3)
    speeds = frame_features(landmark_track(walker), "speeds", 30.0)
    assert speeds.shape == (120, 20) and (speeds >= 0).all()
    moved = frame_features(landmark_track(_turned(walker, 1.2, (1.0, 0.0, 0.5))), "speeds", 30.0)
    np.testing.assert_allclose(moved, speeds, atol=0.02)
    still = replace(walker, positions=np.repeat(walker.positions[:1], 120, axis=0))
    np.testing.assert_allclose(frame_features(landmark_track(still), "speeds", 30.0), 0.0, atol=1e-6)
    # the hands swing 0.1 m (their chain adds up to 0.2-0.3 m) at 1 Hz: peak speeds of 0.6-2 m/s, not 0
    assert 0.3 < speeds[10:-10].max() < 3.0


# ------------------------------------------------------------------------------------------ index / search
def test_index_and_search_cli(hdm05_folder, tmp_path, capsys):
    out = tmp_path / "index"
    assert cli(["index", "--src", str(hdm05_folder), "--out", str(out), "--method", "dtw_positions"]) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["n_files"] == 18 and manifest["method"] == "dtw_positions"
    assert set(manifest["landmarks"]) == set(LANDMARK_NAMES)
    query = min((hdm05_folder / "bd").glob("*squat1Reps*.amc"))
    capsys.readouterr()
    assert cli(["search", "--index", str(out), str(query), "-k", "3", "--json"]) == 0
    results = json.loads(capsys.readouterr().out)
    assert results[0]["query"] == str(query)
    hits = results[0]["results"]
    assert len(hits) == 3 and all(str(query.resolve()) != h["path"] for h in hits)  # itself left out
    assert [h["distance"] for h in hits] == sorted(h["distance"] for h in hits)
    assert all("squat1Reps" in Path(h["path"]).name for h in hits)
    assert cli(["search", "--index", str(out), str(query), "-k", "0", "--json"]) == 0
    assert len(json.loads(capsys.readouterr().out)[0]["results"]) == 17  # all but itself
    # a refused method names both
    assert cli(["search", "--index", str(out), str(query), "--method", "tsr_stpm"]) == 2
    err = capsys.readouterr().err
    assert "dtw_positions" in err and "tsr_stpm" in err


def test_index_takes_the_folder_positionally_and_set_overrides(hdm05_folder, tmp_path, capsys):
    out = tmp_path / "index"
    assert (
        cli(
            [
                "index",
                str(hdm05_folder),
                "--out",
                str(out),
                "--method",
                "dtw_positions",
                "--set",
                "window=0.2",
                "--set",
                "features=[positions,relational]",
            ]
        )
        == 0
    )
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["params"]["window"] == 0.2 and manifest["params"]["features"] == ["positions", "relational"]
    assert manifest["target"] == "mocapkit.retrieval.dtw.DTWRetrieval"
    assert MotionIndex.load(out).method.window == 0.2  # reloaded with its parameters
    capsys.readouterr()
    assert cli(["index", str(hdm05_folder), "--out", str(tmp_path / "x"), "--set", "nope=1"]) == 2
    err = capsys.readouterr().err
    assert "no parameter 'nope'" in err and "dtw_world_frame" in err and "hubness" in err  # the default
    assert cli(["index", str(hdm05_folder), "--src", str(hdm05_folder), "--out", str(tmp_path / "y")]) == 2
    assert "give SRC once" in capsys.readouterr().err


def test_a_saved_index_only_rebuilds_registry_classes(hdm05_folder, tmp_path):
    out = tmp_path / "index"
    build_index(hdm05_folder, out, method="dtw_positions", quiet=True)
    manifest = json.loads((out / "manifest.json").read_text())
    manifest["target"] = "pathlib.Path.touch"  # never read back
    (out / "manifest.json").write_text(json.dumps(manifest))
    assert type(MotionIndex.load(out).method).__name__ == "DTWRetrieval"
    manifest["method"] = "os.system"
    (out / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(RetrievalIndexError, match="unknown retrieval method 'os.system'"):
        MotionIndex.load(out)


def test_index_bad_files_empty_folders_and_foreign_skeletons(hdm05_folder, tmp_path):
    src = tmp_path / "src"
    shutil.copytree(hdm05_folder / "bd", src)
    bad = src / "HDM_bd_broken_001_120.amc"
    bad.write_text(":FULLY-SPECIFIED\n:DEGREES\n1\nroot not numbers\n")
    with pytest.raises(ValueError, match="HDM_bd_broken_001_120.amc"):
        build_index(src, tmp_path / "i1", method="dtw_positions", quiet=True)
    index = build_index(src, tmp_path / "i2", method="dtw_positions", skip_bad=True, quiet=True)
    assert len(index.files) == 9 and index.skipped[0]["path"].endswith("HDM_bd_broken_001_120.amc")
    assert json.loads((tmp_path / "i2" / "manifest.json").read_text())["skipped"][0]["why"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(ValueError, match="no motion files"):
        build_index(tmp_path / "empty", method="dtw_positions", quiet=True)
    loaded = MotionIndex.load(tmp_path / "i2")
    markers = Motion(np.zeros((40, 3, 3)), ["LFHD", "RFHD", "C7"], 120.0, name="markers")
    with pytest.raises(ValueError, match="markers.*lacks the landmarks"):
        loaded.search([("markers", markers)])
    short = Motion(np.zeros((1, len(BANDAI_JOINTS), 3)), BANDAI_JOINTS, 30.0, parents=_walker().parents, name="short")
    with pytest.raises(SkeletonInputError, match="short.*at least"):
        loaded.search([("short", short)])
    with pytest.raises(ValueError, match="not an index folder"):
        search_index(tmp_path / "empty", ["x.amc"])


def test_index_round_trip_gives_the_same_ranking(hdm05_folder, tmp_path):
    index = build_index(hdm05_folder, tmp_path / "idx", quiet=True)  # the recommended default
    assert index.method_name == "dtw_world_frame"
    query = min((hdm05_folder / "mm").glob("*.amc"))
    before = index.search([str(query)], k=0)
    after = search_index(tmp_path / "idx", [str(query)], k=0)
    assert before == after
    motion_class = query.name.split("_")[2]  # HDM_<actor>_<class>_<nnn>_120.amc
    assert [Path(h["path"]).name.split("_")[2] for h in before[0]["results"][:3]] == [motion_class] * 3


# ------------------------------------------------------------------------------------------ benchmark
@needs(HDM05)
def test_cross_performer_benchmark_on_real_hdm05():
    from mocapkit.retrieval.benchmark import RetrievalBenchmark

    bench = RetrievalBenchmark("hdm05", str(HDM05), ["cross_performer", "zhou_tp20"], clips_per_group=12)
    split = bench.split("cross_performer", 0)
    assert set(split.info["folds"]) == {"bd", "bk", "dg", "mm"}
    result = bench.evaluate_estimator(DTWRetrieval(), split)
    m = result["metrics"]
    # 11 classes: chance P@1 is about 0.1; measured 1.0 on all 232 clips
    assert m["n_queries"] == 48 and m["p@1"] > 0.7 and m["map"] > 0.5
    for fold, scores in result["detail"]["folds"].items():
        nearest_actors = {name.split("_")[1] for name in scores["nearest"]}
        assert fold not in nearest_actors  # never its own performer
    tp = bench.evaluate_estimator(DTWRetrieval(), bench.split("zhou_tp20", 0))["metrics"]["tp_ratio"]
    assert 0.5 < tp <= 1.0


def test_dtw_distances_in_query_blocks_equal_one_call(monkeypatch):
    """Queries go to dtaidistance in blocks (memory, progress): the distances are those of one call, in order."""
    import mocapkit.retrieval.dtw as dtw_module

    rng = np.random.default_rng(3)
    queries = [rng.normal(size=(int(rng.integers(5, 12)), 4)) for _ in range(7)]
    database = [rng.normal(size=(int(rng.integers(5, 12)), 4)) for _ in range(5)]
    method = dtw_module.DTWRetrieval(window=0.5, parallel=False)
    whole = method._feature_distances(queries, database)
    monkeypatch.setattr(dtw_module, "QUERY_BLOCK", 3)
    blocked = method._feature_distances(queries, database)
    assert whole.shape == (7, 5)
    np.testing.assert_array_equal(blocked, whole)
    from dtaidistance import dtw_ndim

    window = int(np.ceil(0.5 * max(len(s) for s in queries + database)))  # the band of the longest clip
    expected = dtw_ndim.distance(queries[6], database[2], window=window) / np.sqrt(len(queries[6]) + len(database[2]))
    assert blocked[6, 2] == pytest.approx(expected)
