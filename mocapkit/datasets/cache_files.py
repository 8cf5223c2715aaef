"""What the prepared caches share: file names, writing, opening and checking a cache folder, the lazy memmap.

A cache folder written by a ``prepare`` command holds ``meta.json`` (``format`` and ``version``
among its keys; written last, so a folder without it is unfinished), ``index.npz`` (per-sample
arrays) and one large ``.npy`` array read as a memmap. :class:`PreparedCache` opens one;
:class:`~mocapkit.datasets.ntu.cache.NTUCache` and :class:`~mocapkit.datasets.casia_b.cache.GEICache`
derive from it.

Integrity. Writers put :func:`integrity_record` into ``meta.json`` under ``"integrity"``: the
number of samples, the size and SHA-256 of ``index.npz``, and the size, shape and dtype of the
array file (and the rows holding NaN, counted while writing). Every file is written atomically
(:mod:`mocapkit.io_atomic`: temporary sibling, fsync, rename). Opening a cache checks, and
raises :class:`CacheIntegrityError` naming the file at fault when something does not match:

- ``meta.json`` is a JSON object of the expected format and version;
- ``index.npz`` has the recorded size and checksum, loads, holds every index array, all of
  one length (the recorded sample count);
- the array file's ``.npy`` header is readable, the file is exactly as long as its header says
  (a truncated copy is caught without reading it), and its shape/dtype are those recorded;
- the index points inside the array (subclasses check offsets and lengths).

Caches written before the integrity record existed are still opened; they get every check that
needs no record. NaN rows are reported: by :meth:`PreparedCache.verify` (a full scan in chunks)
and by the per-sample accessors of the subclasses, which refuse a sample holding NaN.
"""

from __future__ import annotations

import hashlib
import json
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from mocapkit.io_atomic import atomic_open, atomic_write_text

INDEX_FILE = "index.npz"
META_FILE = "meta.json"
INTEGRITY_KEY = "integrity"


class CacheIntegrityError(ValueError):
    """A cache file that does not match its ``meta.json`` or is unreadable. ``path`` is the file at fault."""

    def __init__(self, path: str | os.PathLike, message: str):
        self.path = str(path)
        self.detail = message
        super().__init__(f"{self.path}: {message}; prepare the cache again")

    def __reduce__(self):
        return (type(self), (self.path, self.detail))


# --------------------------------------------------------------------------- writing


def save_npz_atomic(path: str | os.PathLike, **arrays) -> Path:
    """``np.savez(path, **arrays)`` written atomically (temporary sibling, fsync, rename)."""
    with atomic_open(path, "wb") as f:
        np.savez(f, **arrays)
    return Path(path)


def save_npy_atomic(path: str | os.PathLike, array: np.ndarray) -> Path:
    """``np.save(path, array)`` written atomically."""
    with atomic_open(path, "wb") as f:
        np.save(f, array)
    return Path(path)


def write_meta(folder: str | os.PathLike, meta: dict, indent: int = 1) -> Path:
    """Write ``meta.json`` atomically (the last file of a cache: its presence marks the cache finished)."""
    return atomic_write_text(Path(folder) / META_FILE, json.dumps(meta, indent=indent) + "\n")


def sha256_of(path: str | os.PathLike, chunk: int = 1 << 20) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(chunk), b""):
            digest.update(block)
    return digest.hexdigest()


def integrity_record(folder: str | os.PathLike, array_file: str, num_samples: int, nan_rows: int = 0) -> dict:
    """The ``meta.json["integrity"]`` entry for a cache whose ``index.npz`` and ``array_file`` are written."""
    folder = Path(folder)
    shape, dtype, _ = npy_header(folder / array_file)
    return {
        "num_samples": int(num_samples),
        "index": {
            "file": INDEX_FILE,
            "bytes": (folder / INDEX_FILE).stat().st_size,
            "sha256": sha256_of(folder / INDEX_FILE),
        },
        "array": {
            "file": array_file,
            "bytes": (folder / array_file).stat().st_size,
            "shape": list(shape),
            "dtype": dtype.str,
            "nan_rows": int(nan_rows),
        },
    }


def npy_header(path: str | os.PathLike) -> tuple[tuple[int, ...], np.dtype, int]:
    """``(shape, dtype, data offset)`` from the header of a ``.npy`` file, without reading its data.

    Raises :class:`CacheIntegrityError` if the header is unreadable, the array is not C-ordered
    plain data, or the file is shorter or longer than the header says.
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
            elif version == (2, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
            else:
                raise ValueError(f"unsupported .npy version {version}")
            offset = f.tell()
    except (OSError, ValueError, EOFError) as exc:
        raise CacheIntegrityError(path, f"not a readable .npy file ({exc})") from exc
    if fortran or dtype.hasobject:
        raise CacheIntegrityError(path, "the array is Fortran-ordered or holds objects; a cache array is plain C data")
    expected = offset + int(np.prod(shape, dtype=np.int64)) * dtype.itemsize
    size = path.stat().st_size
    if size != expected:
        raise CacheIntegrityError(
            path,
            f"the file is {size} bytes but its header announces {list(shape)} {dtype} "
            f"({expected} bytes): it is truncated or damaged",
        )
    return tuple(int(n) for n in shape), dtype, offset


# --------------------------------------------------------------------------- reading


class PreparedCache:
    """A prepared cache folder: ``meta`` (the parsed ``meta.json``) and every index array as an attribute.

    A subclass names its cache in class attributes: ``_KIND`` (in messages, e.g. ``"NTU"``),
    ``_COMMAND`` (the ``mocapkit prepare`` sub-command that writes it), ``_FORMAT`` and
    ``_VERSION`` (expected in ``meta.json``), ``_INDEX_KEYS`` (arrays of ``index.npz``),
    ``_ARRAY_FILE`` (the memory-mapped ``.npy``, opened by :meth:`_array` on first use in each
    process; the cache pickles without it, cheap to send to DataLoader workers) and
    ``_ARRAY_ATTR`` (the attribute holding that memmap, None until opened). It may override
    :meth:`_check_index` to check its index against the array's shape.

    Raises (on opening):
        FileNotFoundError: the folder, or one of its three files, is missing.
        ValueError: ``meta.json`` names another format or version.
        CacheIntegrityError (a ValueError): a file that is unreadable or does not match ``meta.json``
            (see the module docstring); the message names the file.
        KeyError: ``index.npz`` lacks one of ``_INDEX_KEYS``.
    """

    _KIND: str
    _COMMAND: str
    _FORMAT: str
    _VERSION: int
    _INDEX_KEYS: tuple[str, ...]
    _ARRAY_FILE: str
    _ARRAY_ATTR: str

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"{self._KIND} cache folder {self.root} does not exist")
        for required in (META_FILE, INDEX_FILE, self._ARRAY_FILE):
            if not (self.root / required).is_file():
                raise FileNotFoundError(
                    f"{self.root} is not a prepared {self._KIND} cache: {required} is missing "
                    f"(run `mocapkit prepare {self._COMMAND} --src ... --out {self.root}`)"
                )
        meta_path = self.root / META_FILE
        try:
            self.meta = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise CacheIntegrityError(meta_path, f"not a readable JSON file ({exc})") from exc
        if not isinstance(self.meta, dict):
            raise CacheIntegrityError(meta_path, f"expected a JSON object, found {type(self.meta).__name__}")
        if self.meta.get("format") != self._FORMAT or self.meta.get("version") != self._VERSION:
            raise ValueError(
                f"{self.root / META_FILE}: cache format {self.meta.get('format')!r} version "
                f"{self.meta.get('version')!r}, expected {self._FORMAT!r} version {self._VERSION}; "
                "prepare the cache again"
            )
        record = self.meta.get(INTEGRITY_KEY)
        if record is not None and not isinstance(record, dict):
            raise CacheIntegrityError(meta_path, f"{INTEGRITY_KEY!r} must be an object")
        record = record or {}
        self._load_index(record)
        self._array_shape = self._check_array(record)
        self._check_index(self._array_shape[0] if self._array_shape else 0)
        setattr(self, self._ARRAY_ATTR, None)  # the memmap, opened lazily, per process

    # ----------------------------------------------------------------- opening checks

    def _load_index(self, record: dict) -> None:
        index_path = self.root / INDEX_FILE
        expected = record.get("index") or {}
        try:
            if "bytes" in expected and index_path.stat().st_size != expected["bytes"]:
                raise CacheIntegrityError(
                    index_path, f"the file is {index_path.stat().st_size} bytes, meta.json recorded {expected['bytes']}"
                )
            if "sha256" in expected and sha256_of(index_path) != expected["sha256"]:
                raise CacheIntegrityError(index_path, "its SHA-256 checksum differs from the one meta.json recorded")
            with np.load(index_path, allow_pickle=False) as index:
                absent = [k for k in self._INDEX_KEYS if k not in index.files]
                if absent:
                    raise KeyError(f"{index_path}: missing arrays {absent}")
                for key in self._INDEX_KEYS:
                    setattr(self, key, index[key])
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
            if isinstance(exc, CacheIntegrityError):
                raise
            raise CacheIntegrityError(index_path, f"unreadable ({type(exc).__name__}: {exc})") from exc
        lengths = {key: len(getattr(self, key)) if getattr(self, key).ndim else -1 for key in self._INDEX_KEYS}
        if len(set(lengths.values())) != 1 or -1 in lengths.values():
            raise CacheIntegrityError(index_path, f"index arrays of different lengths {lengths}")
        n = next(iter(lengths.values()))
        if "num_samples" in record and n != record["num_samples"]:
            raise CacheIntegrityError(index_path, f"{n} samples, meta.json recorded {record['num_samples']}")

    def _check_array(self, record: dict) -> tuple[int, ...]:
        array_path = self.root / self._ARRAY_FILE
        shape, dtype, _ = npy_header(array_path)
        expected = record.get("array") or {}
        if "shape" in expected and list(shape) != list(expected["shape"]):
            raise CacheIntegrityError(
                array_path, f"shape {list(shape)}, meta.json recorded {expected['shape']} (rows were lost or added)"
            )
        if "dtype" in expected and dtype.str != expected["dtype"]:
            raise CacheIntegrityError(array_path, f"dtype {dtype.str}, meta.json recorded {expected['dtype']}")
        if not shape:
            raise CacheIntegrityError(array_path, "a 0-dimensional array; expected one row per frame or sample")
        return shape

    def _check_index(self, rows: int) -> None:
        """Check the index against the array's ``rows`` (subclasses; nothing by default)."""

    # ----------------------------------------------------------------- access

    def __len__(self) -> int:
        return len(self.names)

    def _array(self) -> np.ndarray:
        """The read-only memmap of ``_ARRAY_FILE``."""
        if getattr(self, self._ARRAY_ATTR) is None:
            path = self.root / self._ARRAY_FILE
            try:
                setattr(self, self._ARRAY_ATTR, np.load(path, mmap_mode="r"))
            except (OSError, ValueError) as exc:
                raise CacheIntegrityError(path, f"cannot be memory-mapped ({exc})") from exc
        return getattr(self, self._ARRAY_ATTR)

    def nan_rows(self, chunk_bytes: int = 64 << 20) -> np.ndarray:
        """Indices of the array's rows (axis 0) holding any NaN, scanning in chunks of about ``chunk_bytes``."""
        array = self._array()
        if array.dtype.kind not in "fc":
            return np.zeros(0, dtype=np.int64)
        row_bytes = max(1, array[:1].nbytes)
        step = max(1, chunk_bytes // row_bytes)
        found = []
        for start in range(0, len(array), step):
            block = np.asarray(array[start : start + step]).reshape(min(step, len(array) - start), -1)
            found.append(start + np.flatnonzero(np.isnan(block).any(axis=1)))
        return np.concatenate(found) if found else np.zeros(0, dtype=np.int64)

    def verify(self) -> None:
        """Full check beyond what opening does: raise :class:`CacheIntegrityError` if any row holds NaN."""
        rows = self.nan_rows()
        if len(rows):
            shown = ", ".join(str(int(r)) for r in rows[:10])
            raise CacheIntegrityError(
                self.root / self._ARRAY_FILE,
                f"{len(rows)} rows hold NaN (first: {shown}{', ...' if len(rows) > 10 else ''})",
            )

    # Pickle without the memmap: each DataLoader worker reopens it on first access.
    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state[self._ARRAY_ATTR] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
