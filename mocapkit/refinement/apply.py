"""Refine a motion file: what ``mocapkit refine IN OUT --method NAME [--set key=value ...] [--train PATH ...]`` runs
(and ``--method RUN/best.ckpt`` / ``--onnx FILE``: a trained refiner network).

The refiners are the registry's refinement methods (:mod:`mocapkit.train.registry`):
``configs/refinement/method/<NAME>.yaml`` = ``{_target_: the MotionRefiner class, its parameters with their
defaults}`` (``mocapkit methods refinement`` lists them); :func:`~mocapkit.train.registry.build_method` builds one with the ``--set``
overrides (Hydra's grammar on that node: ``--set extrapolate=hold``, ``--set outlier_threshold=null``). The
benchmark builds its refiners from the same files.

:func:`refine_file` reads anything :func:`~mocapkit.datasets.formats.motion_io.read_motion` reads, fits the
refiner on the ``--train`` motions (required when ``refiner.requires_fit``; used when given otherwise, e.g. the
optional clean frames of PCA), refines and writes:

**Trained refiner networks** need no ``--train``: ``--method PATH.ckpt`` (a run of ``mocapkit train
experiment=refine_bigru``) is :class:`~mocapkit.refinement.learned.LearnedRefiner` loaded from that checkpoint,
``--onnx FILE`` (its ``mocapkit export``) is :class:`~mocapkit.refinement.learned.OnnxRefiner`, run with
onnxruntime and numpy only (torch is never imported on that path). They are the registry's ``learned`` and
``onnx`` entries with the file as ``checkpoint`` / ``path``; ``--set`` takes their other parameters (``window``,
``overlap``, ``repair_threshold``, ``max_empty_frames``, ``short_gap_frames``, ``short_gap_points``; ``device`` of
the checkpoint, ``threads`` of the ONNX session). The input must hold the joints the network was trained on
(names; any order, extra markers are left as they are) and its up axis; a take at another frame rate is refined
at the network's and brought back (:mod:`mocapkit.refinement.base`; the report says so); the report names the
file as the method.

**C3D in, C3D out** (the everyday case: a Vicon or Qualisys export with gaps). The file is not re-encoded from
the Motion: :func:`~mocapkit.datasets.formats.c3d.patch_samples` writes a byte copy of the source in which only the
samples the refiner changed (filled gaps, and the observed samples a robust method repaired as outliers) are
overwritten, in the file's own storage (float or integer, Intel, DEC or MIPS): coordinates converted back to the
file's ``POINT:UNITS`` at the same marker index (``read_c3d`` keeps the file's marker order; a ``Subject:`` prefix
it strips changes names, not indices), residual 0 (valid: in C3D a zero residual marks a computed, not measured,
point) and an empty camera mask. Every other byte is kept: header, parameters, labels, analog data, events, and
every other sample bit-identical. In integer storage (``POINT:SCALE > 0``, e.g. ``Eb015pi.c3d``) filled values are
quantised to the file's scale (0.083 mm on Eb015pi); a value outside int16 range is an error naming marker and
frame. The written copy is decoded and checked (only the changed samples' bytes differ, each reads back valid at
its value) before it replaces the output path.

Samples the refiner could not fill (leading/trailing gaps for the interpolations, a marker missing in every
frame) are left as they were in the source (invalid, or the all-zero coordinates some writers use for gaps,
which ``read_c3d`` reads as missing) and reported.

**Anything else** (AMC, BVH, NTU, MSR joint positions, or C3D to ``.npz``): ``.c3d`` out writes the refined
positions with :func:`~mocapkit.datasets.formats.c3d.write_c3d` (labels = joint names, millimetres, still-missing
samples invalid), so ``read_motion`` reads them back on the same layout; ``.npz`` out holds ``positions`` float32
``[frames, joints, 3]`` metres (NaN where still missing), ``missing`` and ``filled`` (bool ``[frames, joints]``),
``joint_names`` and ``fps``.

The :class:`RefineReport` lists, per marker with gaps, the samples filled, the longest gap filled (frames and
seconds), the samples repaired, and the samples left missing with their frames and the reason. Bad input (every
sample missing, NaN/Inf in observed entries, a take shorter than the method needs, a data-driven refiner applied
to another skeleton layout, unreadable files) raises a ``ValueError`` subclass whose message names the file.
"""

from __future__ import annotations

import dataclasses
import inspect
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.io_atomic import atomic_open
from mocapkit.motion.container import Motion, any_coordinate
from mocapkit.motion.frames import true_runs
from mocapkit.refinement.base import MotionRefiner

#: ``mocapkit refine --screen-outliers`` warns when the screen hides more than this share of the observed samples
#: (on clean real takes at 120 fps it hides 0–0.3 %, at 30 fps up to 40 %: ``scripts/screen_clean_takes.py``).
SCREEN_WARN_SHARE = 0.02

#: Output suffixes :func:`refine_file` writes.
OUTPUT_SUFFIXES = (".c3d", ".npz")


class RefineError(ValueError):
    """A refine run that cannot go on (bad output name, unusable training data, a write that failed its check)."""


# --------------------------------------------------------------------------- the methods (the registry)


def trained_model_kind(method: str | os.PathLike | None) -> str | None:
    """``"checkpoint"`` for a ``--method`` ending in ``.ckpt``, ``"onnx"`` for one ending in ``.onnx``, else None
    (a method name of the registry)."""
    if method is None:
        return None
    return {".ckpt": "checkpoint", ".onnx": "onnx"}.get(Path(str(method)).suffix.lower())


def build_learned_refiner(
    path: str | os.PathLike, overrides: Sequence[str] = (), onnx: bool = False, fit: bool = True
) -> MotionRefiner:
    """The registry's ``learned`` entry with ``checkpoint=path`` (``onnx``: its ``onnx`` entry with ``path=path``)
    and the ``--set`` Hydra ``overrides``, loaded (``fit()``) unless ``fit=False``. The ONNX refiner never
    imports torch.

    Raises:
        ConfigError: an unknown key (the message names the file and lists the parameters), a bad value, a checkpoint
            that is missing or not a refiner's.
        FileNotFoundError / RefinementError: an ONNX file that is missing or not a refiner export.
    """
    from mocapkit.train.errors import ConfigError
    from mocapkit.train.registry import build_method

    name, key = ("onnx", "path") if onnx else ("learned", "checkpoint")
    for item in overrides:  # the model file is the command's (--method / --onnx), not a --set
        if item.split("=", 1)[0].lstrip("+~") == key:
            raise ConfigError(f"--set {item}: {path} is the model; the trained refiner has no parameter {key!r} to set")
    try:
        refiner = build_method("refinement", name, [*overrides, f"{key}={_quoted(path)}"])
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    return refiner.fit() if fit else refiner


def _quoted(path: str | os.PathLike) -> str:
    """A path as a Hydra override value (quoted: a path may hold characters Hydra's grammar reads)."""
    text = str(path).replace("\\", "\\\\").replace("'", "\\'")
    return f"'{text}'"


# --------------------------------------------------------------------------- the report


@dataclass
class MarkerReport:
    """What happened to one marker (joint) that had gaps or repairs. Frames are 0-based indices into the take."""

    name: str
    index: int
    missing: int  # samples missing in the input
    filled: int  # of those, filled
    longest_gap: int  # longest run of consecutive filled frames
    repaired: int = 0  # observed samples replaced as outliers (robust methods)
    #: (first, last, reason), inclusive; reason: "leading" / "trailing" (before the first / after the last
    #: observation), "missing in every frame" or "interior, not filled by the method"
    unfilled: list[tuple[int, int, str]] = field(default_factory=list)

    @property
    def left_missing(self) -> int:
        return sum(last - first + 1 for first, last, _ in self.unfilled)


@dataclass
class RefineReport:
    """The outcome of :func:`refine_file` (``to_text()`` is what ``mocapkit refine`` prints)."""

    source: str
    output: str
    method: str
    refiner: str  # class name
    fps: float
    frames: int
    markers: list[MarkerReport]  # markers with gaps or repairs, in file order
    training: list[str] = field(default_factory=list)  # training files used
    skipped: list[tuple[str, str]] = field(default_factory=list)  # (training file, why) with --skip-bad
    write_mode: str = ""  # how the output was written
    hint: str = ""
    refined_at_fps: float | None = None  # the rate a fixed-rate refiner worked at, when not the take's
    refined_at_up_axis: str | None = None  # the up axis a fixed-frame refiner worked in, when not the take's
    up_axis: str = "y"  # the take's
    screened: tuple[int, int] | None = None  # --screen-outliers: (samples the screen hid, observed samples)
    warning: str = ""
    #: C3D samples whose coordinates were not finite although their residual said valid (read as gaps)
    nan_gaps: int = 0

    @property
    def filled(self) -> int:
        return sum(m.filled for m in self.markers)

    @property
    def missing(self) -> int:
        return sum(m.missing for m in self.markers)

    @property
    def left_missing(self) -> dict[str, list[tuple[int, int, str]]]:
        """``{marker: [(first, last, reason), ...]}`` of the samples still missing."""
        return {m.name: m.unfilled for m in self.markers if m.unfilled}

    def to_text(self) -> str:
        lines = [f"{self.source}: {self.frames} frames at {self.fps:g} fps; method {self.method} ({self.refiner})"]
        if self.refined_at_fps is not None:
            lines.append(
                f"refined at the model's {self.refined_at_fps:g} fps: the take resampled linearly, the gaps "
                f"filled there and interpolated back to its {self.fps:g} fps frames (observed samples kept)"
            )
        if self.refined_at_up_axis is not None:
            lines.append(
                f"refined in the model's {self.refined_at_up_axis}-up frame: the {self.up_axis}-up take turned "
                f"there and back (coordinates only swapped and negated, so observed samples keep their bits)"
            )
        if self.screened is not None:
            hidden, observed = self.screened
            lines.append(
                f"median screen: hid {hidden} of {observed} observed samples "
                f"({100 * hidden / max(observed, 1):.2f} %) and refilled them with the method"
            )
        if self.nan_gaps:
            lines.append(
                f"{self.nan_gaps} samples were NaN with a valid residual: read as gaps (how ezc3d and many "
                f"tools write a gap) and filled like the others"
            )
        if self.warning:
            lines.append(f"warning: {self.warning}")
        if self.training:
            lines.append(f"trained on {len(self.training)} motion file(s)")
        lines += [f"skipped training file {path}: {why}" for path, why in self.skipped]
        width = max([len(m.name) for m in self.markers] + [1])
        gapped = [m for m in self.markers if m.missing]
        for m in gapped:
            line = (
                f"{m.name:<{width}}  filled {m.filled} samples, longest gap {m.longest_gap} frames "
                f"({m.longest_gap / self.fps:.3f} s)"
            )
            if m.repaired:
                line += f"; repaired {m.repaired} outlier samples"
            if m.unfilled:
                line += f"; {m.left_missing} left missing"
            lines.append(line)
        for m in self.markers:
            if m.repaired and not m.missing:
                lines.append(f"{m.name:<{width}}  repaired {m.repaired} outlier samples")
        lines.append(f"filled {self.filled} of {self.missing} missing samples in {len(gapped)} markers")
        left = [m for m in self.markers if m.unfilled]
        if left:
            lines.append(
                f"left missing ({sum(m.left_missing for m in left)} samples; frames are 0-based, inclusive; "
                f"leading/trailing: before the first / after the last observation of the marker):"
            )
            for m in left:
                runs = [f"{a}-{b} ({why})" if a != b else f"{a} ({why})" for a, b, why in m.unfilled]
                if len(runs) > 8:
                    runs = runs[:8] + [f"... {len(runs) - 8} more"]
                lines.append(f"  {m.name:<{width}}  {m.left_missing} samples: frames {', '.join(runs)}")
            if self.hint:
                lines.append(f"  ({self.hint})")
        elif gapped:
            lines.append("nothing left missing")
        lines.append(f"wrote {self.output}" + (f" ({self.write_mode})" if self.write_mode else ""))
        return "\n".join(lines)


def _report_markers(before: Motion, after: Motion, changed: np.ndarray) -> list[MarkerReport]:
    frames = before.num_frames
    filled = before.missing & ~after.missing
    repaired = changed & ~before.missing
    out = []
    for j in np.flatnonzero(before.missing.any(axis=0) | repaired.any(axis=0)):
        seen = np.flatnonzero(~before.missing[:, j])
        unfilled = []
        for a, stop in true_runs(after.missing[:, j]):
            b = stop - 1  # the report's runs are inclusive
            if seen.size == 0:
                why = "missing in every frame"
            elif a == 0:
                why = "leading"
            elif b == frames - 1:
                why = "trailing"
            else:
                why = "interior, not filled by the method"
            unfilled.append((a, b, why))
        longest = max([stop - start for start, stop in true_runs(filled[:, j])] + [0])
        out.append(
            MarkerReport(
                name=before.joint_names[j],
                index=int(j),
                missing=int(before.missing[:, j].sum()),
                filled=int(filled[:, j].sum()),
                longest_gap=longest,
                repaired=int(repaired[:, j].sum()),
                unfilled=unfilled,
            )
        )
    return out


# --------------------------------------------------------------------------- training data


def load_training(
    paths: Sequence[str | os.PathLike], skip_bad: bool = False
) -> tuple[list[Motion], list[str], list[tuple[str, str]]]:
    """Read the ``--train`` paths: files, or folders searched (recursively) for files ``read_motion`` reads.

    Returns:
        ``(motions, files read, [(file, why), ...] skipped)``.

    Raises:
        FileNotFoundError: a path that does not exist.
        RefineError: a folder without motion files; an unreadable file (named) unless ``skip_bad``; nothing
            readable at all.
    """
    from mocapkit.datasets.formats.motion_io import expand_motion_paths, read_motion

    files = expand_motion_paths(paths, "--train", empty_error=RefineError)
    motions, used, skipped = [], [], []
    for path in files:
        try:
            motions.append(read_motion(path))
            used.append(str(path))
        except Exception as exc:  # any reader error: reported (--skip-bad) or re-raised naming the file
            why = f"{type(exc).__name__}: {exc}"
            if not skip_bad:
                message = str(exc) if str(path) in str(exc) else f"{path}: {why}"
                raise RefineError(f"cannot read training file: {message} (--skip-bad skips unreadable files)") from exc
            skipped.append((str(path), why))
    if not motions:
        raise RefineError(f"--train: none of the {len(files)} training file(s) could be read")
    return motions, used, skipped


# --------------------------------------------------------------------------- refining


def refine_motion(refiner: MotionRefiner, motion: Motion) -> tuple[Motion, np.ndarray]:
    """``refiner.refine(motion)`` and the bool ``[frames, joints]`` mask of the samples it changed
    (filled gaps and repaired observed samples)."""
    out = refiner.refine(motion)
    filled = motion.missing & ~out.missing
    with np.errstate(invalid="ignore"):
        repaired = ~motion.missing & ~out.missing & any_coordinate(out.positions != motion.positions)
    return out, filled | repaired


def refine_file(
    src: str | os.PathLike,
    out: str | os.PathLike,
    method: str | None = None,
    overrides: Sequence[str] = (),
    train: Sequence[str | os.PathLike] = (),
    skip_bad: bool = False,
    repair_outliers: bool = False,
    onnx: str | os.PathLike | None = None,
    screen_outliers: float | bool | None = None,
) -> RefineReport:
    """Refine the motion file ``src`` with the refiner ``method`` and write ``out`` (``.c3d`` or ``.npz``).

    See the module docstring for what is written. ``method`` is a name of ``configs/refinement/method`` or a trained
    checkpoint ``PATH.ckpt`` (a ``PATH.onnx`` is taken as ``onnx``); ``onnx`` (``--onnx``, instead of ``method``)
    an exported refiner. ``overrides`` are ``key=value`` parameters of the method (``--set``); ``train`` are
    files or folders of clean motions of the same layout (``--train``; not with a trained model); ``skip_bad``
    skips unreadable training files (each is reported) instead of failing. ``repair_outliers`` also writes
    the observed samples a robust method (LRMF, TrNN, PSC, filter bases, the learned refiners) flags as
    outliers; by default only the gaps are filled and every observed sample is written unchanged.
    ``screen_outliers`` (``--screen-outliers``: a threshold in metres, or True for
    :data:`~mocapkit.refinement.screening.SCREEN_THRESHOLD`) puts the refiner behind
    :class:`~mocapkit.refinement.screening.MedianScreen`: samples that far from their joint's running median are
    hidden, refilled and written (it implies ``repair_outliers``).

    Raises:
        ConfigError: unknown method or parameter; a checkpoint that is missing or not a refiner's.
        RefineError: an unsupported output suffix (the supported ones are listed), neither or both of
            ``method`` and ``onnx``, a method that needs training data without ``train``, ``train`` with a
            trained model, unusable training data, a failed write check.
        RefinementError: a motion the refiner cannot work on (named: every sample missing, non-finite
            observed values, too few frames, another skeleton layout than the training data).
        MotionFormatError and its subclasses: an unreadable input file.
    """
    from mocapkit.datasets.formats.motion_io import motion_format, read_motion

    src, out = Path(src), Path(out)
    suffix = out.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise RefineError(
            f"{out}: cannot write {suffix or 'a file without suffix'}; supported outputs: "
            f"{', '.join(OUTPUT_SUFFIXES)} (C3D markers, or NumPy positions)"
        )
    if (method is None) == (onnx is None):
        raise RefineError(
            "give the method: --method NAME (mocapkit methods refinement), --method RUN/best.ckpt (a trained "
            "refiner) or --onnx FILE (an exported one)"
            if method is None
            else f"give either --method {method} or --onnx {onnx}, not both"
        )
    kind = "onnx" if onnx is not None else trained_model_kind(method)
    if kind is not None:  # a trained network: loaded, never trained here
        model = Path(onnx if onnx is not None else method)
        if train:
            raise RefineError(
                f"--train: {model} is a trained refiner and is not trained again; train one with "
                f"`mocapkit train experiment=refine_bigru`"
            )
        refiner = build_learned_refiner(model, overrides, onnx=kind == "onnx", fit=False)
        method = str(model)
    else:
        from mocapkit.train.registry import build_method

        refiner = build_method("refinement", method, overrides)
    filling = refiner  # the method itself (the screen, when asked, stands in front of it)
    if screen_outliers is not None:
        from mocapkit.refinement.screening import (
            SCREEN_HALF_WINDOW,
            SCREEN_THRESHOLD,
            MedianScreen,
        )

        threshold = SCREEN_THRESHOLD if screen_outliers is True else float(screen_outliers)
        if not threshold > 0:
            raise RefineError(f"--screen-outliers {screen_outliers}: the threshold must be a distance > 0 (metres)")
        refiner = MedianScreen(refiner, half_window=SCREEN_HALF_WINDOW, threshold=threshold)
        repair_outliers = True
    if refiner.requires_fit and not train and kind is None:
        raise RefineError(
            f"refiner {method!r} ({type(refiner).__name__}) is data-driven and needs training motions: "
            f"pass --train PATH (files or folders of clean motions of the layout of {src.name})"
        )
    if not src.is_file():
        raise FileNotFoundError(f"{src}: no such file")
    motion = read_motion(src)
    used, skipped = [], []
    if kind is not None:
        refiner.fit()  # loads the checkpoint / opens the ONNX session
    elif train:
        motions, used, skipped = load_training(train, skip_bad=skip_bad)
        refiner.fit(motions)
    refined, changed = refine_motion(refiner, motion)
    if not repair_outliers:  # the everyday case: fill the gaps, keep every observed sample as it was
        changed = changed & motion.missing
        kept = np.where(motion.missing[..., None], refined.positions, motion.positions)
        refined = dataclasses.replace(refined, positions=kept, missing=refined.missing)

    out.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".c3d" and motion_format(src) == "c3d":
        mode = patch_c3d(src, out, motion, refined, changed)
    elif suffix == ".c3d":
        from mocapkit.datasets.formats.c3d import write_c3d

        write_c3d(out, refined)
        mode = "joint positions as C3D markers, mm"
    else:
        _write_npz(out, refined, motion.missing & ~refined.missing)
        mode = "positions in metres, NaN where missing"
    hint = ""
    if (
        "extrapolate" in inspect.signature(type(filling).__init__).parameters
        and getattr(filling, "extrapolate", None) is None
    ):
        hint = f"{method} does not extrapolate: --set extrapolate=hold holds the nearest observed value there"
    refiner_name = (
        type(filling).__name__ if filling is refiner else f"{type(refiner).__name__}({type(filling).__name__})"
    )
    screened, warning = None, ""
    if filling is not refiner:
        screened = (int(refined.metadata["refinement"]["screened"]), int((~motion.missing).sum()))
        if screened[0] > SCREEN_WARN_SHARE * screened[1]:
            warning = (
                f"the screen hid {100 * screened[0] / screened[1]:.1f} % of the observed samples: its "
                f"{1000 * refiner.threshold:g} mm threshold was chosen at 120 fps, and at {motion.fps:g} fps or "
                f"in fast motion clean samples can lie that far from their neighbours' median; check the "
                f"output, or raise the threshold (--screen-outliers METRES)"
            )
    return RefineReport(
        source=str(src),
        output=str(out),
        method=method,
        refiner=refiner_name,
        fps=float(motion.fps),
        frames=motion.num_frames,
        markers=_report_markers(motion, refined, changed),
        training=used,
        skipped=skipped,
        write_mode=mode,
        hint=hint,
        screened=screened,
        warning=warning,
        nan_gaps=int(motion.metadata.get("gaps", {}).get("nan_coordinates", 0)),
        refined_at_fps=refined.metadata.get("refinement", {}).get("resampled", {}).get("refined_at_fps"),
        refined_at_up_axis=refined.metadata.get("refinement", {}).get("turned", {}).get("refined_at_up_axis"),
        up_axis=motion.up_axis,
    )


def _write_npz(path: Path, motion: Motion, filled: np.ndarray) -> None:
    positions = motion.positions.astype(np.float32)
    positions[motion.missing] = np.nan
    with atomic_open(path, "wb") as fh:
        np.savez(
            fh,
            positions=positions,
            missing=motion.missing,
            filled=filled,
            joint_names=np.asarray(motion.joint_names, dtype=str),
            fps=np.float64(motion.fps),
        )


# --------------------------------------------------------------------------- C3D in, C3D out


def patch_c3d(src: Path, out: Path, motion: Motion, refined: Motion, changed: np.ndarray) -> str:
    """Write ``src`` to ``out`` with only the ``changed`` samples replaced by ``refined`` (module docstring).

    ``motion`` is ``read_c3d(src)``: its marker ``j`` is the file's point ``j``. Returns a short description of
    the write (:func:`~mocapkit.datasets.formats.c3d.patch_samples`).
    """
    from mocapkit.datasets.formats.c3d import UNIT_SCALE, patch_samples

    units = str(motion.source_units).strip().lower()
    frames, joints = np.nonzero(changed)  # [n] each
    values = refined.positions[frames, joints].astype(np.float64) / UNIT_SCALE[units]  # [n, 3] file units
    if not np.isfinite(values).all():
        raise RefineError(f"{src}: the refiner returned non-finite values for samples it reports as filled")
    try:
        return patch_samples(src, out, frames, joints, values)
    except ValueError as exc:
        raise RefineError(str(exc)) from exc
