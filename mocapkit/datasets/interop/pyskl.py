"""pyskl / MMAction2 skeleton annotation pickles: export an NTU cache to one, import one as an NTU cache.

pyskl (and MMAction2's ``PoseDataset``) read a skeleton data set from one pickle::

    {"split": {"xsub_train": [frame_dir, ...], "xsub_val": [...], ...},
     "annotations": [{"frame_dir": "S001C001P001R001A001",   # the NTU sample name
                      "label": 0,                             # action - 1
                      "keypoint": float32 [M, T, V, C],       # persons, frames, joints, coordinates
                      "total_frames": T}, ...]}

pyskl's NTU 3D pickles (``ntu60_3danno.pkl``, ``ntu120_3danno.pkl``) hold V = 25 Kinect joints,
C = 3 (x, y, z in metres, camera space), M = the persons present (1 or 2), zeros in frames without
a body, T = every frame of the recording. That is what an NTU cache
(:mod:`mocapkit.datasets.ntu.prepare`) holds, so the two convert without loss:

:func:`export_pyskl` (``mocapkit pyskl export --cache DIR --out FILE.pkl``)
    writes every sample of a cache, in the cache's (sorted-name) order: ``keypoint`` is the sample's
    ``[max_bodies, T, 25, 3]`` block with the trailing bodies that are zero in every frame dropped
    (at least one kept), float32. ``split`` holds ``<name>_train`` / ``<name>_val`` lists for the
    protocols of :mod:`mocapkit.datasets.ntu.splits`, computed by
    :func:`~mocapkit.datasets.ntu.splits.split_indices` (``val`` is the protocol's test side, as in
    pyskl), under pyskl's names: for an NTU-60 cache ``xsub`` (``ntu60_xsub``) and ``xview``
    (``ntu60_xview``); for a cache with NTU-120 samples (a setup above S017 or an action above A060)
    ``xsub`` (``ntu120_xsub``) and ``xset`` (``ntu120_xset``), as pyskl's ``ntu120_3danno.pkl``.
    ``splits="ntu60"`` / ``"ntu120"`` or a mapping ``{pyskl name: mocapkit split}`` choose otherwise.
    Class names are not part of pyskl's format and are not written. The pickle is written atomically,
    one sample at a time (memory: one sample), with protocol 4 and numpy's array reconstructor named
    ``numpy.core.multiarray._reconstruct``, which numpy 1.x (pyskl's) and 2.x both load.

:func:`import_pyskl` (``mocapkit pyskl import --pkl FILE --out DIR [--skip-bad]``)
    writes an NTU cache, the same files and ``meta.json`` as ``mocapkit prepare ntu`` (through
    :func:`~mocapkit.datasets.ntu.prepare.write_index_and_meta`), that :class:`NTUCache` opens and
    ``NTUDataModule`` trains on. Subject, camera, setup and replication come from ``frame_dir``, which
    must be an NTU sample name; ``label`` must be its action - 1. Bodies keep the pickle's order and are
    padded with zeros to ``max_bodies`` (2, as pyskl). Nothing is dropped silently:

    - the pickle's ``split`` is written to ``pyskl_split.json`` in the cache, summarised in
      ``meta["pyskl_split"]`` (``file``, ``sha256``, per list its ``count`` and the ``not_imported``
      names, and per pyskl protocol the mocapkit protocols it equals on the imported samples).
      mocapkit's own protocols (``data.split=ntu60_xsub`` ...) come from the sample names, as always;
    - annotation keys other than the four above (e.g. ``keypoint_score``, meaningless for 3D) are
      counted in ``report.json`` / ``report.txt`` under ``ignored_keys``;
    - with ``skip_bad`` each refused annotation is listed in the report with its index, ``frame_dir``
      and reason.

    Refused, naming the pickle and the annotation (index and ``frame_dir``): a pickle that is not a
    dict with ``split`` and ``annotations``; an annotation that is not a dict or lacks a key;
    ``frame_dir`` not an NTU name, or seen twice; ``label`` not ``action - 1``; ``keypoint`` not a
    float array ``[M, T, 25, 3]`` (2D pickles, C = 2, are not supported: only 3D), with NaN or Inf,
    with M = 0 or **M > max_bodies** (an error, not a silent choice of bodies: pass ``max_bodies=3``
    to keep a third body); ``total_frames`` different from T. Without ``skip_bad`` the first such
    annotation stops the import before anything is written.

Safety. A pickle can run code when loaded. The pickle is read by :class:`RestrictedUnpickler`,
whose ``find_class`` gives numpy's array reconstruction (``_reconstruct``, ``_frombuffer``,
``scalar``, ``ndarray``, ``dtype``), ``collections.OrderedDict``, ``builtins.bytes`` and
``_codecs.encode`` (protocol-2 pickles, as mmcv writes them, store bytes that way) and refuses
anything else with :class:`PysklFormatError` naming the global.
"""

from __future__ import annotations

import codecs
import collections
import json
import os
import pickle
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mocapkit.datasets.cache_files import INDEX_FILE, META_FILE, sha256_of
from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.ntu_skeleton import NUM_JOINTS, parse_ntu_name
from mocapkit.datasets.formats.safe_io import regular_file_size
from mocapkit.datasets.ntu.cache import NTUCache
from mocapkit.datasets.ntu.prepare import (
    INDEX_KEYS,
    POSITIONS_FILE,
    read_class_names,
    write_index_and_meta,
)
from mocapkit.datasets.ntu.splits import NTU60_MAX_SETUP, SPLITS, split_indices
from mocapkit.datasets.prepare_report import PrepareReportBase
from mocapkit.io_atomic import atomic_open, atomic_write_text

__all__ = [
    "PYSKL_SPLITS",
    "PYSKL_SPLIT_FILE",
    "PysklFormatError",
    "PysklImportReport",
    "RestrictedUnpickler",
    "export_pyskl",
    "import_pyskl",
    "load_pyskl",
]

#: pyskl's split names -> mocapkit protocols, per benchmark (as in pyskl's ``ntu60_3danno.pkl`` / ``ntu120_3danno.pkl``).
PYSKL_SPLITS: dict[str, dict[str, str]] = {
    "ntu60": {"xsub": "ntu60_xsub", "xview": "ntu60_xview"},
    "ntu120": {"xsub": "ntu120_xsub", "xset": "ntu120_xset"},
}
#: The imported pickle's ``split``, verbatim, in the cache folder.
PYSKL_SPLIT_FILE = "pyskl_split.json"
#: The keys of one annotation that the cache holds.
ANNOTATION_KEYS = ("frame_dir", "label", "keypoint", "total_frames")


class PysklFormatError(MotionFormatError):
    """A pyskl pickle that cannot be read or imported. The message names the pickle and, for an
    annotation, its index and ``frame_dir``."""

    def __init__(self, path: str | os.PathLike, message: str, line: int | None = None, frame: int | None = None):
        super().__init__(path, line, message, frame)

    def __reduce__(self):
        return (type(self), (self.path, self.detail, self.line, self.frame))


# --------------------------------------------------------------------------- safe loading

_RECONSTRUCT = np.empty(0).__reduce__()[0]  # numpy.(_)core.multiarray._reconstruct
_SCALAR = np.float32(0).__reduce__()[0]  # numpy.(_)core.multiarray.scalar
_FROMBUFFER = np.empty(1).__reduce_ex__(5)[0]  # numpy.(_)core.numeric._frombuffer (protocol 5)

#: ``(module, name)`` -> object: everything a pickle of dicts, lists, str, numbers and numpy arrays names,
#: under the module names numpy 1.x and 2.x and Python 2-era protocols use.
_ALLOWED_GLOBALS: dict[tuple[str, str], object] = {
    **{(m, "_reconstruct"): _RECONSTRUCT for m in ("numpy.core.multiarray", "numpy._core.multiarray")},
    **{(m, "scalar"): _SCALAR for m in ("numpy.core.multiarray", "numpy._core.multiarray")},
    **{(m, "_frombuffer"): _FROMBUFFER for m in ("numpy.core.numeric", "numpy._core.numeric")},
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    ("collections", "OrderedDict"): collections.OrderedDict,
    ("builtins", "bytes"): bytes,
    ("__builtin__", "bytes"): bytes,
    ("_codecs", "encode"): codecs.encode,
}


class RestrictedUnpickler(pickle.Unpickler):
    """An unpickler that builds only plain data and numpy arrays (see :data:`_ALLOWED_GLOBALS`).

    Any other global (``os.system``, ``builtins.eval``, a class of some package ...) raises
    :class:`PysklFormatError` naming it, before it is imported.
    """

    def __init__(self, file, path: str | os.PathLike):
        super().__init__(file)
        self.path = str(path)

    def find_class(self, module: str, name: str):
        try:
            return _ALLOWED_GLOBALS[(module, name)]
        except KeyError:
            raise PysklFormatError(
                self.path,
                f"refused to load the global {module}.{name}: a pyskl pickle holds "
                "only dicts, lists, strings, numbers and numpy arrays, and loading "
                "anything else could run code",
            ) from None

    def persistent_load(self, pid):
        raise PysklFormatError(self.path, "refused a persistent ID: not a plain pyskl pickle")


def load_pyskl(pkl: str | os.PathLike) -> object:
    """The object stored in the pickle ``pkl``, read with :class:`RestrictedUnpickler` (no code runs).

    Raises:
        PysklFormatError: a missing or special file, a global other than numpy's array ones, a damaged pickle.
    """
    path = Path(pkl)
    regular_file_size(path, lambda p, m: PysklFormatError(p, m), max_bytes=1 << 62)  # regular files only
    try:
        with open(path, "rb") as f:
            return RestrictedUnpickler(f, path).load()
    except PysklFormatError:
        raise
    except OSError as exc:
        raise PysklFormatError(path, f"cannot read file ({exc.strerror or exc})") from exc
    except Exception as exc:
        raise PysklFormatError(path, f"not a readable pickle ({type(exc).__name__}: {exc})") from exc


# --------------------------------------------------------------------------- export


class _Stream:
    """A list written item by item by :class:`_PysklPickler` (a plain ``list`` when loaded)."""

    def __init__(self, items: Callable[[], Iterator]):
        self.items = items


class _PysklPickler(pickle._Pickler):
    """The pure-Python pickler, writing numpy's reconstructor as ``numpy.core.multiarray._reconstruct`` (loadable
    by numpy 1.x and 2.x alike; numpy 2 names it ``numpy._core...``) and :class:`_Stream` lists one item at a
    time. Runs in fast mode (no memo), so that written samples are not kept alive."""

    dispatch = pickle._Pickler.dispatch.copy()

    def __init__(self, file):
        super().__init__(file, protocol=4)
        self.fast = True  # no memo: nothing written is referenced again, and nothing is kept

    def save_global(self, obj, name=None):
        if obj is _RECONSTRUCT:
            self.save("numpy.core.multiarray")
            self.save("_reconstruct")
            self.write(pickle.STACK_GLOBAL)
            return
        super().save_global(obj, name)

    def _save_stream(self, obj: _Stream) -> None:
        self.write(pickle.EMPTY_LIST)
        for item in obj.items():
            self.save(item)
            self.write(pickle.APPEND)

    dispatch[_Stream] = _save_stream


def _resolve_splits(splits: str | Mapping[str, str] | None, cache: NTUCache) -> dict[str, str]:
    if splits is None:
        ntu120 = bool(len(cache)) and (int(cache.setups.max()) > NTU60_MAX_SETUP or int(cache.labels.max()) >= 60)
        splits = "ntu120" if ntu120 else "ntu60"
    if isinstance(splits, str):
        if splits not in PYSKL_SPLITS:
            raise ValueError(
                f"splits={splits!r}: expected one of {', '.join(PYSKL_SPLITS)}, "
                "or a mapping {pyskl name: mocapkit split}"
            )
        return dict(PYSKL_SPLITS[splits])
    mapping = dict(splits)
    for name, protocol in mapping.items():
        if not isinstance(name, str) or not name:
            raise ValueError(f"splits: pyskl split names must be non-empty strings, got {name!r}")
        if protocol not in SPLITS or protocol == "custom":
            raise ValueError(
                f"splits[{name!r}] = {protocol!r}: expected one of {', '.join(s for s in SPLITS if s != 'custom')}"
            )
    return mapping


def export_pyskl(
    cache_root: str | os.PathLike, out_pkl: str | os.PathLike, splits: str | Mapping[str, str] | None = None
) -> dict:
    """Write the NTU cache at ``cache_root`` as a pyskl annotation pickle ``out_pkl`` (atomically).

    Args:
        cache_root: a prepared NTU cache (``mocapkit prepare ntu`` or :func:`import_pyskl`).
        out_pkl: the pickle to write (its folder must exist; an existing file is replaced).
        splits: the ``split`` lists: None (NTU-60 names ``xsub``/``xview``, or ``xsub``/``xset`` of NTU-120 when
            the cache has a setup above S017 or an action above A060), ``"ntu60"``, ``"ntu120"``, or a mapping
            ``{pyskl name: mocapkit split}`` (e.g. ``{"xsub": "ntu120_xsub"}``); each gives
            ``<name>_train`` and ``<name>_val`` (the protocol's test side).

    Returns:
        ``{"out", "num_samples", "total_frames", "protocols" (pyskl name -> mocapkit split),
        "split" (list name -> length), "persons" (M -> samples)}``.

    Raises:
        FileNotFoundError, ValueError, CacheIntegrityError: the cache cannot be opened, or a sample holds NaN;
        ValueError: unknown ``splits``.
    """
    cache = NTUCache(cache_root)
    protocols = _resolve_splits(splits, cache)
    names = [str(n) for n in cache.names]
    split: dict[str, list[str]] = {}
    for name, protocol in protocols.items():
        train, test = split_indices(cache, protocol)
        split[f"{name}_train"] = [names[i] for i in train]
        split[f"{name}_val"] = [names[i] for i in test]
    persons: dict[int, int] = {}

    def annotations() -> Iterator[dict]:
        for i, name in enumerate(names):
            block = cache.positions(i)  # float32 [max_bodies, T, 25, 3], metres
            present = np.flatnonzero(block.reshape(len(block), -1).any(axis=1))
            m = int(present[-1]) + 1 if len(present) else 1
            persons[m] = persons.get(m, 0) + 1
            yield {
                "frame_dir": name,
                "label": int(cache.labels[i]),
                "keypoint": np.ascontiguousarray(block[:m], dtype=np.float32),
                "total_frames": int(block.shape[1]),
            }

    with atomic_open(out_pkl, "wb") as f:
        _PysklPickler(f).dump({"split": split, "annotations": _Stream(annotations)})
    return {
        "out": str(out_pkl),
        "num_samples": len(names),
        "total_frames": int(cache.lengths.sum()),
        "protocols": protocols,
        "split": {k: len(v) for k, v in split.items()},
        "persons": dict(sorted(persons.items())),
    }


# --------------------------------------------------------------------------- import


@dataclass
class PysklImportReport(PrepareReportBase):
    """What :func:`import_pyskl` did; also written to ``report.json`` and ``report.txt`` in the cache.

    Attributes:
        out: the cache folder. pickle: the pickle read.
        annotations_found: entries of ``annotations``.
        samples_written: samples in the cache. total_frames: rows of ``positions.npy``.
        skipped: with ``skip_bad``, one dict per annotation left out:
            ``{"index", "frame_dir", "reason", "message"}``, ``reason`` one of ``"not_a_dict"``,
            ``"missing_key"``, ``"bad_name"``, ``"duplicate_name"``, ``"bad_label"``, ``"bad_keypoint"``,
            ``"too_many_bodies"``, ``"bad_total_frames"``.
        ignored_keys: annotation keys not kept (e.g. ``keypoint_score``) -> number of annotations holding them.
        persons: M (bodies in the pickle) -> number of samples.
        pyskl_split: ``meta["pyskl_split"]`` (see the module docstring).
        seconds: wall-clock time.
    """

    out: str
    pickle: str
    annotations_found: int = 0
    samples_written: int = 0
    total_frames: int = 0
    skipped: list[dict] = field(default_factory=list)
    ignored_keys: dict[str, int] = field(default_factory=dict)
    persons: dict[int, int] = field(default_factory=dict)
    pyskl_split: dict = field(default_factory=dict)
    seconds: float = 0.0

    def totals(self) -> dict:
        totals = {
            "annotations_found": self.annotations_found,
            "samples_written": self.samples_written,
            "total_frames": self.total_frames,
            "skipped": len(self.skipped),
        }
        for reason in sorted({s["reason"] for s in self.skipped}):
            totals[f"skipped_{reason}"] = self.count(reason)
        totals["seconds"] = round(self.seconds, 3)
        return totals

    def to_dict(self) -> dict:
        return {
            "out": self.out,
            "pickle": self.pickle,
            "totals": self.totals(),
            "skipped": self.skipped,
            "ignored_keys": self.ignored_keys,
            "persons": {str(k): v for k, v in self.persons.items()},
            "pyskl_split": self.pyskl_split,
        }

    def _text_title(self) -> list[str]:
        return [f"pyskl import report for {self.out}", f"from {self.pickle}"]

    def _text_sections(self) -> list[tuple[str, int, list[str]]]:
        agrees = self.pyskl_split.get("agrees_with", {})
        return [
            (
                "Skipped annotations",
                len(self.skipped),
                [
                    f"  [{s['reason']}] annotations[{s['index']}] ({s['frame_dir']}): {s['message']}"
                    for s in self.skipped
                ],
            ),
            (
                "Annotation keys not kept",
                len(self.ignored_keys),
                [f"  {k}: in {n} annotations" for k, n in self.ignored_keys.items()],
            ),
            (
                "Persons per sample (M)",
                len(self.persons),
                [f"  M={m}: {n} samples" for m, n in sorted(self.persons.items())],
            ),
            (
                f"pyskl split lists (in {PYSKL_SPLIT_FILE})",
                len(self.pyskl_split.get("lists", {})),
                [
                    f"  {k}: {v['count']} names, {len(v['not_imported'])} not imported"
                    for k, v in self.pyskl_split.get("lists", {}).items()
                ]
                + [
                    f"  {k} equals mocapkit's {', '.join(v) if v else 'no protocol'} on the imported samples"
                    for k, v in agrees.items()
                ],
            ),
        ]


class _BadItem(Exception):
    def __init__(self, reason: str, message: str):
        super().__init__(message)
        self.reason = reason


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _check_annotation(item, max_bodies: int) -> tuple[str, np.ndarray]:
    """``(frame_dir, keypoint float32 [M, T, 25, 3])`` of a valid annotation; :class:`_BadItem` otherwise."""
    if not isinstance(item, Mapping):
        raise _BadItem("not_a_dict", f"expected a dict, found {type(item).__name__}")
    absent = [k for k in ANNOTATION_KEYS if k not in item]
    if absent:
        raise _BadItem(
            "missing_key",
            f"missing key{'s' if len(absent) > 1 else ''} {', '.join(absent)} "
            f"(an annotation holds {', '.join(ANNOTATION_KEYS)})",
        )
    name = item["frame_dir"]
    try:
        ok = isinstance(name, str) and str(parse_ntu_name(name)) == name
    except ValueError:
        ok = False
    if not ok:
        raise _BadItem("bad_name", f"frame_dir {name!r} is not an NTU sample name SsssCcccPpppRrrrAaaa")
    label, action = item["label"], parse_ntu_name(name).action
    if not _is_int(label) or int(label) != action - 1:
        raise _BadItem(
            "bad_label",
            f"label {label!r} does not match the action A{action:03d} of the name (expected {action - 1}, 0-based)",
        )
    keypoint = item["keypoint"]
    if not isinstance(keypoint, np.ndarray):
        raise _BadItem("bad_keypoint", f"keypoint is a {type(keypoint).__name__}, expected a numpy array")
    if keypoint.ndim != 4:
        raise _BadItem("bad_keypoint", f"keypoint has shape {list(keypoint.shape)}, expected 4 axes [M, T, V, C]")
    m, t, v, c = keypoint.shape
    if c == 2:
        raise _BadItem(
            "bad_keypoint",
            f"keypoint has C=2 (shape {list(keypoint.shape)}): a 2D pickle; "
            "only 3D pickles (C=3, x y z in metres) are supported",
        )
    if c != 3 or v != NUM_JOINTS:
        raise _BadItem(
            "bad_keypoint",
            f"keypoint has shape {list(keypoint.shape)}, expected [M, T, {NUM_JOINTS}, 3] "
            f"(V={NUM_JOINTS} NTU joints, C=3)",
        )
    if keypoint.dtype.kind != "f":
        raise _BadItem("bad_keypoint", f"keypoint has dtype {keypoint.dtype}, expected floats")
    if m == 0:
        raise _BadItem("bad_keypoint", "keypoint has M=0 persons; an empty sample is one body of zeros")
    if m > max_bodies:
        raise _BadItem(
            "too_many_bodies",
            f"keypoint has M={m} persons, more than max_bodies={max_bodies} "
            "(pyskl keeps 2; import with a larger max_bodies to keep them all)",
        )
    total = item["total_frames"]
    if not _is_int(total) or int(total) != t:
        raise _BadItem("bad_total_frames", f"total_frames {total!r} differs from the {t} frames of keypoint")
    keypoint = np.ascontiguousarray(keypoint, dtype=np.float32)
    finite = np.isfinite(keypoint).all(axis=(0, 2, 3))
    if not finite.all():
        raise _BadItem("bad_keypoint", f"keypoint holds NaN or Inf (first in frame {int(np.flatnonzero(~finite)[0])})")
    return name, keypoint


def _read_class_names(class_names: Sequence[str] | str | os.PathLike | None) -> list[str] | None:
    """A list of names, or a ``classes.txt`` file (line k = name of action k+1) read into one."""
    if class_names is None:
        return None
    if isinstance(class_names, (str, os.PathLike)):
        return read_class_names(class_names)
    return [str(n) for n in class_names]


def _split_summary(split: Mapping, rows: Mapping[str, list]) -> dict:
    """``meta["pyskl_split"]`` without the file record: per list its count and the names not imported,
    per pyskl protocol the mocapkit protocols that give the same train / val names on the imported samples."""
    imported = set(rows["names"])
    lists = {key: {"count": len(names), "not_imported": sorted(set(names) - imported)} for key, names in split.items()}
    data = {k: np.asarray(rows[k], dtype=np.int64) for k in ("subjects", "cameras", "setups")}
    names = np.asarray(rows["names"])
    agrees: dict[str, list[str]] = {}
    prefixes = sorted(
        {k[: -len("_train")] for k in split if k.endswith("_train")}
        & {k[: -len("_val")] for k in split if k.endswith("_val")}
    )
    for prefix in prefixes:
        train, val = set(split[f"{prefix}_train"]) & imported, set(split[f"{prefix}_val"]) & imported
        agrees[prefix] = []
        for protocol in (s for s in SPLITS if s != "custom"):
            ours_train, ours_test = split_indices(data, protocol)
            if set(names[ours_train].tolist()) == train and set(names[ours_test].tolist()) == val:
                agrees[prefix].append(protocol)
    return {"lists": lists, "agrees_with": agrees}


def import_pyskl(
    pkl: str | os.PathLike,
    out_cache: str | os.PathLike,
    skip_bad: bool = False,
    max_bodies: int = 2,
    class_names: Sequence[str] | str | os.PathLike | None = None,
) -> PysklImportReport:
    """Write the pyskl 3D annotation pickle ``pkl`` as an NTU cache in ``out_cache`` (see the module docstring).

    Args:
        pkl: a pyskl / MMAction2 NTU 3D annotation pickle (read without running code: :func:`load_pyskl`).
        out_cache: cache folder (created; a cache there is replaced, but only once the whole pickle is checked).
        skip_bad: leave out each bad annotation (listed in the report) instead of raising at the first.
        max_bodies: bodies per sample in the cache (``positions.npy`` axis 1); an annotation with more is bad.
        class_names: names of the actions (a list, or a ``classes.txt`` file, line k = action k+1), which pyskl's
            format does not hold; None: ``num_classes`` is 60, or 120 when an action is above A060.

    Returns:
        The :class:`PysklImportReport` (also ``out_cache/report.json`` and ``report.txt``).

    Raises:
        PysklFormatError: an unsafe, unreadable or malformed pickle; without ``skip_bad`` the first bad annotation
            (its index and ``frame_dir`` named); with it, a pickle with no good annotation.
        ValueError: ``max_bodies`` < 1; ``class_names`` too short for the labels.
    """
    started = time.perf_counter()
    pkl, out = Path(pkl), Path(out_cache)
    if max_bodies < 1:
        raise ValueError(f"max_bodies must be >= 1, got {max_bodies}")
    class_names = _read_class_names(class_names)
    report = PysklImportReport(out=str(out), pickle=str(pkl))

    data = load_pyskl(pkl)
    if not isinstance(data, Mapping):
        raise PysklFormatError(pkl, f"expected a dict with 'split' and 'annotations', found {type(data).__name__}")
    absent = [k for k in ("split", "annotations") if k not in data]
    if absent:
        raise PysklFormatError(
            pkl,
            f"missing top-level key{'s' if len(absent) > 1 else ''} {', '.join(absent)} "
            f"(found {', '.join(map(repr, data)) or 'none'})",
        )
    for key in data:
        if key not in ("split", "annotations"):
            report.ignored_keys[f"(top level) {key}"] = 1
    split, annotations = data["split"], data["annotations"]
    if not isinstance(split, Mapping):
        raise PysklFormatError(pkl, f"'split' is a {type(split).__name__}, expected a dict of name lists")
    for key, names in split.items():
        if not isinstance(key, str):
            raise PysklFormatError(pkl, f"split key {key!r} is not a string")
        if not isinstance(names, (list, tuple)) or not all(isinstance(n, str) for n in names):
            raise PysklFormatError(pkl, f"split[{key!r}] must be a list of frame_dir strings")
    if not isinstance(annotations, (list, tuple)):
        raise PysklFormatError(pkl, f"'annotations' is a {type(annotations).__name__}, expected a list")
    report.annotations_found = len(annotations)
    if not annotations:
        raise PysklFormatError(pkl, "'annotations' is empty")

    good: dict[str, np.ndarray] = {}
    for i, item in enumerate(annotations):
        frame_dir = item.get("frame_dir") if isinstance(item, Mapping) else None
        try:
            name, keypoint = _check_annotation(item, max_bodies)
            if name in good:
                raise _BadItem("duplicate_name", f"frame_dir {name!r} appears twice")
        except _BadItem as bad:
            message = f"annotations[{i}] (frame_dir {frame_dir!r}): {bad}"
            if not skip_bad:
                raise PysklFormatError(pkl, message) from None
            report.skipped.append(
                {
                    "index": i,
                    "frame_dir": frame_dir if isinstance(frame_dir, str) else None,
                    "reason": bad.reason,
                    "message": str(bad),
                }
            )
            continue
        good[name] = keypoint
        for key in item:
            if key not in ANNOTATION_KEYS:
                report.ignored_keys[str(key)] = report.ignored_keys.get(str(key), 0) + 1
    if not good:
        raise PysklFormatError(
            pkl, f"none of the {len(annotations)} annotations can be imported (first: {report.skipped[0]['message']})"
        )

    top = max(parse_ntu_name(name).label for name in good)
    if class_names is not None and top >= len(class_names):
        raise ValueError(f"class_names names {len(class_names)} actions but action A{top + 1:03d} occurs")

    # Everything is checked: write the cache (meta.json last, so a half-written folder is no cache).
    out.mkdir(parents=True, exist_ok=True)
    for stale in (META_FILE, INDEX_FILE, POSITIONS_FILE):
        (out / stale).unlink(missing_ok=True)
    order = sorted(good)
    total = sum(good[name].shape[1] for name in order)
    rows: dict[str, list] = {k: [] for k in INDEX_KEYS}
    positions_path = out / POSITIONS_FILE
    try:
        positions = np.lib.format.open_memmap(
            positions_path, mode="w+", dtype=np.float32, shape=(total, max_bodies, NUM_JOINTS, 3)
        )
        cursor = 0
        for name in order:
            keypoint = good[name]  # [M, T, 25, 3]
            m, length = keypoint.shape[:2]
            positions[cursor : cursor + length, :m] = keypoint.transpose(1, 0, 2, 3)
            report.persons[m] = report.persons.get(m, 0) + 1
            sample = parse_ntu_name(name)
            for key, value in (
                ("names", name),
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
        positions.flush()
        del positions
    except BaseException:
        positions = None  # noqa: F841  (drops the memmap so the file can go)
        positions_path.unlink(missing_ok=True)
        raise

    split_plain = {str(k): list(v) for k, v in split.items()}
    atomic_write_text(out / PYSKL_SPLIT_FILE, json.dumps(split_plain, indent=1) + "\n")
    report.pyskl_split = {
        "file": PYSKL_SPLIT_FILE,
        "sha256": sha256_of(out / PYSKL_SPLIT_FILE),
        **_split_summary(split_plain, rows),
    }
    report.samples_written = len(order)
    report.total_frames = total
    report.seconds = time.perf_counter() - started
    report.write(out)
    write_index_and_meta(
        out,
        rows,
        source=str(pkl.resolve()),
        max_bodies=max_bodies,
        class_names=class_names,
        options={"imported_from": "pyskl", "max_bodies": max_bodies, "skip_bad": skip_bad},
        totals=report.totals(),
        extra={"pyskl_split": report.pyskl_split},
    )
    return report
