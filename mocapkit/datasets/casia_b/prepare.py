"""Turn a CASIA-B silhouette folder into a Gait Energy Image cache (``mocapkit prepare casia-b``).

:func:`prepare_casia_b` lists the sequences (``<subject>/<condition>-<nn>/<view>/*.png``,
:func:`~mocapkit.datasets.formats.casia_b.list_casia_b`), reads each one
(:func:`~mocapkit.datasets.formats.casia_b.read_sequence`), builds its GEIs
(:func:`~mocapkit.datasets.casia_b.gei.gait_energy_images`: one per whole gait cycle, or one per
sequence) in parallel, and writes the cache read by
:class:`~mocapkit.datasets.casia_b.cache.GEICache` (layout in :mod:`mocapkit.datasets.casia_b.cache`):
``geis.npy``, ``index.npz``, ``meta.json`` (last), plus ``report.json`` / ``report.txt``
listing every skipped sequence and why, the sequences without a detectable gait period and
what was done with them, the listing's problems and the expected (subject, condition-nn, view)
sequences absent from the folder.

**Sequences without a detectable period** (``per="cycle"``; about 3 % of the synthetic set,
mostly 0° and 180° views, where the lower-body width hardly oscillates): by default
(``no_period="sequence"``) such a sequence gives **one GEI over the whole sequence** (index
``cycles`` 0, ``frames`` = its non-empty silhouettes), listed in the report section "one GEI per
sequence (no period detected)", so the documented command does not stop on them. Alternatives:
``fallback_period=N`` (cycles of ``N`` frames, each use listed) or ``no_period="error"`` (the former,
strict behaviour: such a sequence is bad, it raises, or is skipped as ``no_period`` with ``skip_bad``).

Memory: workers send back each sequence's GEIs as uint8; the cache is assembled in the
main process (full CASIA-B at 124×124 with ~3 cycles per sequence: ~40k GEIs, ~0.6 GB).
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.casia_b.cache import INDEX_KEYS, META_FILE, write_gei_cache
from mocapkit.datasets.casia_b.gei import (
    OPENGAIT_SIZE,
    PER_CHOICES,
    GaitSequenceError,
    gait_energy_images,
)
from mocapkit.datasets.formats.casia_b import (
    SilhouetteFormatError,
    list_casia_b,
    read_sequence,
)
from mocapkit.datasets.parallel import parallel_map
from mocapkit.datasets.prepare_report import REPORT_JSON, REPORT_TXT, PrepareReportBase  # noqa: F401  (re-exported)

#: Reasons a sequence is skipped (``GEIPrepareReport.skipped[i]["reason"]``).
SKIP_REASONS = ("unreadable", "no_frames", "no_period", "too_short")
#: What :func:`prepare_casia_b` does with a sequence whose gait period is not detected (``no_period``).
NO_PERIOD_CHOICES = ("sequence", "fallback", "error")


def parse_gei_size(text: str) -> tuple[int, int]:
    """``"64x44"`` → ``(64, 44)`` (height × width), for the CLI's ``--size``."""
    height, sep, width = str(text).lower().partition("x")
    if not (sep and height.strip().isdigit() and width.strip().isdigit()) or int(height) < 1 or int(width) < 1:
        raise ValueError(f"GEI size must be HEIGHTxWIDTH with positive integers, e.g. 64x44 or 124x124; got {text!r}")
    return int(height), int(width)


@dataclass
class GEIPrepareReport(PrepareReportBase):
    """What :func:`prepare_casia_b` did; also written to ``report.json`` and ``report.txt``.

    Attributes:
        out, source: the cache folder and the silhouette folder.
        per, size: ``"cycle"`` / ``"sequence"`` and the GEI ``(height, width)``.
        sequences_found: sequence folders listed.
        sequences_written: sequences with at least one GEI in the cache.
        geis_written: GEIs in the cache.
        frames_read: silhouettes read from the written sequences.
        frames_averaged: silhouettes averaged into the GEIs (non-empty frames in whole cycles).
        skipped: one dict per sequence left out: ``{"sequence", "folder", "reason", "message"}``, ``reason``
            in :data:`SKIP_REASONS` (``message`` names the file and frame for unreadable PNGs).
        listing_problems: what :func:`list_casia_b` could not use (messages as it gives them).
        missing: sequences absent from the folder (``"001/bg-02/090"``), as the listing names them: the
            expected 6 ``nm``, 2 ``bg`` and 2 ``cl`` walks in 11 views of each subject found.
        fallback_period: sequences whose GEIs use the fallback period (no period was detected).
        whole_sequence: sequences given one GEI over the whole sequence because no period was
            detected (``no_period="sequence"``, the default).
        seconds: wall-clock time of the whole run.
    """

    out: str
    source: str
    per: str
    size: tuple[int, int]
    sequences_found: int = 0
    sequences_written: int = 0
    geis_written: int = 0
    frames_read: int = 0
    frames_averaged: int = 0
    skipped: list[dict] = field(default_factory=list)
    listing_problems: list[str] = field(default_factory=list)
    missing: list[str] = field(default_factory=list)
    fallback_period: list[str] = field(default_factory=list)
    whole_sequence: list[str] = field(default_factory=list)
    seconds: float = 0.0

    def totals(self) -> dict:
        return {
            "sequences_found": self.sequences_found,
            "sequences_written": self.sequences_written,
            "geis_written": self.geis_written,
            "frames_read": self.frames_read,
            "frames_averaged": self.frames_averaged,
            **{f"skipped_{reason}": self.count(reason) for reason in SKIP_REASONS},
            "listing_problems": len(self.listing_problems),
            "missing_sequences": len(self.missing),
            "fallback_period_used": len(self.fallback_period),
            "one_gei_per_sequence_no_period": len(self.whole_sequence),
            "seconds": round(self.seconds, 3),
        }

    def to_dict(self) -> dict:
        return {
            "out": self.out,
            "source": self.source,
            "per": self.per,
            "size": list(self.size),
            "totals": self.totals(),
            "skipped": self.skipped,
            "listing_problems": self.listing_problems,
            "missing": self.missing,
            "fallback_period": self.fallback_period,
            "whole_sequence": self.whole_sequence,
        }

    def summary(self) -> str:
        """One paragraph for the console."""
        height, width = self.size
        skipped = ", ".join(f"{self.count(r)} {r}" for r in SKIP_REASONS if self.count(r))
        return (
            f"{self.geis_written} GEIs ({height}x{width}, per {self.per}) from {self.sequences_written} of "
            f"{self.sequences_found} sequences in {self.seconds:.1f} s -> {self.out}\n"
            f"skipped {len(self.skipped)} sequences{f' ({skipped})' if skipped else ''}; "
            f"{len(self.listing_problems)} listing problems; {len(self.missing)} expected sequences missing; "
            f"{len(self.whole_sequence)} without a detectable period, one GEI over the whole sequence; "
            f"{len(self.fallback_period)} with the fallback period; details in {Path(self.out) / REPORT_TXT}"
        )

    def _text_title(self) -> list[str]:
        return [
            f"CASIA-B GEI preparation report for {self.out}",
            f"source: {self.source}",
            f"GEI size {self.size[0]}x{self.size[1]}, one per {self.per}",
        ]

    def _text_sections(self) -> list[tuple[str, int, list[str]]]:
        listed = (
            ("Listing problems", self.listing_problems),
            ("Missing sequences, subject/condition-nn/view", self.missing),
            ("One GEI per sequence (no period detected)", self.whole_sequence),
            ("Sequences with the fallback period, no period detected", self.fallback_period),
        )
        return [
            (
                "Skipped sequences",
                len(self.skipped),
                [f"  [{s['reason']}] {s['sequence']}: {s['message']}" for s in self.skipped],
            ),
            *((heading, len(items), [f"  {item}" for item in items]) for heading, items in listed),
        ]


def prepare_casia_b(
    src: str | os.PathLike,
    out: str | os.PathLike,
    size: tuple[int, int] = OPENGAIT_SIZE,
    per: str = "cycle",
    skip_bad: bool = False,
    workers: int = 1,
    subjects: list[int] | None = None,
    fallback_period: int | None = None,
    no_period: str | None = None,
    progress: bool = True,
) -> GEIPrepareReport:
    """Build the GEIs of every sequence under ``src`` into a cache in ``out``.

    Args:
        src: CASIA-B silhouette root (``<subject>/<condition>-<nn>/<view>/<frame>.png``).
        out: cache folder (created; an existing cache there is replaced).
        size: GEI ``(height, width)``: ``(64, 44)`` (OpenGait) or ``(124, 124)`` (thesis), or any other.
        per: ``"cycle"`` (one GEI per whole gait cycle) or ``"sequence"`` (one GEI per sequence).
        skip_bad: record unusable sequences (unreadable or non-binary PNG, no non-empty frame,
            no gait period, shorter than a cycle) in the report and go on, instead of raising at the first.
        workers: processes building GEIs (1 = this process).
        subjects: only these subject IDs (1-based); None: all.
        fallback_period: with ``per="cycle"``, the cycle length (frames) used for a sequence whose
            period is not detected (each such sequence is listed in the report); giving it implies
            ``no_period="fallback"``.
        no_period: with ``per="cycle"``, what a sequence whose gait period is not detected gives:
            ``"sequence"`` (the default unless ``fallback_period`` is given): one GEI of all its
            non-empty silhouettes, listed in the report ("one GEI per sequence (no period
            detected)"); ``"fallback"``: GEIs of ``fallback_period`` frames; ``"error"``: the
            sequence is bad (reason ``"no_period"``: raises, or is skipped with ``skip_bad``).
        progress: show a tqdm progress bar and print the summary.

    Returns:
        The :class:`GEIPrepareReport` (also in ``out/report.json`` and ``out/report.txt``).

    Raises:
        FileNotFoundError: ``src`` does not exist.
        ValueError: ``src`` holds no sequence folder (the message gives the expected layout).
        SilhouetteFormatError: the first unreadable silhouette (names file and frame), unless ``skip_bad``.
        GaitSequenceError: the first sequence without a GEI (names its folder and why; with the default
            ``no_period`` a missing period is not a reason), unless ``skip_bad``.
        RuntimeError: every sequence was skipped (the report is written first).
    """
    started = time.perf_counter()
    src, out = Path(src), Path(out)
    size = tuple(int(v) for v in size)
    if len(size) != 2 or min(size) < 1:
        raise ValueError(f"size must be (height, width) with positive integers, got {size}")
    if per not in PER_CHOICES:
        raise ValueError(f"per must be one of {PER_CHOICES}, got {per!r}")
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    no_period = _no_period_policy(no_period, fallback_period)
    if not src.is_dir():
        raise FileNotFoundError(f"CASIA-B source folder {src} does not exist or is not a folder")

    listing = list_casia_b(src, subjects=subjects)  # raises when there is no sequence at all
    report = GEIPrepareReport(
        out=str(out),
        source=str(src.resolve()),
        per=per,
        size=size,
        sequences_found=len(listing.sequences),
        listing_problems=list(listing.problems),
        missing=list(listing.missing()),
    )

    rows: dict[str, list] = {key: [] for key in INDEX_KEYS}
    blocks: list[np.ndarray] = []
    jobs = [(seq, size, per, no_period, fallback_period) for seq in listing.sequences]
    with parallel_map(
        _build_one, jobs, workers, max_chunksize=8, desc="building GEIs", unit="seq", progress=progress
    ) as results:
        for seq, result in zip(listing.sequences, results):
            if "error" in result:
                if not skip_bad:
                    raise result["error"]
                report.skipped.append(
                    {
                        "sequence": seq.key.name,
                        "folder": str(seq.folder),
                        "reason": result["reason"],
                        "message": str(result["error"]),
                    }
                )
                continue
            geis, frames = result["geis"], result["frames"]
            key = seq.key
            blocks.append(geis)
            for cycle, count in enumerate(frames):
                for name, value in (
                    ("names", key.name),
                    ("subjects", key.subject),
                    ("conditions", key.condition_label),
                    ("sequences", key.sequence),
                    ("views", key.view),
                    ("cycles", cycle),
                    ("frames", count),
                ):
                    rows[name].append(value)
            report.sequences_written += 1
            report.geis_written += len(geis)
            report.frames_read += result["frames_read"]
            report.frames_averaged += int(sum(frames))
            if result["fallback"]:
                report.fallback_period.append(key.name)
            if result["whole_sequence"]:
                report.whole_sequence.append(key.name)

    out.mkdir(parents=True, exist_ok=True)
    (out / META_FILE).unlink(missing_ok=True)  # an older cache there must not look finished beside this report
    report.seconds = time.perf_counter() - started
    report.write(out)
    if not blocks:
        raise RuntimeError(f"no GEI could be built from the {len(jobs)} sequences under {src}; see {out / REPORT_TXT}")
    index = {key: np.asarray(values, dtype=np.int64) for key, values in rows.items() if key != "names"}
    index["names"] = np.asarray(rows["names"], dtype=str)
    meta = {
        "per": per,
        "size": list(size),
        "source": report.source,
        "options": {
            "skip_bad": skip_bad,
            "workers": workers,
            "fallback_period": fallback_period,
            "no_period": no_period,
            "subjects": None if subjects is None else sorted(int(s) for s in subjects),
        },
        "counts": report.totals(),
    }
    write_gei_cache(out, np.concatenate(blocks), index, meta)
    report.seconds = time.perf_counter() - started
    report.write(out)  # with the final time
    if progress:
        print(report.summary())
    return report


# --------------------------------------------------------------------------- steps of prepare_casia_b


def _no_period_policy(no_period: str | None, fallback_period: int | None) -> str:
    """The ``no_period`` choice :func:`prepare_casia_b` applies, checked against ``fallback_period``."""
    if no_period is None:
        no_period = "sequence" if fallback_period is None else "fallback"
    if no_period not in NO_PERIOD_CHOICES:
        raise ValueError(f"no_period must be one of {NO_PERIOD_CHOICES}, got {no_period!r}")
    if no_period == "fallback" and fallback_period is None:
        raise ValueError("no_period='fallback' needs fallback_period (frames per cycle)")
    if no_period != "fallback" and fallback_period is not None:
        raise ValueError(
            f"fallback_period={fallback_period} contradicts no_period={no_period!r}: give one or the other"
        )
    if fallback_period is not None and int(fallback_period) < 1:
        raise ValueError(f"fallback_period must be >= 1 frame, got {fallback_period}")
    return no_period


def _build_one(job) -> dict:
    """Worker: read one sequence and build its GEIs. Returns plain picklable values."""
    seq, size, per, no_period, fallback_period = job
    whole = False
    try:
        if not seq.frames:
            raise GaitSequenceError("empty view folder (no PNG frames)", reason="no_frames")
        frames = read_sequence(seq)
        try:
            geis, info = gait_energy_images(
                frames, size=size, per=per, fallback_period=fallback_period if no_period == "fallback" else None
            )
        except GaitSequenceError as exc:
            if exc.reason != "no_period" or no_period != "sequence":
                raise
            geis, info = gait_energy_images(frames, size=size, per="sequence")  # one GEI of every non-empty frame
            whole = True
    except SilhouetteFormatError as exc:
        return {"error": exc, "reason": "unreadable"}
    except GaitSequenceError as exc:
        return {"error": GaitSequenceError(f"{seq.folder}: {exc}", exc.reason), "reason": exc.reason}
    except Exception as exc:  # anything else one sequence raises must not stop the batch: reported as unreadable
        return {
            "error": SilhouetteFormatError(seq.folder, None, f"{type(exc).__name__}: {exc}"),
            "reason": "unreadable",
        }
    return {
        "geis": np.round(geis * 255).astype(np.uint8),
        "frames": info.frames_per_gei.tolist(),
        "frames_read": len(frames),
        "fallback": per == "cycle" and not whole and not info.period_detected,
        "whole_sequence": whole,
    }
