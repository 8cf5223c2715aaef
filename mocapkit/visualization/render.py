"""Drawing motions: skeleton animations (``.gif`` / ``.mp4``) and still strips (``.png``) with matplotlib.

* :func:`render_motion` animates one or several motions. Several people: a list of
  :class:`~mocapkit.motion.container.Motion`, a Motion with ``metadata["other_bodies"]``
  (what ``read_motion`` returns for a two-person NTU file), or an NTU ``SkeletonSequence``
  whose ``[bodies, frames, 25, 3]`` tracks become one person each; one colour per person.
* :func:`render_strip` draws ``n`` evenly spaced frames side by side into one PNG.
* :func:`render_file` reads any supported file (through
  ``mocapkit.datasets.formats.motion_io.read_motion``) and does one of the two; it is what
  ``mocapkit render FILE --out anim.gif [--strip]`` calls.

Drawing rules, the same for both:

* bones are the segments ``(joint, parent)`` from ``Motion.parents``; a motion without
  a hierarchy (a C3D marker set) is drawn as points only;
* the motion's ``up_axis`` is drawn up; ``view="3d"`` (default) is a perspective-free
  3-D axes at ``elev``/``azim``, ``"front"``, ``"side"`` and ``"top"`` are fixed 2-D
  projections (front: first horizontal axis right, up axis up; side: second horizontal
  axis; top: looking down the up axis);
* axes are equal and their limits fixed over the whole clip (all people included),
  so the figure does not jump; missing joints (NaN) are simply not drawn;
* ``fps`` (output frame rate, default ``min(motion fps, 15)``) or ``step`` (draw every
  ``step``-th frame) keep a long 120 Hz clip to a few seconds of rendering.

Figures are made with ``matplotlib.figure.Figure`` and the Agg canvas, so the
pyplot state and the active backend are left alone.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from mocapkit.motion.container import AXES, Motion

VIEWS = ("3d", "front", "side", "top")
#: Colours of successive people.
PERSON_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown")
DEFAULT_MAX_FPS = 15.0


class RenderError(RuntimeError):
    """Rendering cannot be done as asked (e.g. ``.mp4`` without ffmpeg)."""


# --------------------------------------------------------------------------- inputs


def as_motions(motion) -> list[Motion]:
    """One Motion per person from a Motion, a list of Motions, or an NTU ``SkeletonSequence``.

    A ``SkeletonSequence`` (``positions`` ``[B, T, 25, 3]``, metres, Kinect camera space,
    y up) gives one Motion per body track at 30 fps; frames where a track is absent
    (all zeros) are missing.
    """
    if isinstance(motion, Motion):
        motions = [motion] + _other_bodies(motion)
    elif hasattr(motion, "positions") and hasattr(motion, "layout") and np.ndim(motion.positions) == 4:
        pos = np.asarray(motion.positions, dtype=np.float32)  # [B, T, J, 3]
        layout = motion.layout
        absent = ~np.any(pos != 0, axis=(2, 3))  # [B, T]
        motions = []
        for b in range(pos.shape[0]):
            missing = np.broadcast_to(absent[b][:, None], pos.shape[1:3]).copy()
            motions.append(
                Motion(
                    positions=pos[b],
                    joint_names=layout.joint_names,
                    parents=layout.parents,
                    missing=missing,
                    fps=30.0,
                    up_axis="y",
                    name=f"{getattr(motion, 'name', '')}#{b}",
                    layout_name=layout.name,
                )
            )
    else:
        motions = list(motion)
        if not motions or not all(isinstance(m, Motion) for m in motions):
            raise TypeError("render: expected a Motion, a list of Motions or an NTU SkeletonSequence")
        motions = [person for m in motions for person in [m] + _other_bodies(m)]
    fps = motions[0].fps
    if any(abs(m.fps - fps) > 1e-6 * fps for m in motions):
        raise ValueError(f"render: the people have different frame rates {[m.fps for m in motions]}; resample first")
    if any(m.up_axis != motions[0].up_axis for m in motions):
        raise ValueError("render: the people have different up axes")
    return motions


def _other_bodies(motion: Motion) -> list[Motion]:
    """The extra people of a multi-person Motion (``metadata["other_bodies"]``: ``[frames, joints, 3]``
    arrays on the same skeleton, NaN where absent, as ``read_motion`` gives for NTU files)."""
    out = []
    for k, body in enumerate(motion.metadata.get("other_bodies", []) or []):
        body = np.asarray(body, dtype=np.float32)
        if body.shape != motion.positions.shape:
            continue
        out.append(
            Motion(
                positions=body,
                joint_names=motion.joint_names,
                parents=motion.parents,
                fps=motion.fps,
                up_axis=motion.up_axis,
                name=f"{motion.name}#{k + 1}",
                layout_name=motion.layout_name,
            )
        )
    return out


def frame_indices(num_frames: int, source_fps: float, fps: float | None = None, step: int | None = None) -> np.ndarray:
    """Source frames drawn for an animation, and implicitly its output rate.

    ``step`` wins if given; otherwise ``step = max(1, round(source_fps / fps))`` with
    ``fps`` defaulting to ``min(source_fps, 15)``.
    """
    if step is None:
        target = min(source_fps, DEFAULT_MAX_FPS) if fps is None else float(fps)
        if target <= 0:
            raise ValueError(f"fps must be positive, got {fps}")
        step = max(1, round(source_fps / target))
    if step < 1:
        raise ValueError(f"step must be >= 1, got {step}")
    return np.arange(0, num_frames, int(step))


def _plot_coords(motion: Motion) -> np.ndarray:
    """float32 ``[T, J, 3]`` in plotting axes: right-handed, third axis = the motion's up axis."""
    up = AXES[motion.up_axis]
    h1, h2 = (up + 1) % 3, (up + 2) % 3  # cyclic, so (h1, h2, up) is a proper rotation of (x, y, z)
    p = motion.positions
    if motion.up_axis == "y":  # y up, z towards the viewer: draw x right, -z into the screen
        return np.stack([p[..., 0], -p[..., 2], p[..., 1]], axis=-1)
    return np.stack([p[..., h1], p[..., h2], p[..., up]], axis=-1)


def _project(coords: np.ndarray, view: str) -> np.ndarray:
    """``[..., 3]`` plotting coordinates -> ``[..., 2]`` for a 2-D view (or unchanged for 3-D)."""
    if view == "3d":
        return coords
    if view == "front":
        return coords[..., [0, 2]]
    if view == "side":
        return coords[..., [1, 2]]
    if view == "top":
        return coords[..., [0, 1]]
    raise ValueError(f"view must be one of {VIEWS}, got {view!r}")


def _bone_polyline(coords: np.ndarray, parents: tuple[int, ...] | None) -> np.ndarray | None:
    """``[T, 3 * bones, D]``: child, parent, NaN for every bone (one polyline per frame), or None."""
    if parents is None:
        return None
    bones = [(j, p) for j, p in enumerate(parents) if p >= 0]
    if not bones:
        return None
    child = coords[:, [b[0] for b in bones]]
    parent = coords[:, [b[1] for b in bones]]
    gap = np.full_like(child, np.nan)
    return np.stack([child, parent, gap], axis=2).reshape(coords.shape[0], 3 * len(bones), coords.shape[-1])


class _Scene:
    """A figure with one panel per requested frame (strip) or one panel updated per frame (animation)."""

    def __init__(
        self,
        motions: list[Motion],
        view: str,
        panels: int,
        panel_size: float,
        dpi: int,
        elev: float,
        azim: float,
        title: str | None,
        marker_size: float,
        line_width: float,
    ):
        if view not in VIEWS:
            raise ValueError(f"view must be one of {VIEWS}, got {view!r}")
        self.view = view
        self.coords = [_project(_plot_coords(m), view) for m in motions]
        self.bones = [_bone_polyline(c, m.parents) for c, m in zip(self.coords, motions)]
        self.fps = motions[0].fps
        self.num_frames = max(m.num_frames for m in motions)
        self.fig = Figure(figsize=(panel_size * panels, panel_size), dpi=dpi)
        FigureCanvasAgg(self.fig)
        self.title = title
        lo, hi = self._limits()
        self.axes, self.artists = [], []
        for k in range(panels):
            if view == "3d":
                ax = self.fig.add_subplot(1, panels, k + 1, projection="3d")
                ax.set_box_aspect((1, 1, 1), zoom=1.2)
                ax.view_init(elev=elev, azim=azim)
                ax.set_zlim(lo[2], hi[2])
                for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
                    axis.set_ticklabels([])
            else:
                ax = self.fig.add_subplot(1, panels, k + 1)
                ax.set_aspect("equal", adjustable="box")
                ax.set_xticks([])
                ax.set_yticks([])
            ax.set_xlim(lo[0], hi[0])
            ax.set_ylim(lo[1], hi[1])
            arts = []
            for i, (c, b) in enumerate(zip(self.coords, self.bones)):
                colour = PERSON_COLOURS[i % len(PERSON_COLOURS)]
                empty = [[] for _ in range(c.shape[-1])]
                line = ax.plot(*empty, "-", color=colour, lw=line_width)[0] if b is not None else None
                dots = ax.plot(*empty, "o", color=colour, ms=marker_size, mec="none")[0]
                arts.append((line, dots))
            self.axes.append(ax)
            self.artists.append(arts)
        top = 1.0 - (0.3 if panels > 1 and title else 0.18) * 2.0 / panel_size  # room for the titles
        self.fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=top, wspace=0.04)

    def _limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Equal-sized limits over the whole clip and all people (cube / square around the centre)."""
        allc = np.concatenate([c.reshape(-1, c.shape[-1]) for c in self.coords])
        allc = allc[np.isfinite(allc).all(axis=1)]
        if len(allc) == 0:
            d = self.coords[0].shape[-1]
            return -np.ones(d), np.ones(d)
        lo, hi = allc.min(0), allc.max(0)
        centre = (lo + hi) / 2
        half = max(float((hi - lo).max()) / 2 * 1.05, 1e-3)
        low, high = centre - half, centre + half
        if self.view in ("3d", "front", "side"):  # the floor (lowest point) at the bottom of the frame
            up = low.shape[0] - 1
            low[up] = lo[up] - 0.025 * half
            high[up] = low[up] + 2 * half
        return low, high

    def draw(self, panel: int, frame: int) -> None:
        for (line, dots), c, b in zip(self.artists[panel], self.coords, self.bones):
            if frame >= c.shape[0]:
                pts = np.full((0, c.shape[-1]), np.nan)
                seg = pts
            else:
                pts = c[frame]
                seg = b[frame] if b is not None else None
            self._set(dots, pts)
            if line is not None:
                self._set(line, seg)
        label = f"{frame / self.fps:.2f} s"
        ax = self.axes[panel]
        if len(self.axes) == 1:
            ax.set_title(f"{self.title}   {label}" if self.title else label, fontsize=9)
        else:
            ax.set_title(label, fontsize=8)

    def _set(self, artist, xyz: np.ndarray) -> None:
        if self.view == "3d":
            artist.set_data_3d(xyz[:, 0], xyz[:, 1], xyz[:, 2])
        else:
            artist.set_data(xyz[:, 0], xyz[:, 1])


# --------------------------------------------------------------------------- public API


def render_motion(
    motion,
    out_path: str | os.PathLike,
    fps: float | None = None,
    step: int | None = None,
    title: str | None = None,
    view: str = "3d",
    size: float = 4.0,
    dpi: int = 80,
    elev: float = 15.0,
    azim: float = -70.0,
    marker_size: float = 2.5,
    line_width: float = 1.5,
) -> Path:
    """Animate ``motion`` into ``out_path`` (``.gif`` with Pillow, ``.mp4`` with ffmpeg).

    Args:
        motion: a Motion, a list of Motions (one per person, same fps) or an NTU SkeletonSequence.
        fps: output frames per second (default ``min(motion fps, 15)``); frames are
            subsampled with ``step = round(motion fps / fps)``, so playback keeps real time
            up to rounding.
        step: draw every ``step``-th frame instead (then output fps = motion fps / step unless ``fps`` is given).
        title: text above the axes (the time in seconds is always shown).
        view: ``"3d"``, ``"front"``, ``"side"`` or ``"top"``.
        size: figure height (and width) in inches; the image is ``size * dpi`` pixels square.

    Returns:
        ``out_path``. The number of frames written is ``len(frame_indices(...))``.

    Raises:
        RenderError: ``.mp4`` asked for and ffmpeg is not available, or an unknown suffix.
    """
    from matplotlib.animation import FFMpegWriter, PillowWriter, writers

    motions = as_motions(motion)
    out_path = Path(out_path)
    suffix = out_path.suffix.lower()
    scene = _Scene(motions, view, 1, size, dpi, elev, azim, title, marker_size, line_width)
    frames = frame_indices(scene.num_frames, scene.fps, fps=fps, step=step)
    used_step = int(frames[1] - frames[0]) if len(frames) > 1 else 1
    out_fps = float(fps) if fps is not None else scene.fps / used_step
    if suffix == ".gif":
        writer = PillowWriter(fps=out_fps)
    elif suffix == ".mp4":
        if not (writers.is_available("ffmpeg") and shutil.which("ffmpeg")):
            raise RenderError(
                f"cannot write {out_path}: .mp4 needs the ffmpeg program, which is not installed "
                "(install ffmpeg or write a .gif)"
            )
        writer = FFMpegWriter(fps=out_fps)
    else:
        raise RenderError(f"cannot write {out_path}: unknown suffix {suffix!r} (use .gif or .mp4)")
    out_path.parent.mkdir(parents=True, exist_ok=True)
    with writer.saving(scene.fig, str(out_path), dpi):
        for t in frames:
            scene.draw(0, int(t))
            writer.grab_frame()
    return out_path


def render_strip(
    motion,
    out_png: str | os.PathLike,
    n: int = 8,
    title: str | None = None,
    view: str = "3d",
    panel_size: float = 2.0,
    dpi: int = 100,
    elev: float = 15.0,
    azim: float = -70.0,
    marker_size: float = 2.0,
    line_width: float = 1.2,
) -> Path:
    """Write a PNG of ``n`` evenly spaced frames (first and last included) side by side.

    The image is exactly ``(n * panel_size * dpi) x (panel_size * dpi)`` pixels
    (1600 x 200 by default). Same inputs and drawing rules as :func:`render_motion`.
    """
    motions = as_motions(motion)
    if n < 1:
        raise ValueError(f"n must be >= 1, got {n}")
    scene = _Scene(motions, view, n, panel_size, dpi, elev, azim, title, marker_size, line_width)
    picks = np.linspace(0, scene.num_frames - 1, n).round().astype(int)
    for k, t in enumerate(picks):
        scene.draw(k, int(t))
    if title:
        scene.fig.suptitle(title, fontsize=9, y=0.99)
    out_png = Path(out_png)
    out_png.parent.mkdir(parents=True, exist_ok=True)
    scene.fig.savefig(out_png, dpi=dpi, format="png")
    return out_png


def render_file(path: str | os.PathLike, out: str | os.PathLike, strip: bool = False, **options) -> Path:
    """Read ``path`` with ``read_motion`` (any supported format) and render it to ``out``.

    ``strip=True`` writes :func:`render_strip` (``options`` may hold ``n``), otherwise
    :func:`render_motion`; the title defaults to the file name.
    """
    from mocapkit.datasets.formats.motion_io import read_motion

    motion = read_motion(path)
    options.setdefault("title", Path(path).name)
    if strip:
        return render_strip(motion, out, **options)
    return render_motion(motion, out, **options)


__all__ = ["VIEWS", "RenderError", "as_motions", "frame_indices", "render_file", "render_motion", "render_strip"]
