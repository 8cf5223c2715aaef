"""``mocapkit synthesize``: fit a variation synthesiser on example AMC or BVH clips and write new variants.

Zhou 2014 ch. 4 (../shared/spec/thesis-zhou-2014-retrieval-synthesis.md §3): about ten example clips of one motion
type in, ``n_variants`` new clips out. BVH clips (Bandai's, Mixamo-style rigs) are converted exactly to ASF/AMC
first (:func:`~mocapkit.synthesis.clips.as_amc_clips`: one T-pose rest for all of them). The output folder gets
``variant_000.amc`` … (on the reference skeleton, the first clip's) with a copy of that skeleton's ``.asf``, or
self-contained ``variant_000.bvh`` … (the same joints, bone lengths and frame rate, for tools that take BVH; the
default for BVH input, and then in the input's own rig: hierarchy, joint frames and channel orders,
:func:`~mocapkit.datasets.formats.bvh_to_amc.amc_to_bvh`), and ``report.json``.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.asf_amc import read_amc, write_amc, write_asf
from mocapkit.datasets.formats.bvh import read_bvh, write_bvh
from mocapkit.datasets.formats.bvh_to_amc import amc_to_bvh
from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.synthesis.base import MotionSynthesizer
from mocapkit.synthesis.clips import SynthesisInputError, as_amc_clips, clip_windows

#: Output formats of the variants: ASF/AMC (the training clips' own) or BVH.
OUTPUT_FORMATS = ("amc", "bvh")
#: File suffixes of training clips: ASF/AMC joint angles, or BVH (converted).
INPUT_SUFFIXES = (".amc", ".bvh")


def find_clips(inputs: Sequence[str | os.PathLike], motion_type: str | None = None) -> list[Path]:
    """The AMC and BVH files named by ``inputs`` (files, or folders searched recursively for ``*.amc`` and
    ``*.bvh``), keeping only names that contain ``motion_type`` when given; sorted, without duplicates.

    Raises:
        FileNotFoundError: an input does not exist.
        SynthesisInputError: no file matches, or the matches mix AMC and BVH (the message names the folders and
            the pattern, or one file of each).
    """
    found: list[Path] = []
    for item in inputs:
        path = Path(item)
        if path.is_dir():
            found.extend(sorted(p for p in path.rglob("*") if p.suffix.lower() in INPUT_SUFFIXES and p.is_file()))
        elif path.is_file():
            found.append(path)
        else:
            raise FileNotFoundError(f"{path}: no such file or folder")
    if motion_type:
        found = [p for p in found if motion_type in p.name]
    found = sorted(dict.fromkeys(p.resolve() for p in found))
    if not found:
        where = ", ".join(str(i) for i in inputs)
        pattern = f"*{motion_type}*" if motion_type else "*"
        raise SynthesisInputError(f"no AMC or BVH clips matching {pattern}.amc / {pattern}.bvh in {where}")
    kinds = {p.suffix.lower() for p in found}
    if len(kinds) > 1:
        examples = ", ".join(str(next(p for p in found if p.suffix.lower() == kind)) for kind in sorted(kinds))
        raise SynthesisInputError(
            f"the training clips mix {' and '.join(sorted(kinds))} files ({examples}); give "
            f"clips of one skeleton, in one format"
        )
    return found


def read_clip(path: Path):
    """One training file: an AMC (its ASF beside it) or a BVH, as a :class:`~mocapkit.motion.container.Motion`."""
    return read_bvh(path) if path.suffix.lower() == ".bvh" else read_amc(path)


def make_synthesizer(
    method: str, seed: int, footskate_cleanup: bool, overrides: Sequence[str] = ()
) -> MotionSynthesizer:
    """The registry's synthesis method ``method`` (``configs/synthesis/method/NAME.yaml``) seeded with ``seed``
    (its ``random_state``, where it has one), with the ``--set`` Hydra ``overrides`` applied last.
    ``footskate_cleanup`` switches the footskate cleanup that every method shares
    (:class:`~mocapkit.synthesis.base.MotionSynthesizer`).

    Raises:
        ConfigError: an unknown method (the message lists the names), an unknown parameter (named, with the
            method's parameters) or a bad value.
    """
    from mocapkit.train.registry import build_method, method_parameters

    parameters = method_parameters("synthesis", method)
    settings = [f"random_state={int(seed)}"] if "random_state" in parameters else []
    if "footskate_cleanup" in parameters:
        settings.append(f"footskate_cleanup={str(bool(footskate_cleanup)).lower()}")
    return build_method("synthesis", method, [*settings, *overrides])


def synthesize(
    inputs: Sequence[str | os.PathLike],
    out_dir: str | os.PathLike,
    n_variants: int = 10,
    n_frames: int | None = None,
    seed: int = 0,
    method: str | None = None,
    motion_type: str | None = None,
    max_clips: int = 10,
    footskate_cleanup: bool = True,
    overrides: Sequence[str] = (),
    progress: bool = True,
    output_format: str | None = None,
    window_seconds: float | None = None,
) -> dict:
    """Fit ``method`` on example clips and write ``n_variants`` variants to ``out_dir``.

    Args:
        inputs: AMC or BVH files and/or folders (searched recursively); each AMC's ASF is looked up beside it;
            BVH clips are converted to ASF/AMC on one T-pose rest (:func:`~mocapkit.synthesis.clips.as_amc_clips`).
        out_dir: the output folder (created): ``variant_000.amc`` … and the reference ``.asf`` (or
            ``variant_000.bvh`` …), ``report.json``.
        n_variants: variants to write.
        n_frames: frames per variant (default: the mean training length).
        seed: seeds the fit (``random_state``) and the sampling.
        method: a synthesis method of the registry (``mocapkit methods synthesis``; None: its default, ``slfm``,
            :class:`~mocapkit.synthesis.slfm.SLFMSynthesizer`).
        motion_type: keep only files whose name contains this (e.g. ``"hopBothLegs1hops"``).
        max_clips: use the first ``max_clips`` matching files (sorted by path; the thesis trains on 10); with
            ``window_seconds``, the first ``max_clips`` windows.
        footskate_cleanup: ground and pin planted feet in the variants.
        overrides: ``--set`` Hydra overrides of the method's parameters (e.g. ``["n_inducing=32"]``).
        progress: progress lines on stderr.
        output_format: ``"amc"`` (with the reference skeleton's ``.asf``) or ``"bvh"`` (one self-contained file
            per variant, positions in metres; :func:`~mocapkit.datasets.formats.bvh.read_bvh` reads back the
            AMC variant's joint positions; from BVH input, in the input's own rig); ``None``: the inputs' format.
        window_seconds: cut every matching file into consecutive windows of this many seconds
            (:func:`~mocapkit.synthesis.clips.clip_windows`) and train on those: for long takes that repeat one
            motion (CMU's walks). ``None``: every file is one clip.

    Returns:
        The report written to ``report.json``: training clips (with ``window_seconds``: the windows, and per file
        the frames left out after its last whole window), fit seconds, sampling seconds, seconds of
        compute per second of synthesised motion, the variants' files, the synthesiser's parameters, for SLFM
        the noise scale it sampled with (and, with ``noise_scale="auto"``, ``V / V_train`` of each scale tried) and
        the joint-angle flips its training clips were cut at, and (with footskate cleanup) the mean horizontal
        ankle speed during contacts before and after it and the largest horizontal and vertical shift it gave the
        root, per variant (metres).

    Raises:
        SynthesisInputError: no matching clips, too few, too short, or clips on different skeletons (named).
    """

    def say(message: str) -> None:
        if progress:
            print(f"[synthesize] {message}", file=sys.stderr, flush=True)

    if output_format is not None and output_format not in OUTPUT_FORMATS:
        raise ValueError(f"output format {output_format!r}: expected one of {', '.join(OUTPUT_FORMATS)}")
    files = find_clips(inputs, motion_type)
    if output_format is None:
        output_format = files[0].suffix.lower().lstrip(".")
    left_out = {}
    if window_seconds is None:
        files = files[: max(int(max_clips), 0)]
        say(f"reading {len(files)} clip(s)")
        clips = as_amc_clips([read_clip(f) for f in files])
        training = [str(f) for f in files]
    else:
        clips, short = [], []
        first_take = None
        for f in files:
            if len(clips) >= max_clips:
                break
            take = read_clip(f)
            if first_take is None:
                first_take = take
            take = as_amc_clips([take], reference=first_take)[0]  # BVH: one rest pose, the first take's
            windows = clip_windows(take, window_seconds)
            used = windows[: max_clips - len(clips)]
            left_out[str(f)] = len(take.positions) - sum(len(w.positions) for w in used)
            if not windows:
                short.append(str(f))
            clips.extend(used)
        training = [str(c.source) for c in clips]
        if short:
            say(f"shorter than one {window_seconds:g} s window, not used: {', '.join(short)}")
        say(f"cut {len(left_out) - len(short)} file(s) into {len(clips)} window(s) of {window_seconds:g} s")
    from mocapkit.train.registry import default_method

    method = method or default_method("synthesis")
    synthesizer = make_synthesizer(method, seed, footskate_cleanup, overrides)
    if progress and hasattr(synthesizer, "verbose"):
        synthesizer.set_params(verbose=True)
    say(f"fitting {type(synthesizer).__name__} on {len(clips)} clips")
    start = time.perf_counter()
    synthesizer.fit(clips)
    fit_seconds = time.perf_counter() - start
    say(f"fitted in {fit_seconds:.1f} s; sampling {n_variants} variant(s)")
    start = time.perf_counter()
    variants = synthesizer.sample(n_variants, n_frames=n_frames, seed=seed)
    sample_seconds = time.perf_counter() - start
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    asf_name = None
    if output_format == "amc":
        skeleton = clips[0].metadata["asf"]
        asf_source = clips[0].metadata.get("asf_path")
        asf_name = Path(asf_source).name if asf_source else "skeleton.asf"
        if asf_source:
            shutil.copyfile(asf_source, out / asf_name)
        else:
            write_asf(out / asf_name, skeleton)
    rig = clips[0].metadata.get("bvh_rig")
    bvh_rig_note, in_rig = None, None
    if output_format == "bvh" and rig is not None:  # BVH in, BVH out: in the input's own rig where it holds them
        try:
            in_rig = [amc_to_bvh(motion, rig) for motion in variants]
            bvh_rig_note = f"the input's ({rig.reference})"
        except MotionFormatError as exc:
            bvh_rig_note = f"the ASF skeleton's, as the input's rig cannot hold the variants: {exc}"
            say(f"BVH variants written on the ASF skeleton: {exc}")
    written = []
    for k, motion in enumerate(variants):
        path = out / f"variant_{k:03d}.{output_format}"
        if output_format == "amc":
            write_amc(path, motion)
        else:
            write_bvh(path, motion if in_rig is None else in_rig[k])
        written.append(path.name)
    motion_seconds = sum(len(m.positions) for m in variants) / synthesizer.fps_
    report = {
        "method": method,
        "training_clips": training,
        "format": output_format,
        "skeleton": asf_name,
        "variants": written,
        "frames_per_variant": len(variants[0].positions),
        "fps": synthesizer.fps_,
        "seed": seed,
        "fit_seconds": round(fit_seconds, 3),
        "sample_seconds": round(sample_seconds, 3),
        "sample_seconds_per_motion_second": round(sample_seconds / motion_seconds, 5),
        "parameters": {k: v for k, v in synthesizer.get_params().items() if k != "verbose"},
    }
    if rig is not None:
        report["bvh_rest_pose"] = rig.reference
    if bvh_rig_note:
        report["bvh_output_rig"] = bvh_rig_note
    if window_seconds is not None:
        report["window_seconds"] = float(window_seconds)
        report["frames_left_out"] = left_out
    if hasattr(synthesizer, "noise_scale_"):
        report["noise_scale"] = synthesizer.noise_scale_
        report["variation_by_noise_scale"] = {
            str(k): round(v, 4) for k, v in synthesizer.variation_by_noise_scale_.items()
        }
    if getattr(synthesizer, "angle_flips_", None):
        report["angle_flips"] = [
            {"clip": clip, "frame": frame, "bone": bone, "degrees": round(degrees, 1)}
            for clip, frame, bone, degrees in synthesizer.angle_flips_
        ]
    reports = getattr(synthesizer, "footskate_reports_", None)
    if footskate_cleanup and reports:
        report["footskate_sliding_m_per_s"] = {
            "before": [None if r.sliding_before != r.sliding_before else round(r.sliding_before, 4) for r in reports],
            "after": [None if r.sliding_after != r.sliding_after else round(r.sliding_after, 4) for r in reports],
        }
        report["footskate_root_shift_m"] = {
            "horizontal_max": [
                round(float(np.hypot(r.root_shift[:, 0], r.root_shift[:, 2]).max()), 4) for r in reports
            ],
            "vertical_max": [round(float(np.abs(r.root_shift[:, 1]).max()), 4) for r in reports],
        }
    (out / "report.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    files_written = (
        f"{len(written)} variant(s), {asf_name} and report.json"
        if asf_name
        else f"{len(written)} variant(s) and report.json"
    )
    say(
        f"wrote {files_written} to {out} "
        f"({report['sample_seconds_per_motion_second']:.4f} s of compute per second of motion)"
    )
    return report
