"""The prepared Gait Energy Image cache (written by ``mocapkit prepare casia-b``).

A cache folder holds::

    geis.npy      uint8 [N, H, W]: GEI pixel values × 255 (a GEI is a mean of binary
                  silhouettes, so 0 = never foreground, 255 = always), memory-mappable
    index.npz     per GEI, int64 [N]: subjects (1-based), conditions (0 nm, 1 bg, 2 cl),
                  sequences (1-based repetition), views (degrees), cycles (0-based cycle
                  within its sequence; 0 when one GEI per sequence), frames (silhouettes
                  averaged); str [N] names ("001/nm-01/090")
    meta.json     format/version, height, width, per ("cycle" | "sequence"), source,
                  counts and options; written last (a folder without it is unfinished)
    report.json / report.txt   every skipped sequence and why

:func:`write_gei_cache` writes one, :class:`GEICache` reads it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from mocapkit.datasets.cache_files import (
    INDEX_FILE,
    META_FILE,
    CacheIntegrityError,
    PreparedCache,
    integrity_record,
    save_npy_atomic,
    save_npz_atomic,
    write_meta,
)

CACHE_FORMAT = "mocapkit-gei-cache"
CACHE_VERSION = 1
GEIS_FILE = "geis.npy"
INDEX_KEYS = ("names", "subjects", "conditions", "sequences", "views", "cycles", "frames")


def write_gei_cache(out: str | os.PathLike, geis: np.ndarray, index: dict[str, np.ndarray], meta: dict) -> Path:
    """Write a cache folder.

    Args:
        out: the folder (created).
        geis: float in [0, 1] or uint8, ``[N, H, W]``.
        index: arrays of length N for every key in :data:`INDEX_KEYS`.
        meta: extra metadata (``per``, ``source``, options); format, version and sizes are added.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    geis = np.asarray(geis)
    if geis.ndim != 3:
        raise ValueError(f"geis must be [N, H, W], got shape {geis.shape}")
    if geis.dtype != np.uint8:
        if not np.isfinite(geis).all() or geis.min() < 0 or geis.max() > 1:
            raise ValueError("float GEIs must be finite and in [0, 1]")
        geis = np.round(geis * 255).astype(np.uint8)
    missing = [k for k in INDEX_KEYS if k not in index]
    if missing:
        raise KeyError(f"index is missing {missing}")
    for key in INDEX_KEYS:
        if len(index[key]) != len(geis):
            raise ValueError(f"index[{key!r}] has {len(index[key])} entries for {len(geis)} GEIs")
    (out / META_FILE).unlink(missing_ok=True)  # unfinished until meta.json is rewritten
    save_npy_atomic(out / GEIS_FILE, geis)
    save_npz_atomic(
        out / INDEX_FILE,
        names=np.asarray(index["names"], dtype=str),
        **{k: np.asarray(index[k], dtype=np.int64) for k in INDEX_KEYS if k != "names"},
    )
    full_meta = {
        "format": CACHE_FORMAT,
        "version": CACHE_VERSION,
        "num_geis": int(len(geis)),
        "height": int(geis.shape[1]),
        "width": int(geis.shape[2]),
        **meta,
        "integrity": integrity_record(out, GEIS_FILE, len(geis)),
    }
    write_meta(out, full_meta, indent=2)
    return out


class GEICache(PreparedCache):
    """A prepared GEI cache folder (opened and checked as :class:`~mocapkit.datasets.cache_files.PreparedCache`).

    Attributes:
        names, subjects, conditions, sequences, views, cycles, frames: numpy arrays of length ``len(cache)``
            (see the module docstring).
        meta: the parsed ``meta.json``.
        height, width: GEI size in pixels.
    """

    _KIND, _COMMAND, _FORMAT, _VERSION = "GEI", "casia-b", CACHE_FORMAT, CACHE_VERSION
    _INDEX_KEYS, _ARRAY_FILE, _ARRAY_ATTR = INDEX_KEYS, GEIS_FILE, "_geis"

    def __init__(self, root: str | os.PathLike):
        super().__init__(root)
        self.height, self.width = int(self.meta["height"]), int(self.meta["width"])

    def _check_index(self, rows: int) -> None:
        """One GEI per index entry, of the size meta.json records."""
        path = self.root / GEIS_FILE
        if rows != len(self.names):
            raise CacheIntegrityError(path, f"{rows} GEIs for {len(self.names)} index entries")
        shape = tuple(self._array_shape[1:])
        expected = (self.meta.get("height"), self.meta.get("width"))
        if shape != expected:
            raise CacheIntegrityError(path, f"GEIs of {shape}, meta.json says height x width {expected}")

    def __repr__(self) -> str:
        return (
            f"GEICache({str(self.root)!r}: {len(self)} GEIs of {self.height}x{self.width}, "
            f"{len(np.unique(self.subjects))} subjects, per {self.meta.get('per')})"
        )

    all_geis = property(PreparedCache._array, doc="Read-only memmap, uint8 ``[N, H, W]`` (divide by 255 for [0, 1]).")

    def gei(self, i: int) -> np.ndarray:
        """GEI ``i`` as float32 ``[H, W]`` in [0, 1]."""
        return self.all_geis[i].astype(np.float32) / 255.0
