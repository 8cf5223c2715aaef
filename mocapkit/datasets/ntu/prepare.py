"""Turn a folder of NTU ``.skeleton`` files into a memory-mappable training cache.

:func:`prepare_ntu` parses every file once (in parallel) and writes, into ``out/``:

``positions.npy``
    float32 ``[total_frames, max_bodies, 25, 3]``, joint positions in metres
    (camera space). All samples are concatenated along the first axis: sample
    ``i`` is rows ``offsets[i] : offsets[i] + lengths[i]``. Bodies are those
    kept by :func:`~mocapkit.datasets.formats.ntu_skeleton.select_main_bodies` (by default the
    NTU authors' rules: tracks seen in 12 frames or more, spread denoising, then most motion first;
    plus the flicker rule: tracks that come and go or jump are dropped); a body absent in a frame
    (or a missing second body) is zeros.
``index.npz``
    one entry per sample, in sorted-name order: ``names`` (str), ``offsets``,
    ``lengths`` (frames), ``labels`` (0-based action), ``subjects``,
    ``cameras``, ``setups``, ``replications`` (int64, 1-based as in the name).
``meta.json``
    format version, source folder, counts, ``max_bodies``, the options used,
    ``num_classes`` and ``class_names`` (from ``src/classes.txt`` if present,
    line k = action k+1, else null). Written last: a folder without it is not a
    finished cache.
``report.json`` / ``report.txt``
    every file left out and why (missing-skeleton list, malformed with file and
    line, bad name, duplicate name); the body selection of every sample (which body
    ID became body 0 / 1 and why, which were dropped and by which rule); samples
    where no body was kept; totals, with the number of tracks per rule. ``report.txt``
    lists every sample with more than one track, a rescue or no body (a sample whose
    only track is body 0 is counted); the console gets :meth:`PrepareReport.summary`.

Frames are **not trimmed**: ``lengths[i]`` is always the frame count written in
the file, so frames in which no kept body is present are rows of zeros. This
keeps the cache a faithful copy of the files (frame ``t`` of the cache is frame
``t`` of the ``.skeleton``) and lets the array be sized exactly by a cheap
pre-pass; temporal cropping belongs to the training transforms.

Memory: the pre-pass reads only the first line (frame count) of each file to
allocate ``positions.npy`` with :func:`numpy.lib.format.open_memmap`; workers
then parse one file at a time and send back only the selected bodies, which
the main process writes into the memmap. Peak memory is a few files' worth,
whatever the number of files (full NTU-120: 114,480 files, ~5 GB on disk).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from mocapkit.datasets.cache_files import (
    INDEX_FILE,
    META_FILE,
    integrity_record,
    save_npz_atomic,
    write_meta,
)
from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.ntu_skeleton import (
    DROP_RULES,
    KEEP_RULES,
    MIN_BODY_FRAMES,
    NUM_JOINTS,
    SkeletonFormatError,
    parse_ntu_name,
    read_missing_list,
    read_skeleton,
    select_main_bodies,
)
from mocapkit.datasets.formats.safe_io import regular_file_size
from mocapkit.datasets.parallel import parallel_map
from mocapkit.datasets.prepare_report import REPORT_JSON, REPORT_TXT, PrepareReportBase
from mocapkit.io_atomic import atomic_path

#: Version of the on-disk layout written here and expected by :class:`~mocapkit.datasets.ntu.cache.NTUCache`.
CACHE_FORMAT = "mocapkit-ntu-cache"
CACHE_VERSION = 1

POSITIONS_FILE = "positions.npy"
#: Arrays of ``index.npz``, one entry per sample.
INDEX_KEYS = ("names", "offsets", "lengths", "labels", "subjects", "cameras", "setups", "replications")


@dataclass
class PrepareReport(PrepareReportBase):
    """What :func:`prepare_ntu` did; also written to ``report.json`` and ``report.txt``.

    Attributes:
        out: the cache folder.
        files_found: ``.skeleton`` files under the source folder.
        samples_written: samples in the cache.
        total_frames: rows of ``positions.npy``.
        skipped: one dict per file left out: ``{"file", "name", "reason", "message"}``
            with ``reason`` one of ``"missing_list"``, ``"malformed"``, ``"bad_name"``,
            ``"duplicate_name"``.
        bodies: the body selection of every sample written, in cache order:
            ``{"name", "tracks", "kept": [{"body_id", "rule", "reason"}, ...] (body 0 first),
            "dropped": [{"body_id", "rule", "reason"}, ...]}``; rules are the codes of
            :data:`~mocapkit.datasets.formats.ntu_skeleton.KEEP_RULES` and ``DROP_RULES``.
        empty_samples: names of samples written with no body at all (all zeros).
        seconds: wall-clock time of the whole run.
    """

    out: str
    files_found: int = 0
    samples_written: int = 0
    total_frames: int = 0
    skipped: list[dict] = field(default_factory=list)
    bodies: list[dict] = field(default_factory=list)
    empty_samples: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def dropped_bodies(self) -> list[dict]:
        """The entries of :attr:`bodies` where a track was dropped."""
        return [b for b in self.bodies if b["dropped"]]

    def rule_counts(self) -> dict[str, int]:
        """Tracks per rule code, over every sample: dropped ones first (in rule order), then kept ones."""
        counts = dict.fromkeys((*DROP_RULES, *KEEP_RULES), 0)
        for entry in self.bodies:
            for track in (*entry["dropped"], *entry["kept"]):
                counts[track["rule"]] = counts.get(track["rule"], 0) + 1
        return counts

    def totals(self) -> dict:
        rules = self.rule_counts()
        return {
            "files_found": self.files_found,
            "samples_written": self.samples_written,
            "total_frames": self.total_frames,
            "skipped_missing_list": self.count("missing_list"),
            "skipped_malformed": self.count("malformed"),
            "skipped_bad_name": self.count("bad_name"),
            "skipped_duplicate_name": self.count("duplicate_name"),
            "samples_with_dropped_bodies": len(self.dropped_bodies),
            **{f"tracks_dropped_{rule}": rules[rule] for rule in DROP_RULES},
            **{f"tracks_kept_{rule}": rules[rule] for rule in KEEP_RULES},
            "empty_samples": len(self.empty_samples),
            "seconds": round(self.seconds, 3),
        }

    def to_dict(self) -> dict:
        return {
            "out": self.out,
            "totals": self.totals(),
            "skipped": self.skipped,
            "bodies": self.bodies,
            "empty_samples": self.empty_samples,
        }

    def summary(self) -> str:
        """A few lines for the console: counts per reason and where the details are."""
        rules = self.rule_counts()
        skipped = ", ".join(
            f"{self.count(r)} {r}" for r in ("missing_list", "malformed", "bad_name", "duplicate_name") if self.count(r)
        )
        dropped = ", ".join(f"{rules[r]} {_RULE_WORDS[r]}" for r in DROP_RULES if rules[r]) or "none"
        rescued = ", ".join(f"{rules[r]} {_RULE_WORDS[r]}" for r in KEEP_RULES if r.startswith("rescued") and rules[r])
        lines = [
            (
                f"{self.samples_written} samples ({self.total_frames} frames) from {self.files_found} files in "
                f"{self.seconds:.1f} s -> {self.out}"
            ),
            f"skipped {len(self.skipped)} files{f' ({skipped})' if skipped else ''}",
            f"body selection: tracks dropped in {len(self.dropped_bodies)} samples: {dropped}",
        ]
        if rescued:
            lines.append(f"kept although a rule would drop them (every track of the sample failed it): {rescued}")
        lines.append(
            f"{len(self.empty_samples)} samples with no body (all zeros); "
            f"every decision in {Path(self.out) / REPORT_TXT} and {REPORT_JSON}"
        )
        return "\n".join(lines)

    def _text_title(self) -> list[str]:
        return [f"NTU preparation report for {self.out}"]

    def _text_sections(self) -> list[tuple[str, int, list[str]]]:
        listed, single = [], 0
        for d in self.bodies:
            kept, dropped = d["kept"], d["dropped"]
            if len(kept) == 1 and not dropped and kept[0]["rule"] == "only_candidate":
                single += 1
                continue
            listed.append(f"  {d['name']} ({d['tracks']} tracks):")
            listed += [f"      body {k}: {x['body_id']} [{x['rule']}] {x['reason']}" for k, x in enumerate(kept)]
            listed += [f"      dropped {x['body_id']} [{x['rule']}] {x['reason']}" for x in dropped]
        heading = f"Body selection (the {single} samples whose only track is body 0 are not listed); samples listed"
        return [
            (
                "Skipped files",
                len(self.skipped),
                [f"  [{s['reason']}] {s['file']}: {s['message']}" for s in self.skipped],
            ),
            (heading, len(self.bodies) - single, listed),
            (
                "Samples with no body kept, stored as zeros",
                len(self.empty_samples),
                [f"  {name}" for name in self.empty_samples],
            ),
        ]


#: How :meth:`PrepareReport.summary` names each rule code.
_RULE_WORDS = {
    "short": "seen in too few frames",
    "spread": "wider than tall (spread)",
    "flicker": "flickering",
    "jump": "jumping",
    "less_motion": "beyond the kept bodies (less motion)",
    "most_motion": "ranked by motion",
    "only_candidate": "only candidate",
    "rescued_short": "short",
    "rescued_spread": "wide",
    "rescued_flicker": "flickering or jumping",
}


def prepare_ntu(
    src: str | os.PathLike,
    out: str | os.PathLike,
    workers: int = 1,
    skip_bad: bool = False,
    missing_list: str | os.PathLike | Iterable[str] | None = None,
    max_bodies: int = 2,
    denoise_spread: bool = True,
    min_body_frames: int = MIN_BODY_FRAMES,
    denoise_flicker: bool = True,
    progress: bool = True,
) -> PrepareReport:
    """Parse every ``.skeleton`` file under ``src`` (recursively) into a cache in ``out``.

    Args:
        src: folder searched recursively for ``*.skeleton`` files named ``SsssCcccPpppRrrrAaaa``.
            An optional ``src/classes.txt`` (line k = name of action k+1) gives ``class_names``.
        out: cache folder (created; an existing cache there is replaced).
        workers: parsing processes (1 = parse in this process).
        skip_bad: record malformed files and bad names in the report and go on,
            instead of raising at the first one.
        missing_list: path of an official "samples with missing skeletons" list, or
            an iterable of sample names; those samples are left out.
        max_bodies: bodies kept per sample (``positions.npy`` axis 1).
        denoise_spread, min_body_frames, denoise_flicker: the body selection rules, passed to
            :func:`~mocapkit.datasets.formats.ntu_skeleton.select_main_bodies` (``min_frames``). The
            defaults (True, 12, True) are the NTU authors' rules, as pyskl uses them, plus the flicker
            rule; ``False, 1, False`` is the former default (most motion wins).
        progress: show a tqdm progress bar.

    Returns:
        The :class:`PrepareReport` (also written to ``out/report.json`` and ``out/report.txt``).

    Raises:
        FileNotFoundError: ``src`` does not exist, or holds no ``.skeleton`` file.
        SkeletonFormatError: the first malformed file (names file and line), unless ``skip_bad``.
        ValueError: a file name that is not an NTU sample name, or the same sample twice, unless ``skip_bad``.
    """
    started = time.perf_counter()
    src, out = Path(src), Path(out)
    if workers < 1:
        raise ValueError(f"workers must be >= 1, got {workers}")
    if max_bodies < 1:
        raise ValueError(f"max_bodies must be >= 1, got {max_bodies}")
    report = PrepareReport(out=str(out))

    files = _find_files(src)
    report.files_found = len(files)
    files = _check_names(files, skip_bad, report)
    missing = _load_missing(missing_list)
    missing_source = (
        str(missing_list)
        if isinstance(missing_list, (str, os.PathLike))
        else None
        if missing_list is None
        else f"{len(missing)} names given by the caller"
    )
    kept_files = []
    for path in files:
        if path.stem in missing:
            report.skipped.append(
                {
                    "file": str(path),
                    "name": path.stem,
                    "reason": "missing_list",
                    "message": "listed as a sample with missing skeletons",
                }
            )
        else:
            kept_files.append(path)
    files = kept_files
    class_names = _read_class_names(src)

    out.mkdir(parents=True, exist_ok=True)
    for stale in (META_FILE, INDEX_FILE, POSITIONS_FILE):  # a half-written cache must never look finished
        (out / stale).unlink(missing_ok=True)

    # Pre-pass: frame counts from the first lines size the memmap. A file whose first
    # line is unusable gets 0 rows here; its worker then raises the authoritative error.
    # (Should a parsed file ever have more frames than its pre-pass count, the memmap grows.)
    heads = tqdm(files, desc="reading frame counts", unit="file", disable=not progress)
    expected = np.array([_frame_count_or_zero(p) for p in heads], dtype=np.int64)
    capacity = int(expected.sum())
    positions_path = out / POSITIONS_FILE
    positions = np.lib.format.open_memmap(
        positions_path, mode="w+", dtype=np.float32, shape=(capacity, max_bodies, NUM_JOINTS, 3)
    )
    options = {
        "max_bodies": max_bodies,
        "denoise_spread": denoise_spread,
        "min_body_frames": min_body_frames,
        "denoise_flicker": denoise_flicker,
    }
    jobs = [(str(p), options) for p in files]
    rows: dict[str, list] = {k: [] for k in INDEX_KEYS}
    cursor = 0
    nan_rows = 0
    try:
        with parallel_map(
            _parse_one, jobs, workers, max_chunksize=16, desc="parsing .skeleton", unit="file", progress=progress
        ) as results:
            for path, frames, result in zip(files, expected, results):
                if "error" in result:
                    error = result["error"]
                    if not skip_bad:
                        raise error
                    report.skipped.append(
                        {"file": str(path), "name": path.stem, "reason": "malformed", "message": str(error)}
                    )
                    continue
                block = result["positions"]  # [max_bodies, T, 25, 3]
                length = block.shape[1]
                if cursor + length > capacity:  # the pre-pass under-counted this file: make room
                    positions.flush()
                    del positions
                    capacity = cursor + length + int(expected.sum()) // 4
                    _resize_rows(positions_path, capacity)
                    positions = np.lib.format.open_memmap(positions_path, mode="r+")
                positions[cursor : cursor + length] = block.transpose(1, 0, 2, 3)
                nan_rows += int(np.isnan(block).any(axis=(0, 2, 3)).sum())
                sample = parse_ntu_name(path.stem)
                for key, value in (
                    ("names", path.stem),
                    ("offsets", cursor),
                    ("lengths", length),
                    ("labels", sample.label),
                    ("subjects", sample.subject),
                    ("cameras", sample.camera),
                    ("setups", sample.setup),
                    ("replications", sample.replication),
                ):
                    rows[key].append(value)
                cursor += length
                report.bodies.append(
                    {
                        "name": path.stem,
                        "tracks": result["tracks"],
                        "kept": result["kept"],
                        "dropped": result["dropped"],
                    }
                )
                if not result["kept"]:
                    report.empty_samples.append(path.stem)
        positions.flush()
        del positions
        if cursor != capacity:  # some files were skipped as malformed after the pre-pass
            _resize_rows(positions_path, cursor)
    except BaseException:  # leave no half-written multi-gigabyte array behind
        positions = None  # noqa: F841  (drops the memmap so the file can go)
        positions_path.unlink(missing_ok=True)
        raise

    report.samples_written = len(rows["names"])
    report.total_frames = cursor
    report.seconds = time.perf_counter() - started
    report.write(out)
    write_index_and_meta(
        out,
        rows,
        source=str(src.resolve()),
        max_bodies=max_bodies,
        class_names=class_names,
        options={**options, "skip_bad": skip_bad, "workers": workers, "missing_list": missing_source},
        totals=report.totals(),
        nan_rows=nan_rows,
    )
    return report


def write_index_and_meta(
    out: str | os.PathLike,
    rows: Mapping[str, Sequence],
    *,
    source: str,
    max_bodies: int,
    class_names: list[str] | None,
    options: dict,
    totals: dict,
    nan_rows: int = 0,
    extra: Mapping | None = None,
) -> dict:
    """Finish an NTU cache whose ``positions.npy`` is written: ``index.npz``, then ``meta.json`` (last).

    The one place that lays out ``index.npz`` and ``meta.json``; :func:`prepare_ntu` and
    :func:`mocapkit.datasets.interop.pyskl.import_pyskl` both end with it.

    Args:
        out: the cache folder, holding ``positions.npy`` (float32 ``[sum(lengths), max_bodies, 25, 3]``, metres).
        rows: one sequence per key of :data:`INDEX_KEYS`, one entry per sample in sorted-name order
            (``names`` str; the others int, ``labels`` 0-based, the IDs 1-based).
        source: what the cache was made from (``meta["source"]``).
        max_bodies: bodies per sample (axis 1 of ``positions.npy``).
        class_names: ``num_classes`` names (line k = action k+1) or None (then 60, or 120 if an action is above 60).
        options, totals: ``meta["options"]`` and ``meta["totals"]``.
        nan_rows: rows of ``positions.npy`` holding NaN (recorded in the integrity record).
        extra: more ``meta.json`` keys (placed before ``"integrity"``).

    Returns:
        The ``meta`` written.

    Raises:
        ValueError: ``class_names`` is shorter than the largest action needs.
    """
    out = Path(out)
    index = {k: np.asarray(rows[k], dtype=np.int64) for k in INDEX_KEYS if k != "names"}
    index["names"] = np.asarray(rows["names"], dtype="<U20")
    num_classes = _num_classes(class_names, index["labels"])
    save_npz_atomic(out / INDEX_FILE, **index)
    num_samples = len(index["names"])
    meta = {
        "format": CACHE_FORMAT,
        "version": CACHE_VERSION,
        "source": source,
        "num_samples": num_samples,
        "total_frames": int(index["lengths"].sum()),
        "max_bodies": max_bodies,
        "num_joints": NUM_JOINTS,
        "num_classes": num_classes,
        "class_names": class_names,
        "options": options,
        "totals": totals,
        "frames_trimmed": False,
        **(extra or {}),
        "integrity": integrity_record(out, POSITIONS_FILE, num_samples, nan_rows=nan_rows),
    }
    write_meta(out, meta)
    return meta


# --------------------------------------------------------------------------- steps of prepare_ntu


def _find_files(src: Path) -> list[Path]:
    if not src.is_dir():
        raise FileNotFoundError(f"NTU source folder {src} does not exist or is not a folder")
    files = sorted(src.rglob("*.skeleton"), key=lambda p: (p.name, str(p)))
    if not files:
        raise FileNotFoundError(f"no .skeleton files found under {src} (searched recursively)")
    return files


def _check_names(files: list[Path], skip_bad: bool, report: PrepareReport) -> list[Path]:
    """Keep files whose stem is exactly an NTU sample name, each name once."""
    good: dict[str, Path] = {}
    for path in files:
        try:
            name_ok = str(parse_ntu_name(path.stem)) == path.stem
        except ValueError:
            name_ok = False
        if not name_ok:
            message = f"{path}: file name is not an NTU sample name SsssCcccPpppRrrrAaaa.skeleton"
            if not skip_bad:
                raise ValueError(message)
            report.skipped.append({"file": str(path), "name": path.stem, "reason": "bad_name", "message": message})
        elif path.stem in good:
            message = f"{path}: sample {path.stem} already read from {good[path.stem]}"
            if not skip_bad:
                raise ValueError(message)
            report.skipped.append(
                {"file": str(path), "name": path.stem, "reason": "duplicate_name", "message": message}
            )
        else:
            good[path.stem] = path
    return list(good.values())


def _load_missing(missing_list) -> set[str]:
    if missing_list is None:
        return set()
    if isinstance(missing_list, (str, os.PathLike)):
        if not Path(missing_list).is_file():
            raise FileNotFoundError(f"missing-skeleton list {missing_list} does not exist")
        return read_missing_list(missing_list)
    return {Path(str(n)).stem for n in missing_list}


def _read_class_names(src: Path) -> list[str] | None:
    path = src / "classes.txt"
    return read_class_names(path) if path.is_file() else None


def read_class_names(path: str | os.PathLike) -> list[str]:
    """The action names of a ``classes.txt`` (line k = the name of action k+1; trailing blank lines ignored).

    Raises:
        ValueError: an empty line among the names (names the file and line).
    """
    path = Path(path)
    names = [line.strip() for line in path.read_text(encoding="utf-8").splitlines()]
    while names and not names[-1]:
        names.pop()
    for k, name in enumerate(names):
        if not name:
            raise ValueError(f"{path}, line {k + 1}: empty class name")
    return names


def _num_classes(class_names: list[str] | None, labels: np.ndarray) -> int:
    """len(class_names) if given, else 60 (NTU-60) or 120 if any action is above 60."""
    if class_names is not None:
        if len(labels) and labels.max() >= len(class_names):
            raise ValueError(f"classes.txt names {len(class_names)} actions but action A{labels.max() + 1:03d} occurs")
        return len(class_names)
    return 120 if len(labels) and labels.max() >= 60 else 60


def _frame_count_or_zero(path: Path) -> int:
    """The frame count on the first line, or 0 if it is unusable (the parser will say why).

    Only regular files are opened (a FIFO would block, a device never end). The first line
    ends at LF, CR or CRLF, as for the parser; a first line longer than 4 KiB counts 0 here
    (the memmap then grows if the parser accepts the file).
    """
    try:
        size = regular_file_size(path, lambda p, m: SkeletonFormatError(p, None, m))
        with open(path, "rb") as f:
            head = f.read(4096)
        lines = head.splitlines()
        if not lines or (len(lines) == 1 and len(head) == 4096):
            return 0
        count = int(lines[0].strip())
    except (OSError, ValueError):  # SkeletonFormatError is a ValueError
        return 0
    # Each frame takes at least 2 bytes ("0\n"): a larger count is a corrupt header, not a reason
    # to allocate gigabytes.
    return count if 0 <= count and 2 * count <= size else 0


def _parse_one(job: tuple[str, dict]) -> dict:
    """Worker: read one file and select its main bodies. Returns plain picklable values."""
    path, options = job
    try:
        seq = read_skeleton(path)
        selection = select_main_bodies(
            seq,
            max_bodies=options["max_bodies"],
            denoise_spread=options["denoise_spread"],
            min_frames=options["min_body_frames"],
            denoise_flicker=options["denoise_flicker"],
        )
    except MotionFormatError as exc:
        return {"error": exc}
    except Exception as exc:  # noqa: BLE001 - one bad file must not end the batch (see --skip-bad)
        return {"error": SkeletonFormatError(path, None, f"unexpected {type(exc).__name__} while reading: {exc}")}
    return {
        "positions": selection.positions,
        "tracks": seq.num_bodies,
        "kept": [
            {"body_id": seq.body_ids[b], "rule": selection.rules[b], "reason": selection.kept_reasons[b]}
            for b in selection.kept
        ],
        "dropped": [
            {"body_id": seq.body_ids[b], "rule": selection.rules[b], "reason": reason}
            for b, reason in sorted(selection.dropped.items())
        ],
    }


def _resize_rows(path: Path, rows: int) -> None:
    """Give the ``.npy`` at ``path`` exactly ``rows`` rows: the first ones kept, new ones zero (copied in chunks, renamed)."""
    old = np.load(path, mmap_mode="r")
    with atomic_path(path) as tmp:
        new = np.lib.format.open_memmap(tmp, mode="w+", dtype=old.dtype, shape=(rows,) + old.shape[1:])
        step = 65536
        keep = min(rows, len(old))
        for start in range(0, keep, step):
            new[start : start + step] = old[start : min(start + step, keep)]
        new.flush()
        del new, old
