"""One entry point for every motion file format: :func:`read_motion` and :func:`write_motion`.

The format is chosen from the file name:

============================== ======== ================================================ ======
file name                      format   reader                                           writer
============================== ======== ================================================ ======
``*.amc`` (``.asf`` beside it) ``amc``  ``mocapkit.datasets.formats.asf_amc.read_amc``           yes
``*.bvh``                      ``bvh``  ``mocapkit.datasets.formats.bvh.read_bvh``               yes
``*.c3d``                      ``c3d``  :func:`mocapkit.datasets.formats.c3d.read_c3d`           yes
``*_skeleton3D.txt``,          ``msr``  ``mocapkit.datasets.msr_action3d.dataset.               no
``*_skeleton.txt``                      read_msr_skeleton``
``*.skeleton``                 ``ntu``  NTU ``read_skeleton`` + ``select_main_bodies``   yes
============================== ======== ================================================ ======

Readers are imported only when a file of their format is read, so every format whose
module is present works even while another one is missing; a missing reader raises
:class:`FormatUnavailableError` naming the format. Keyword options go to the reader
(``asf=`` for AMC, ``labels=`` for C3D, ``max_bodies=`` for NTU...).

NTU files hold several tracked bodies: the :class:`Motion` is the body with the most
motion (``select_main_bodies``), on the ``ntu25`` layout at 30 fps, missing in the frames
where that body is not tracked; the other kept bodies are in
``metadata["other_bodies"]`` (float32 ``[frames, 25, 3]`` arrays, NaN where absent).
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path

import numpy as np

from mocapkit.motion.container import Motion, any_coordinate

#: format -> (description, module, reader function, writer function or None)
FORMATS: dict[str, tuple[str, str, str, str | None]] = {
    "amc": ("ASF/AMC motion (.amc with its .asf)", "mocapkit.datasets.formats.asf_amc", "read_amc", "write_amc"),
    "bvh": ("BVH (.bvh)", "mocapkit.datasets.formats.bvh", "read_bvh", "write_bvh"),
    "c3d": ("C3D markers (.c3d)", "mocapkit.datasets.formats.c3d", "read_c3d", "write_c3d"),
    "msr": (
        "MSR Action3D skeleton text (*_skeleton3D.txt, *_skeleton.txt)",
        "mocapkit.datasets.formats.msr_action3d",
        "read_msr_skeleton",
        None,
    ),
    "ntu": ("NTU RGB+D skeleton (.skeleton)", "mocapkit.datasets.formats.motion_io", "_read_ntu", "_write_ntu"),
}

#: Kinect v2 frame rate of NTU RGB+D.
NTU_FPS = 30.0


class UnsupportedFormatError(ValueError):
    """A file name whose format mocapkit does not read (or write). The message lists the supported ones."""


class FormatUnavailableError(ImportError):
    """The module that reads (or writes) a supported format cannot be imported."""


def motion_format(path: str | os.PathLike) -> str:
    """The format key (``"amc"``, ``"bvh"``, ``"c3d"``, ``"msr"``, ``"ntu"``) of a file name."""
    name = Path(path).name.lower()
    if name.endswith(("_skeleton3d.txt", "_skeleton.txt")):
        return "msr"
    suffix = Path(name).suffix
    by_suffix = {".amc": "amc", ".bvh": "bvh", ".c3d": "c3d", ".skeleton": "ntu"}
    if suffix in by_suffix:
        return by_suffix[suffix]
    hint = ""
    if suffix == ".asf":
        hint = " (an .asf file holds only the skeleton: read the .amc motion, which finds its .asf)"
    raise UnsupportedFormatError(f"{path}: unknown motion file type{hint}; supported: {_supported()}")


def is_motion_file(path: str | os.PathLike) -> bool:
    """Whether the file name is one of the formats :func:`read_motion` reads (by name only; the file is not opened)."""
    try:
        motion_format(path)
    except UnsupportedFormatError:
        return False
    return True


def find_motion_files(folder: str | os.PathLike) -> list[Path]:
    """Every file under ``folder`` (recursively, sorted) whose name :func:`read_motion` reads (``.asf`` skeletons,
    texts and other files are not motions and are not listed)."""
    return sorted(p for p in Path(folder).rglob("*") if p.is_file() and is_motion_file(p))


def expand_motion_paths(paths, what: str = "input", empty_error: type[Exception] = ValueError) -> list[Path]:
    """Files and folders (searched recursively with :func:`find_motion_files`) → the motion files, in order.

    Raises:
        FileNotFoundError: a path that does not exist (``"<what> <path>: no such file or folder"``).
        empty_error: a folder without motion files, naming it.
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    files: list[Path] = []
    for path in map(Path, paths):
        if path.is_dir():
            found = find_motion_files(path)
            if not found:
                raise empty_error(
                    f"{what} {path}: no motion files in this folder (looked for .c3d, .amc, .bvh, "
                    f".skeleton, MSR *_skeleton3D.txt)"
                )
            files += found
        elif path.is_file():
            files.append(path)
        else:
            raise FileNotFoundError(f"{what} {path}: no such file or folder")
    return files


def read_motion(path: str | os.PathLike, **options) -> Motion:
    """Read any supported motion file into a :class:`Motion` (see the module docstring).

    Raises:
        UnsupportedFormatError: the file name matches no supported format.
        FormatUnavailableError: the format's reader module is not available.
        The reader's own errors (e.g. ``C3DFormatError``, ``SkeletonFormatError``) for damaged files.
    """
    fmt = motion_format(path)
    reader = _load(fmt, 2, "reading")
    if fmt == "amc":
        motion = reader(path, asf=options.pop("asf", None), **options)
    else:
        motion = reader(path, **options)
    if not isinstance(motion, Motion):
        raise TypeError(f"{FORMATS[fmt][1]}.{FORMATS[fmt][2]} returned {type(motion).__name__}, not a Motion")
    return motion


def write_motion(path: str | os.PathLike, motion: Motion, **options) -> None:
    """Write ``motion`` in the format given by the file name (``.c3d``, ``.bvh``, ``.amc``, ``.skeleton``).

    Options go to the writer (e.g. ``units="m"`` for C3D).
    """
    fmt = motion_format(path)
    if FORMATS[fmt][3] is None:
        writable = ", ".join(FORMATS[f][0] for f in FORMATS if FORMATS[f][3])
        raise UnsupportedFormatError(f"{path}: mocapkit does not write {FORMATS[fmt][0]}; writable: {writable}")
    _load(fmt, 3, "writing")(path, motion, **options)


def _supported() -> str:
    return ", ".join(description for description, *_ in FORMATS.values())


def _load(fmt: str, which: int, doing: str):
    description, module_name, *functions = FORMATS[fmt]
    function = functions[which - 2]
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        missing = getattr(exc, "name", None)
        what = (
            f"{module_name} is not available"
            if missing == module_name
            else f"{module_name} could not be imported ({exc})"
        )
        raise FormatUnavailableError(f"{doing} {description} needs {module_name}.{function}, but {what}") from exc
    try:
        return getattr(module, function)
    except AttributeError:
        raise FormatUnavailableError(
            f"{doing} {description} needs {module_name}.{function}, which {module_name} does not define"
        ) from None


# --------------------------------------------------------------------------- NTU


def _read_ntu(path: str | os.PathLike, max_bodies: int = 2, **selection_options) -> Motion:
    """An NTU ``.skeleton`` file as a Motion of its main body.

    ``selection_options`` go to ``select_main_bodies`` (``denoise_spread``, ``min_frames``,
    ``denoise_flicker``, ...); its defaults are those of ``mocapkit prepare ntu``.
    """
    from mocapkit.datasets.formats.ntu_skeleton import read_skeleton, select_main_bodies
    from mocapkit.motion.layouts import NTU25

    seq = read_skeleton(path)
    selection = select_main_bodies(seq, max_bodies=max_bodies, **selection_options)
    bodies = []
    for track in selection.kept:
        body = seq.positions[track].copy()  # [T, 25, 3], zeros where absent
        body[~seq.present[track]] = np.nan
        bodies.append(body)
    if bodies:
        main = bodies[0]
    else:  # no tracked body at all: everything missing
        main = np.full((seq.num_frames, len(NTU25.joint_names), 3), np.nan, dtype=np.float32)
    metadata = {
        "format": "ntu",
        "other_bodies": bodies[1:],
        "body_ids": [seq.body_ids[t] for t in selection.kept],
        "kept_tracks": list(selection.kept),
        "dropped_tracks": dict(selection.dropped),
        "num_tracks": seq.num_bodies,
    }
    try:
        metadata["sample"] = str(seq.sample)
        metadata["label"] = seq.sample.label
    except ValueError:
        pass
    return Motion(
        positions=main,
        joint_names=NTU25.joint_names,
        parents=NTU25.parents,
        fps=NTU_FPS,
        source_units="m",
        up_axis="y",
        name=seq.name,
        source=str(path),
        layout_name=NTU25.name,
        metadata=metadata,
    )


def _write_ntu(path: str | os.PathLike, motion: Motion, body_ids: list[int] | None = None) -> None:
    """Write a Motion on the ``ntu25`` layout (plus ``metadata["other_bodies"]``) as a ``.skeleton`` file.

    A body is written in the frames where at least one of its joints is present; missing
    joints within a written frame become zeros (the file has no per-joint gap marker).
    Only positions survive: depth/colour pixels are re-projected and orientations are identity.
    """
    from mocapkit.datasets.formats.ntu_skeleton import (
        sequence_from_positions,
        write_skeleton,
    )
    from mocapkit.motion.layouts import NTU25

    if tuple(motion.joint_names) != NTU25.joint_names:
        raise ValueError(
            f"{motion.source or motion.name}: only motions on the ntu25 layout can be written as "
            f".skeleton (map_layout(NTU25) first)"
        )
    bodies = [motion.positions] + [np.asarray(b, dtype=np.float32) for b in motion.metadata.get("other_bodies", [])]
    stacked = np.stack(bodies)  # [B, T, 25, 3]
    present = ~any_coordinate(np.isnan(stacked)).all(axis=2)  # [B, T]
    stacked = np.nan_to_num(stacked, nan=0.0)
    if body_ids is None:
        ids = list(motion.metadata.get("body_ids", []))
        body_ids = ids if len(ids) == len(bodies) else None
    name = Path(path).name[: -len(".skeleton")] if str(path).endswith(".skeleton") else Path(path).stem
    write_skeleton(path, sequence_from_positions(name, stacked, body_ids=body_ids, present=present))
