"""Benchmark: motion-file reader throughput, mocapkit's readers against plain readers, in one run.

For every format in :data:`CASES` whose mocapkit reader exists, both readers read
the same real sample files (``shared/samples/<format>`` next to the repository),
their results are checked to agree, and files/s, frames/s and the ratio are
printed as a Markdown table. Timings are the best of ``--repeat`` rounds, the two
readers interleaved in every round so that other load on the machine hits both.

The *plain* reader of a format is written the usual way of public repositories
(e.g. PyMO / bvh-python for BVH): ``readline``, ``split()`` and one ``float()`` per
value, and forward kinematics as Python loops over frames and joints with small
numpy matrices. It is part of this file, so the comparison is reproducible.

Adding a format (ASF/AMC, C3D, MSR Action3D) is one :class:`Case` in :data:`CASES`:
the sample glob, the import path of our reader, a plain reader, and how to get
``[frames, joints, 3]`` metres from each for the agreement check. Cases whose
reader module is not there yet are listed as skipped.

Usage: ``python bench/bench_readers.py [--repeat 3] [--copies 3] [--formats bvh] [--src DIR]``
"""

from __future__ import annotations

import argparse
import importlib
import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from timing import best_of  # bench/timing.py, beside this script

DEFAULT_SRC = Path(__file__).resolve().parents[1].parent / "shared" / "samples"


# --------------------------------------------------------------------------- plain readers


def plain_read_bvh(path: str | Path, scale: float = 1.0) -> np.ndarray:
    """A plain BVH reader: per-line parsing, ``float()`` per value, per-frame per-joint FK in Python.

    Returns float64 ``[frames, joints, 3]`` positions (file units × ``scale``), End Sites
    excluded, with the same conventions as :func:`mocapkit.datasets.formats.bvh.read_bvh`
    (intrinsic rotations in channel order, position channels replace the OFFSET).
    """
    names, parents, offsets, channels = [], [], [], []
    stack: list[int] = []
    in_end = False
    with open(path) as f:
        for line in f:
            tok = line.split()
            if not tok:
                continue
            key = tok[0]
            if key in ("ROOT", "JOINT"):
                names.append(" ".join(tok[1:]))
                parents.append(stack[-1] if stack else -1)
                offsets.append([0.0, 0.0, 0.0])
                channels.append([])
                stack.append(len(names) - 1)
            elif key == "End":
                in_end = True
            elif key == "OFFSET":
                if not in_end:
                    offsets[stack[-1]] = [float(v) for v in tok[1:4]]
            elif key == "CHANNELS":
                channels[stack[-1]] = tok[2 : 2 + int(tok[1])]
            elif key == "}":
                if in_end:
                    in_end = False
                else:
                    stack.pop()
            elif key == "MOTION":
                break
        num_frames = int(f.readline().split()[1])
        f.readline()  # Frame Time
        frames = []
        for _ in range(num_frames):
            frames.append([float(v) for v in f.readline().split()])

    def axis_matrix(axis: str, deg: float) -> np.ndarray:
        a = np.radians(deg)
        c, s = np.cos(a), np.sin(a)
        if axis == "X":
            return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        if axis == "Y":
            return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    out = np.zeros((num_frames, len(names), 3))
    for t, values in enumerate(frames):
        k = 0
        glob = [None] * len(names)
        for j in range(len(names)):
            rot = np.eye(3)
            trans = np.array(offsets[j], dtype=float)
            for ch in channels[j]:
                v = values[k]
                k += 1
                if ch.endswith("position"):
                    trans["XYZ".index(ch[0])] = v
                else:
                    rot = rot @ axis_matrix(ch[0], v)
            p = parents[j]
            if p < 0:
                glob[j] = rot
                out[t, j] = trans
            else:
                glob[j] = glob[p] @ rot
                out[t, j] = out[t, p] + glob[p] @ trans
    return out * scale


def plain_read_amc(path: str | Path) -> np.ndarray:
    """A plain AMC reader in the style of the common CMU parsers: per-line parsing, ``float()``
    per value, then FK per frame and per bone with small numpy matrices (``L = C·M·C⁻¹``).

    The ASF is parsed with mocapkit's ``read_asf`` (the benchmark times the AMC and the FK).
    Returns float64 ``[frames, joints, 3]`` metres: root, then the bones in ASF order.
    """
    from mocapkit.datasets.formats.asf_amc import find_asf, read_asf

    skel = read_asf(find_asf(path))
    to_rad = np.pi / 180.0 if skel.units.get("angle", "deg") == "deg" else 1.0
    metres = skel.metres_per_unit

    def axis_matrix(axis: str, angle: float) -> np.ndarray:
        c, s = np.cos(angle), np.sin(angle)
        if axis == "x":
            return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
        if axis == "y":
            return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
        return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])

    def euler(axes, angles) -> np.ndarray:  # fixed axes, first named applied first
        m = np.eye(3)
        for a, v in zip(axes, angles):
            m = axis_matrix(a.lower()[-1], v * to_rad) @ m
        return m

    frames: list[dict] = []
    with open(path, encoding="latin-1") as f:
        for line in f:
            tok = line.split()
            if not tok or tok[0].startswith(("#", ":")):
                continue
            if tok[0].isdigit():
                frames.append({})
            else:
                frames[-1][tok[0]] = [float(v) for v in tok[1:]]
    bones = {b.name: b for b in skel.bones}
    parent = {child: par for par, children in skel.hierarchy.items() for child in children}
    names = ["root"] + [b.name for b in skel.bones]
    out = np.zeros((len(frames), len(names), 3))
    c_root = euler(skel.root_axis, skel.root_orientation)
    for t, values in enumerate(frames):
        root = dict(zip(skel.root_order, values["root"]))
        m_root = euler([k for k in skel.root_order if k[0] == "R"], [root[k] for k in skel.root_order if k[0] == "R"])
        rot = {"root": c_root @ m_root @ c_root.T}
        pos = {"root": (skel.root_position + np.array([root.get(k, 0.0) for k in ("TX", "TY", "TZ")])) * metres}
        for name in names[1:]:
            b = bones[name]
            c = euler(b.axis_order, b.axis)
            m = euler(b.dof, values.get(name, [])) if b.dof else np.eye(3)
            rot[name] = rot[parent[name]] @ c @ m @ c.T
            pos[name] = pos[parent[name]] + rot[name] @ (b.direction * b.length * metres)
        out[t] = [pos[n] for n in names]
    return out


def plain_read_msr(path: str | Path) -> np.ndarray:
    """A plain MSR Action3D reader: per-line ``split()`` and ``float()``, 20 rows a frame."""
    rows = []
    with open(path) as f:
        for line in f:
            tok = line.split()
            if tok:
                rows.append([float(v) for v in tok])
    return np.array(rows)[:, :3].reshape(-1, 20, 3)


def plain_read_c3d(path: str | Path) -> np.ndarray:
    """The pure-Python ``c3d`` package's frame loop (the usual alternative to a compiled reader),
    metres; invalid points (negative residual) as NaN."""
    import c3d  # optional: pip install c3d

    with open(path, "rb") as handle:
        reader = c3d.Reader(handle)
        units = reader.get("POINT").get("UNITS").string_value.strip().lower()
        scale = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}.get(units, 1e-3)
        frames = []
        for _, points, _ in reader.read_frames():
            xyz = points[:, :3] * scale
            xyz[points[:, 3] < 0] = np.nan
            frames.append(xyz)
    return np.array(frames)


def ezc3d_read_c3d(path: str | Path) -> np.ndarray:
    """The compiled ezc3d reader (what ``read_c3d`` used before it decoded files itself), metres; invalid points
    (negative residual) as NaN, as ezc3d returns them."""
    import ezc3d

    c3d = ezc3d.c3d(str(path))
    units = str(c3d["parameters"]["POINT"]["UNITS"]["value"][0]).strip().lower()
    scale = {"mm": 1e-3, "cm": 1e-2, "m": 1.0}.get(units, 1e-3)
    return np.transpose(c3d["data"]["points"][:3], (2, 1, 0)) * scale


# --------------------------------------------------------------------------- cases


@dataclass
class Case:
    """One format to benchmark.

    Attributes:
        fmt: label, e.g. ``"bvh"``.
        pattern: glob of sample files under ``--src`` (e.g. ``"bvh/*.bvh"``).
        ours: ``"module:function"`` of the mocapkit reader (imported lazily; missing -> skipped).
        plain: the plain reader, ``path -> anything``.
        ours_positions: ``our result -> [frames, joints, 3]`` metres, for the agreement check.
        plain_positions: ``(path, our result, plain result) -> [frames, joints, 3]`` metres.
        frames: ``our result -> number of frames``.
        atol: agreement tolerance in metres.
    """

    fmt: str
    pattern: str
    ours: str
    plain: Callable
    ours_positions: Callable
    plain_positions: Callable
    frames: Callable
    atol: float = 1e-5


def _bvh_plain_positions(path, ours, plain):
    return plain * ours.metadata["scale"]  # the plain reader has no unit inference: reuse the decision


CASES: list[Case] = [
    Case(
        "bvh",
        "bvh/*.bvh",
        "mocapkit.datasets.formats.bvh:read_bvh",
        plain_read_bvh,
        ours_positions=lambda m: m.positions,
        plain_positions=_bvh_plain_positions,
        frames=lambda m: m.num_frames,
    ),
    Case(
        "asf/amc",
        "asf_amc/**/*.amc",
        "mocapkit.datasets.formats.asf_amc:read_amc",
        plain_read_amc,
        ours_positions=lambda m: m.positions,
        plain_positions=lambda path, ours, plain: plain,
        frames=lambda m: m.num_frames,
    ),
    Case(
        "msr3d",
        "msr3d/*_skeleton3D.txt",
        "mocapkit.datasets.formats.msr_action3d:read_msr_skeleton",
        plain_read_msr,
        # ours marks all-zero joints missing; the raw file has zeros
        ours_positions=lambda m: m.filled(0.0),
        plain_positions=lambda path, ours, plain: plain,
        frames=lambda m: m.num_frames,
    ),
    Case(
        "c3d",
        "c3d/*.c3d",
        "mocapkit.datasets.formats.c3d:read_c3d",
        plain_read_c3d,
        ours_positions=lambda m: np.nan_to_num(m.positions, nan=0.0),
        plain_positions=lambda path, ours, plain: np.nan_to_num(_c3d_like_ours(ours, plain), nan=0.0),
        frames=lambda m: m.num_frames,
        atol=1e-4,
    ),
    Case(
        "c3d vs ezc3d",
        "c3d/*.c3d",
        "mocapkit.datasets.formats.c3d:read_c3d",
        ezc3d_read_c3d,
        ours_positions=lambda m: np.nan_to_num(m.positions, nan=0.0),
        plain_positions=lambda path, ours, plain: np.nan_to_num(_c3d_like_ours(ours, plain), nan=0.0),
        frames=lambda m: m.num_frames,
        atol=1e-6,
    ),
]


def _c3d_like_ours(ours, plain: np.ndarray) -> np.ndarray:
    """The plain reader's points restricted to the markers ours keeps, with ours' gap rule."""
    plain = plain[:, : ours.num_joints]
    return np.where(ours.missing[..., None], np.nan, plain)


def _load(spec: str):
    module, _, name = spec.partition(":")
    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError):
        return None


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--src", type=Path, default=DEFAULT_SRC, help="the shared samples folder")
    parser.add_argument("--repeat", type=int, default=3, help="rounds; the best is reported")
    parser.add_argument("--copies", type=int, default=1, help="read every file this many times per round")
    parser.add_argument("--formats", nargs="*", default=None, help="only these formats (default: all)")
    args = parser.parse_args(argv)

    rows, skipped = [], []
    for case in CASES:
        if args.formats and case.fmt not in args.formats:
            continue
        ours = _load(case.ours)
        files = sorted(args.src.glob(case.pattern))
        if ours is None:
            skipped.append(f"{case.fmt}: reader {case.ours} not available")
            continue
        try:
            case.plain(files[0]) if files else None
        except ImportError as exc:
            skipped.append(f"{case.fmt}: plain reader needs {exc.name} (pip install {exc.name})")
            continue
        if not files:
            skipped.append(f"{case.fmt}: no files match {args.src / case.pattern}")
            continue
        frames = 0
        for f in files:  # agreement first: the speeds mean nothing otherwise (also warms the page cache)
            mine = ours(f)
            theirs = case.plain_positions(f, mine, case.plain(f))
            np.testing.assert_allclose(case.ours_positions(mine), theirs, rtol=0, atol=case.atol, err_msg=str(f))
            frames += case.frames(mine)
        work = files * args.copies
        best = best_of(
            {
                "plain": lambda plain=case.plain, work=work: [plain(f) for f in work],
                "ours": lambda ours=ours, work=work: [ours(f) for f in work],
            },
            args.repeat,
        )
        n, nf = len(work), frames * args.copies
        rows.append((case.fmt, len(files), n, nf, best["plain"], best["ours"]))

    load = os.getloadavg()[0]
    print(f"\nbest of {args.repeat} rounds; {os.cpu_count()} CPUs, load average {load:.2f}\n")
    print("| format | files (reads) | frames | reader | s | files/s | frames/s | ours vs plain |")
    print("|---|---:|---:|---|---:|---:|---:|---:|")
    for fmt, nfiles, n, nf, plain, mine in rows:
        print(f"| {fmt} | {nfiles} ({n}) | {nf} | plain | {plain:.3f} | {n / plain:.1f} | {nf / plain:.0f} | |")
        print(
            f"| {fmt} | {nfiles} ({n}) | {nf} | mocapkit | {mine:.3f} | {n / mine:.1f} | {nf / mine:.0f} "
            f"| **{plain / mine:.1f}x** |"
        )
    for s in skipped:
        print(f"skipped: {s}")
    if not rows:
        print("nothing measured (no reader or no sample files)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
