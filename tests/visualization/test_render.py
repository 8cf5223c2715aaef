"""Rendering: GIF frame counts, strip size, non-empty drawings, markers, several people, errors."""

import shutil
import sys
import types

import numpy as np
import pytest
from PIL import Image, ImageChops

from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import NTU25
from mocapkit.visualization.render import (
    RenderError,
    as_motions,
    frame_indices,
    render_file,
    render_motion,
    render_strip,
)
from tests.shared_data import SHARED, needs

BVH_DIR = SHARED / "samples" / "bvh"


def walker(frames: int = 40, fps: float = 120.0, shift: float = 0.0) -> Motion:
    """A 5-joint stick figure (pelvis, chest, head, two feet) walking along x and waving its feet."""
    t = np.arange(frames) / fps
    pos = np.zeros((frames, 5, 3), dtype=np.float32)
    pos[:, 0] = np.stack([0.8 * t + shift, np.full_like(t, 0.9), np.zeros_like(t)], axis=1)
    pos[:, 1] = pos[:, 0] + [0, 0.5, 0]
    pos[:, 2] = pos[:, 1] + [0, 0.3, 0]
    swing = 0.3 * np.sin(2 * np.pi * 1.5 * t)
    pos[:, 3] = pos[:, 0] + np.stack([swing, np.full_like(t, -0.9), np.full_like(t, 0.1)], axis=1)
    pos[:, 4] = pos[:, 0] + np.stack([-swing, np.full_like(t, -0.9), np.full_like(t, -0.1)], axis=1)
    return Motion(
        positions=pos,
        joint_names=("pelvis", "chest", "head", "lfoot", "rfoot"),
        parents=(-1, 0, 1, 0, 0),
        fps=fps,
        name="walker",
    )


def ink(image: Image.Image) -> int:
    """Pixels that are clearly coloured (not white or grey axes)."""
    rgb = np.asarray(image.convert("RGB")).astype(int)
    return int(((rgb.max(-1) - rgb.min(-1)) > 60).sum())


def gif_frames(path) -> list[Image.Image]:
    im = Image.open(path)
    out = []
    for k in range(im.n_frames):
        im.seek(k)
        out.append(im.convert("RGB"))
    return out


def test_frame_indices_rules():
    assert list(frame_indices(40, 120.0)) == list(range(0, 40, 8))  # default: at most 15 fps
    assert list(frame_indices(40, 120.0, step=10)) == [0, 10, 20, 30]
    assert list(frame_indices(10, 10.0)) == list(range(10))  # slow clips keep every frame
    assert len(frame_indices(994, 120.0, fps=12)) == 100
    with pytest.raises(ValueError):
        frame_indices(10, 30.0, step=0)


@pytest.mark.parametrize("view", ["3d", "front"])
def test_gif_has_expected_frames_and_is_drawn(tmp_path, view):
    m = walker()
    out = render_motion(m, tmp_path / "a.gif", step=8, view=view, size=2.0, dpi=60, title="walker")
    frames = gif_frames(out)
    assert len(frames) == len(frame_indices(m.num_frames, m.fps, step=8)) == 5
    assert frames[0].size == (120, 120)
    assert all(ink(f) > 30 for f in frames)  # the skeleton is drawn in every frame
    assert ImageChops.difference(frames[0], frames[2]).getbbox() is not None  # and it moves
    assert Image.open(out).info.get("duration") == pytest.approx(1000 / 15, abs=10)  # 120 Hz / 8 (GIF: 10 ms units)


def test_strip_png_size_and_content(tmp_path):
    out = render_strip(walker(), tmp_path / "s.png", n=4, panel_size=1.5, dpi=80, title="walker")
    im = Image.open(out)
    assert im.size == (4 * 120, 120)
    quarter = im.width // 4
    for k in range(4):  # every panel has its skeleton
        assert ink(im.crop((k * quarter, 0, (k + 1) * quarter, im.height))) > 20


def test_markers_without_hierarchy_and_missing_values(tmp_path):
    m = walker()
    pos = m.positions.copy()
    pos[5:, 2] = np.nan  # a marker lost after frame 5
    markers = Motion(positions=pos, joint_names=m.joint_names, fps=m.fps, up_axis="y")
    out = render_strip(markers, tmp_path / "m.png", n=3, view="front", panel_size=1.0, dpi=60)
    assert Image.open(out).size == (180, 60) and ink(Image.open(out)) > 5


def test_several_people_and_z_up(tmp_path):
    a, b = walker(), walker(shift=1.0)
    z_up = Motion(
        positions=b.positions[..., [0, 2, 1]], joint_names=b.joint_names, parents=b.parents, fps=b.fps, up_axis="z"
    )
    assert len(as_motions([a, b])) == 2
    out = render_strip([a, b], tmp_path / "two.png", n=2, view="front", panel_size=1.5, dpi=60)
    rgb = np.asarray(Image.open(out).convert("RGB")).astype(int)
    blue = ((rgb[..., 2] - rgb[..., 0]) > 60).sum()
    red = ((rgb[..., 0] - rgb[..., 2]) > 60).sum()
    assert blue > 10 and red > 10  # one colour per person
    render_strip(z_up, tmp_path / "z.png", n=2, panel_size=1.0, dpi=60)
    with pytest.raises(ValueError, match="frame rates"):
        as_motions([a, walker(fps=30.0)])


def test_ntu_sequence_tracks_become_people():
    class Seq:  # duck-typed like ntu_skeleton.SkeletonSequence
        name = "S001C001P001R001A050"
        layout = NTU25
        positions = np.random.default_rng(0).normal(size=(2, 6, 25, 3)).astype(np.float32)

    Seq.positions[1, 3:] = 0.0  # body 2 leaves after frame 3
    people = as_motions(Seq())
    assert len(people) == 2 and people[0].parents == NTU25.parents
    assert people[1].missing[3:].all() and not people[1].missing[:3].any()


def test_mp4_without_ffmpeg_and_unknown_suffix(tmp_path):
    if shutil.which("ffmpeg"):
        pytest.skip("ffmpeg is installed here: the .mp4 path works")
    with pytest.raises(RenderError, match="ffmpeg"):
        render_motion(walker(), tmp_path / "a.mp4")
    with pytest.raises(RenderError, match="suffix"):
        render_motion(walker(), tmp_path / "a.avi")


def test_render_file_goes_through_read_motion(tmp_path, monkeypatch):
    calls = []

    def read_motion(path):
        calls.append(path)
        return walker(frames=16)

    fake = types.ModuleType("mocapkit.datasets.formats.motion_io")
    fake.read_motion = read_motion
    monkeypatch.setitem(sys.modules, "mocapkit.datasets.formats.motion_io", fake)
    out = render_file("clip.bvh", tmp_path / "c.gif", step=8, size=1.5, dpi=40)
    assert calls == ["clip.bvh"] and Image.open(out).n_frames == 2
    out = render_file("clip.bvh", tmp_path / "c.png", strip=True, n=3, panel_size=1.0, dpi=50)
    assert Image.open(out).size == (150, 50)


@needs(BVH_DIR)
def test_real_bvh_strip(tmp_path):
    from mocapkit.datasets.formats.bvh import read_bvh

    m = read_bvh(BVH_DIR / "test_mocapbank.bvh", end_sites=True)
    out = render_strip(m, tmp_path / "bvh.png", n=4, view="front", panel_size=1.5, dpi=60)
    assert Image.open(out).size == (360, 90) and ink(Image.open(out)) > 100


NTU_TWO_PEOPLE = SHARED / "samples" / "ntu_skeleton" / "S001C003P008R002A058.skeleton"


@needs(NTU_TWO_PEOPLE)
def test_real_two_person_ntu_through_read_motion(tmp_path):
    from mocapkit.datasets.formats.motion_io import read_motion

    m = read_motion(NTU_TWO_PEOPLE)
    people = as_motions(m)
    assert len(people) == 1 + len(m.metadata.get("other_bodies", []))
    out = render_file(NTU_TWO_PEOPLE, tmp_path / "ntu.png", strip=True, n=3, view="front", panel_size=1.5, dpi=60)
    rgb = np.asarray(Image.open(out).convert("RGB")).astype(int)
    assert ((rgb[..., 2] - rgb[..., 0]) > 60).sum() > 10
    if len(people) > 1:  # handshake: the second person in red
        assert ((rgb[..., 0] - rgb[..., 2]) > 60).sum() > 10


@needs(BVH_DIR)
def test_real_bvh_gif_through_read_motion(tmp_path):
    out = render_file(BVH_DIR / "test_freebvh.bvh", tmp_path / "f.gif", fps=5, view="front", size=1.5, dpi=50)
    assert Image.open(out).n_frames == len(frame_indices(69, 30.0, fps=5)) == 12
