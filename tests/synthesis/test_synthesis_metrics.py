"""Metrics of motion-variation synthesis (mocapkit/synthesis/metrics.py) on hand-built motions, and the synthesis
benchmark (mocapkit/synthesis/benchmark.py) end to end through the comparison runner on real HDM05 hops,
and its CMU form (takes cut into windows, a held-out take).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocapkit.evaluation.compare import ComparisonError, compose, run_comparison
from mocapkit.motion.container import Motion
from mocapkit.synthesis.metrics import (
    BONE_DRIFT_RESOLUTION_MM,
    PROXY_RESOLUTION,
    bone_length_drift,
    clip_naturalness,
    feature_distances,
    foot_skating,
    mean_jerk,
    naturalness,
    root_normalised_positions,
    variation,
    within_spread,
)
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"
CMU = SHARED / "data" / "cmu_amc"
BANDAI = SHARED / "data" / "bandai_motion_1"
JOINTS = ("Hips", "LeftUpLeg", "RightUpLeg", "LeftFoot", "RightFoot", "Head")
PARENTS = (-1, 0, 0, 1, 2, 0)


def body(head_heights, fps: float = 10.0, feet=None) -> Motion:
    """A rig facing +z (left hip at −x, right hip at +x, as the HDM05 hips' line after normalisation) whose head
    rises as ``head_heights`` (metres) per frame; ``feet``: optional ``[T, 2, 3]`` foot positions."""
    heights = np.asarray(head_heights, dtype=np.float64)
    T = len(heights)
    p = np.zeros((T, len(JOINTS), 3))
    p[:, 0] = [0.0, 1.0, 0.0]
    p[:, 1] = [-0.1, 1.0, 0.0]
    p[:, 2] = [0.1, 1.0, 0.0]
    p[:, 3] = [-0.1, 0.0, 0.0]
    p[:, 4] = [0.1, 0.0, 0.0]
    p[:, 5, 1] = heights
    if feet is not None:
        p[:, 3:5] = feet
    return Motion(positions=p, joint_names=JOINTS, parents=PARENTS, fps=fps, name="hand-built")


def moved(motion: Motion, yaw: np.ndarray, offset: np.ndarray) -> Motion:
    """``motion`` turned about +y by ``yaw[T]`` (radians) and shifted on the ground by ``offset[T, 2]``."""
    p = motion.positions.astype(np.float64)
    c, s = np.cos(yaw)[:, None], np.sin(yaw)[:, None]
    out = p.copy()
    out[..., 0] = c * p[..., 0] + s * p[..., 2] + offset[:, :1]
    out[..., 2] = -s * p[..., 0] + c * p[..., 2] + offset[:, 1:]
    return Motion(positions=out, joint_names=motion.joint_names, parents=motion.parents, fps=motion.fps)


def test_variation_equals_hand_computed_dtw():
    # the motions differ only in the head height, so the local cost is |Δ head height|:
    # DTW([0,1,2], [0,2]) = 1, DTW([0,1,2], [1,1,1]) = 1 + 0 + 1 = 2, DTW([0,2], [1,1,1]) = 3 (3 steps of cost 1)
    motions = [body([0.0, 1.0, 2.0]), body([0.0, 2.0]), body([1.0, 1.0, 1.0])]
    score = variation(motions)
    assert score.v == pytest.approx((1 + 2 + 3) / 3)
    assert score.distances[0, 1] == pytest.approx(1.0) and score.distances[1, 2] == pytest.approx(3.0)
    assert score.path_lengths[0, 1] == 3 and score.path_lengths[0, 2] == 3 and score.path_lengths[1, 2] == 3
    assert score.v_per_step == pytest.approx((1 / 3 + 2 / 3 + 3 / 3) / 3)


def test_variation_ignores_ground_position_and_heading():
    a, b = body([0.0, 0.5, 1.0, 0.2]), body([0.1, 0.9, 0.3, 0.3])
    rng = np.random.default_rng(0)
    turned = moved(a, rng.uniform(-3, 3, 4), rng.normal(size=(4, 2)))
    np.testing.assert_allclose(root_normalised_positions(turned), root_normalised_positions(a), atol=1e-5)
    assert variation([turned, b]).v == pytest.approx(variation([a, b]).v, abs=1e-4)


def test_variation_of_identical_copies_is_zero():
    clip = body(np.sin(np.linspace(0, 3, 30)))
    assert variation([clip, clip, clip]).v == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ValueError, match="at least two"):
        variation([clip])


def test_foot_skating_of_fixed_and_sliding_feet():
    T, fps = 50, 100.0
    fixed = body(np.full(T, 1.7), fps=fps)
    assert foot_skating(fixed) == pytest.approx(0.0, abs=1e-6)
    feet = np.zeros((T, 2, 3))
    feet[:, 0, 0] = -0.1 + 0.5 * np.arange(T) / fps  # both feet slide along x at 0.5 m/s on the ground
    feet[:, 1, 0] = 0.1 + 0.5 * np.arange(T) / fps
    assert foot_skating(body(np.full(T, 1.7), fps=fps, feet=feet)) == pytest.approx(50.0, rel=1e-4)  # cm/s
    lifted = feet.copy()
    lifted[:, :, 1] = np.linspace(0.0, 1.0, T)[:, None]  # rising 2 m/s: never a contact
    assert np.isnan(foot_skating(body(np.full(T, 1.7), fps=fps, feet=lifted)))


def test_jerk_of_constant_acceleration_is_zero_and_of_a_sine_its_derivative():
    fps = 30.0
    t = np.arange(60) / fps
    const = body(1.0 + 0.3 * t - 0.5 * 2.0 * t**2, fps=fps)
    A, w = 0.1, 2 * np.pi * 2.0
    wave = body(1.5 + A * np.sin(w * t), fps=fps)
    assert mean_jerk(const) < 0.05
    # only the head moves: mean over 6 joints of |A w³ cos| ≈ A w³ (2/π) / 6 (finite differences: within 15 %)
    assert mean_jerk(wave) == pytest.approx(A * w**3 * 2 / np.pi / len(JOINTS), rel=0.15)


def test_bone_length_drift_detects_a_stretched_bone():
    steady = body(np.full(20, 1.7))
    assert bone_length_drift(steady) == pytest.approx(0.0, abs=1e-6)
    heights = np.linspace(1.6, 1.8, 20)  # the hips → head bone stretches from 0.6 to 0.8 m
    expected = np.std(heights - 1.0) * 1000 / (len(JOINTS) - 1)
    assert bone_length_drift(body(heights)) == pytest.approx(expected, rel=1e-4)


def test_feature_distance_reference_spread():
    rng = np.random.default_rng(1)
    real = [body(1.5 + 0.1 * np.sin(np.linspace(0, 6, 40) + rng.uniform(0, 1))) for _ in range(5)]
    odd = [body(1.0 + 0.5 * np.sin(np.linspace(0, 30, 40)))]
    scores = feature_distances(real[:1] + odd, real[1:])
    assert scores.real.shape == (4,) and scores.variants.shape == (2,)
    assert scores.variants[1] > scores.real.max()  # far outside the real clips' spread
    summary = scores.summary()
    assert summary["within_real"] == pytest.approx(0.5)
    with pytest.raises(ValueError, match="two real clips"):
        feature_distances(real, real[:1])


def test_within_spread_is_no_larger_than_the_largest_real_value():
    real = np.array([3.0, 5.0, np.nan])
    assert within_spread([1.0, 5.0, 5.01, np.nan], real).tolist() == [True, True, False, True]
    # without a real clip lacking contacts, a variant without contacts is outside; no finite real value: all out
    assert within_spread([np.nan, 1.0], [3.0, 5.0]).tolist() == [False, True]
    assert within_spread([0.0], [np.nan]).tolist() == [False]
    # rigid FK bones drift by float noise: within the resolution, the same as the real clips' zero
    assert within_spread([1e-4, 0.5], [2e-5, 0.0], BONE_DRIFT_RESOLUTION_MM).tolist() == [True, False]
    assert within_spread([1e-4], [2e-5]).tolist() == [False]


def test_clip_naturalness_is_per_clip_and_naturalness_its_mean():
    fps, T = 10.0, 30
    planted = np.zeros((T, 2, 3))
    planted[:, 1, 0] = 0.2
    sliding = planted.copy()
    sliding[:, :, 2] = 0.03 * np.arange(T)[:, None]  # both feet slide 3 cm a frame: 0.3 m/s
    clips = [body(np.full(T, 1.7), fps, planted), body(np.full(T, 1.7), fps, sliding)]
    table = clip_naturalness(clips)
    assert table["foot_skating_cms"] == pytest.approx([0.0, 30.0])
    assert naturalness(clips)["foot_skating_cms"] == pytest.approx(15.0)
    assert within_spread(table["foot_skating_cms"], [10.0]).tolist() == [True, False]


# ------------------------------------------------------------------------------------------ the benchmark
def test_config_composes_with_every_method():
    cfg = compose(["synthesis_hdm05", "benchmark.root=/nonexistent"])
    assert set(cfg.methods) == {"slfm", "lau", "perlin", "cvae", "cvae_varied", "copy"}
    assert cfg.methods.cvae_varied.params.noise_scale == "auto" and cfg.methods.cvae.estimator.noise_scale == 1.0
    assert "params" not in cfg.methods.cvae  # the registry's cvae (configs/synthesis/method/cvae.yaml) as is
    assert list(cfg.protocols) == list(cfg.benchmark.protocols)


@needs(HDM05)
def test_benchmark_runs_end_to_end(tmp_path):
    cfg = {
        "name": "synthesis_test",
        "out": str(tmp_path),
        "benchmark": {
            "_target_": "mocapkit.synthesis.benchmark.SynthesisBenchmark",
            "root": str(HDM05),
            "protocols": ["hopBothLegs1hops"],
            "n_train": 4,
            "n_variants": 3,
        },
        "protocols": ["hopBothLegs1hops"],
        "seeds": [0],
        "methods": {
            "copy": {"label": "copy", "estimator": {"_target_": "mocapkit.synthesis.perlin.CopyTrainingClips"}},
            "perlin": {
                "label": "perlin",
                "estimator": {"_target_": "mocapkit.synthesis.perlin.PerlinNoiseSynthesizer", "amplitude": 1.0},
            },
        },
    }
    run_comparison(cfg)
    saved = json.loads((tmp_path / "results.json").read_text())
    assert {(c["method"], c["protocol"], c["seed"]) for c in saved["cells"]} == {
        ("copy", "hopBothLegs1hops", 0),
        ("perlin", "hopBothLegs1hops", 0),
    }
    split = saved["splits"]["hopBothLegs1hops"]["0"]
    assert split["n_train"] == 4 and split["n_test"] == 33 - 4
    for cell in saved["cells"]:
        m = cell["metrics"]
        for key in (
            "v_variants",
            "v_train",
            "v_heldout",
            "v_ratio",
            "foot_skating_cms",
            "jerk",
            "bone_drift_mm",
            "real_jerk",
            "feature_distance",
            "feature_distance_real",
            "fit_seconds",
            "sample_seconds_per_second",
        ):
            assert np.isfinite(m[key]), key
        assert m["v_ratio"] == pytest.approx(m["v_variants"] / m["v_train"])
        # every proxy within the real spread: the share recomputed from the per-clip values saved beside it
        d = cell["detail"]
        ok = within_spread(d["variant_feature_distances"], d["real_feature_distances"])
        for name in ("foot_skating_cms", "jerk", "bone_drift_mm"):
            ok &= within_spread(d["variant_proxies"][name], d["real_proxies"][name], PROXY_RESOLUTION.get(name, 0.0))
        assert m["within_real_all"] == pytest.approx(ok.mean())
        assert m["within_real_all"] <= min(m["within_real"], m["within_real_skating"], m["within_real_jerk"])
        assert m["real_jerk_max"] == pytest.approx(max(d["real_proxies"]["jerk"]))
    copy, perlin = (next(c for c in saved["cells"] if c["method"] == k) for k in ("copy", "perlin"))
    assert copy["metrics"]["v_train"] == perlin["metrics"]["v_train"]  # one reference per split
    assert (tmp_path / "variation.png").is_file()
    assert "Variation and naturalness" in (tmp_path / "results.md").read_text()


@needs(HDM05)
def test_benchmark_rejects_a_type_with_too_few_clips():
    with pytest.raises(ComparisonError, match="n_train"):
        from mocapkit.synthesis.benchmark import SynthesisBenchmark

        SynthesisBenchmark(str(HDM05), ["jogLeftCircle4StepsRstart"], n_train=12)


@needs(CMU)
def test_cmu_walks_are_cut_into_windows_and_a_held_out_take_is_the_reference():
    from mocapkit.synthesis.benchmark import SynthesisBenchmark

    cfg = compose(["synthesis_cmu"])
    assert cfg.benchmark.dataset == "cmu"
    assert set(cfg.methods) == {"slfm", "lau", "perlin", "cvae", "cvae_varied", "copy"}
    bench = SynthesisBenchmark(
        str(CMU),
        ["walk_uneven"],
        n_train=10,
        n_variants=2,
        dataset="cmu",
        types={"walk_uneven": ["03_01", "03_02", "03_03", "03_04"]},
        window_seconds=2.0,
        heldout_takes=["03_04"],
    )
    frames = {"03_01": 432, "03_02": 365, "03_03": 4563, "03_04": 4722}  # 120 fps takes
    assert len(bench.motions) == sum(n // 240 for n in frames.values()) == 40
    assert all(m.num_frames == 240 for m in bench.motions)
    assert bench.describe()["frames_left_out"] == {take: n % 240 for take, n in frames.items()}
    splits = [bench.split("walk_uneven", seed) for seed in (0, 1)]
    for split in splits:
        train_takes = {bench.clips[i]["take"] for i in split.train}
        assert len(split.train) == 10 and "03_04" not in train_takes
        assert {bench.clips[i]["take"] for i in split.test} == {"03_04"} and len(split.test) == 4722 // 240
    assert list(splits[0].train) != list(splits[1].train)  # the seed draws the windows
    # a window is the take's frames, on the take's skeleton
    take = next(m for m, c in zip(bench.motions, bench.clips) if c["name"] == "03_03[240:480]")
    from mocapkit.datasets.formats.asf_amc import read_amc

    np.testing.assert_allclose(take.positions, read_amc(CMU / "03_03.amc").positions[240:480], atol=1e-9)
    with pytest.raises(ComparisonError, match="not found"):
        SynthesisBenchmark(str(CMU), ["walk"], dataset="cmu", types={"walk": ["03_09"]})
    with pytest.raises(ComparisonError, match="to draw from"):  # one take of 3.6 s: too few windows
        SynthesisBenchmark(
            str(CMU),
            ["walk"],
            dataset="cmu",
            types={"walk": ["03_01", "03_04"]},
            window_seconds=2.0,
            heldout_takes=["03_04"],
        )
    with pytest.raises(ComparisonError, match="ASF/AMC"):
        SynthesisBenchmark(str(CMU), ["walk"], dataset="msr")


@needs(BANDAI)
def test_bandai_bvh_takes_are_synthesis_clips_on_one_rest_pose(tmp_path):
    """Bandai's BVH takes, converted to ASF/AMC on one T-pose rest, go through the same benchmark and runner."""
    from mocapkit.synthesis.benchmark import SynthesisBenchmark

    cfg = compose(
        [
            "synthesis_bandai",
            f"out={tmp_path}",
            f"benchmark.root={BANDAI}",
            "protocols=[bow]",
            "benchmark.protocols=[bow]",
            "benchmark.n_train=4",
            "benchmark.n_variants=3",
            "seeds=[0]",
            "only=[perlin,copy]",
        ]
    )
    run_comparison(cfg)
    cells = {c["method"]: c for c in json.loads((tmp_path / "results.json").read_text())["cells"]}
    assert set(cells) == {"perlin", "copy"}
    assert cells["copy"]["metrics"]["feature_distance"] < cells["copy"]["metrics"]["feature_distance_real"] * 3
    bench = SynthesisBenchmark(str(BANDAI), ["bow"], n_train=10, n_variants=2, dataset="bandai")
    assert len(bench.motions) == 15 and {c["class"] for c in bench.clips} == {"bow"}
    rigs = {id(m.metadata["bvh_rig"]) for m in bench.motions}
    assert len(rigs) == 1 and bench.motions[0].metadata["bvh_rig"].reference.endswith("bow_active_001.bvh frame 0")
