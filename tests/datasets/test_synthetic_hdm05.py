"""Synthetic HDM05-style ASF/AMC data: files, determinism, plausibility, merges exercised."""

import numpy as np
import pytest

from mocapkit.datasets.formats.asf_amc import read_amc, read_asf
from mocapkit.datasets.mocap.hdm05_classes import labels, parse_clip_name
from mocapkit.datasets.synthetic.hdm05 import (
    DEFAULT_CLASSES,
    HDM05SynthConfig,
    actor_skeleton,
    synthesize_hdm05,
)
from mocapkit.motion.layouts import CMU31

SMALL = HDM05SynthConfig(
    classes=(
        "punchLFront1Reps",
        "punchRSide1Reps",
        "walk2StepsLstart",
        "walkLeftCircle4StepsRstart",
        "hopLLeg2hops",
        "squat1Reps",
        "turnLeft",
    ),
    actors=("bd", "mm"),
    clips_per_actor=1,
    seed=3,
)


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth")
    return out, synthesize_hdm05(out, SMALL, progress=False)


def test_files_and_names(small):
    out, paths = small
    assert len(paths) == 7 * 2 and all(p.suffix == ".amc" for p in paths)
    assert sorted(p.name for p in out.glob("*.asf")) == ["HDM_bd.asf", "HDM_mm.asf"]
    assert (out / "classes.txt").read_text().split() == list(SMALL.classes)
    for p in paths:
        clip = parse_clip_name(p)
        assert clip.cls in SMALL.classes and clip.actor in SMALL.actors and clip.take == 1


def test_clips_read_back_plausible(small):
    _, paths = small
    for p in paths:
        m = read_amc(p)  # finds HDM_<actor>.asf beside it
        assert m.layout_name == "cmu31" and m.joint_names == CMU31.joint_names and m.fps == 120.0
        assert 24 <= m.num_frames <= SMALL.max_frames
        pos = m.positions
        feet = pos[:, [m.index(j) for j in ("lfoot", "ltoes", "rfoot", "rtoes")], 1].min(1)
        assert np.abs(feet[feet < 0.01]).max(initial=0) < 0.01 and feet.min() > -0.01  # on, not under, the floor
        head = pos[:, m.index("head"), 1]
        assert (head > pos[:, m.index("root"), 1]).all() and (head - feet > 0.9).all()
        if "squat" not in p.name:
            assert (head - feet > 1.3).all()
        assert np.isfinite(pos).all() and np.abs(np.diff(pos, axis=0)).max() < 0.2  # smooth, no jumps


def test_actors_differ(small):
    out, _ = small
    h = {a: read_asf(out / f"HDM_{a}.asf").rest_positions()[:, 1] for a in ("bd", "mm")}
    assert (h["bd"].max() - h["bd"].min()) > (h["mm"].max() - h["mm"].min()) + 0.1  # bd is taller
    s = actor_skeleton("tr")
    assert s.joint_names == CMU31.joint_names and s.parents == CMU31.parents


def test_class_semantics(small):
    out, _ = small
    walk = read_amc(out / "walk2StepsLstart_bd_001.amc").positions[:, 0]
    assert np.linalg.norm(walk[-1, [0, 2]] - walk[0, [0, 2]]) > 0.8  # walking travels
    squat = read_amc(out / "squat1Reps_bd_001.amc").positions[:, 0, 1]
    assert squat.max() - squat.min() > 0.25  # the pelvis goes down
    punch = read_amc(out / "punchLFront1Reps_mm_001.amc")
    lw, rw = punch.index("lradius"), punch.index("rradius")
    reach = lambda j: np.linalg.norm(punch.positions[:, j] - punch.positions[:, punch.index("thorax")], axis=1)
    assert reach(lw).max() > reach(rw).max() + 0.1  # the left arm punches out


def test_deterministic_and_seeded(tmp_path):
    cfg = HDM05SynthConfig(classes=("kickRFront2Reps",), actors=("dg",), clips_per_actor=2, seed=5)
    a = synthesize_hdm05(tmp_path / "a", cfg, progress=False)
    b = synthesize_hdm05(tmp_path / "b", cfg, progress=False)
    assert [p.read_bytes() for p in a] == [p.read_bytes() for p in b]
    assert a[0].read_bytes() != a[1].read_bytes()  # takes differ
    c = synthesize_hdm05(
        tmp_path / "c",
        HDM05SynthConfig(classes=cfg.classes, actors=cfg.actors, clips_per_actor=2, seed=6),
        progress=False,
    )
    assert a[0].read_bytes() != c[0].read_bytes()


def test_default_classes_exercise_the_merges():
    assert (
        len(set(labels(DEFAULT_CLASSES, 130)))
        > len(set(labels(DEFAULT_CLASSES, 65)))
        > len(set(labels(DEFAULT_CLASSES, 25)))
        > 5
    )


def test_config_validation():
    with pytest.raises(ValueError, match="not HDM05 classes"):
        HDM05SynthConfig(classes=("moonwalk",))
    with pytest.raises(ValueError, match="unknown HDM05 actors"):
        HDM05SynthConfig(actors=("zz",))
    with pytest.raises(ValueError):
        HDM05SynthConfig(clips_per_actor=0)


def test_every_default_class_stays_human_sized(tmp_path):
    """Each motion template keeps the body on or near the floor (jumps and hops lift it < 0.5 m)."""
    from mocapkit.datasets.synthetic.hdm05 import DEFAULT_CLASSES

    paths = synthesize_hdm05(tmp_path, HDM05SynthConfig(actors=("tr",), clips_per_actor=1, seed=1), progress=False)
    assert len(paths) == len(DEFAULT_CLASSES)
    for p in paths:
        pos = read_amc(p).positions
        feet = pos[:, [CMU31.index(j) for j in ("lfoot", "ltoes", "rfoot", "rtoes")], 1].min(1)
        assert feet.min() > -0.01 and feet.max() < 0.5, p.name
        assert pos[..., 1].max() < 2.6, p.name
