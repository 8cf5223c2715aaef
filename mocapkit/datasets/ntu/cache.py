"""Read access to a cache written by :func:`~mocapkit.datasets.ntu.prepare.prepare_ntu`.

The per-sample metadata (a few arrays of ``len(cache)`` integers) is loaded into
memory; the joint positions stay on disk and are memory-mapped, so opening the
full NTU-120 cache is instant and costs no RAM. An :class:`NTUCache` pickles
without its memmap (cheap to send to DataLoader workers) and reopens it on first
use in each process.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from mocapkit.datasets.ntu.prepare import (
    CACHE_FORMAT,
    CACHE_VERSION,
    INDEX_FILE,
    META_FILE,
    POSITIONS_FILE,
)

_INDEX_KEYS = ("names", "offsets", "lengths", "labels", "subjects", "cameras", "setups", "replications")


class NTUCache:
    """A prepared NTU cache folder.

    Attributes (numpy arrays of length ``len(cache)``, in sorted-name order):
        names: sample names, e.g. ``"S001C002P003R001A004"``.
        labels: 0-based action classes (``action - 1``).
        subjects, cameras, setups, replications: 1-based, as in the names.
        lengths: frames per sample. offsets: first row of each sample in ``positions.npy``.
    Other attributes:
        meta: the parsed ``meta.json``.
        class_names: list of ``num_classes`` names, or None if the source had no ``classes.txt``.
        num_classes: number of action classes (60 or 120 unless ``classes.txt`` said otherwise).
        max_bodies: bodies per sample (axis 0 of :meth:`positions`).
    """

    def __init__(self, root: str | os.PathLike):
        self.root = Path(root)
        if not self.root.is_dir():
            raise FileNotFoundError(f"NTU cache folder {self.root} does not exist")
        for required in (META_FILE, INDEX_FILE, POSITIONS_FILE):
            if not (self.root / required).is_file():
                raise FileNotFoundError(f"{self.root} is not a prepared NTU cache: {required} is missing "
                                        f"(run `mocapkit prepare ntu --src ... --out {self.root}`)")
        self.meta = json.loads((self.root / META_FILE).read_text(encoding="utf-8"))
        if self.meta.get("format") != CACHE_FORMAT or self.meta.get("version") != CACHE_VERSION:
            raise ValueError(f"{self.root / META_FILE}: cache format {self.meta.get('format')!r} version "
                             f"{self.meta.get('version')!r}, expected {CACHE_FORMAT!r} version {CACHE_VERSION}; "
                             f"prepare the cache again")
        with np.load(self.root / INDEX_FILE, allow_pickle=False) as index:
            absent = [k for k in _INDEX_KEYS if k not in index.files]
            if absent:
                raise KeyError(f"{self.root / INDEX_FILE}: missing arrays {absent}")
            for key in _INDEX_KEYS:
                setattr(self, key, index[key])
        self.class_names: list[str] | None = self.meta.get("class_names")
        self.num_classes: int = int(self.meta["num_classes"])
        self.max_bodies: int = int(self.meta["max_bodies"])
        self._positions: np.ndarray | None = None  # opened lazily, per process

    def __len__(self) -> int:
        return len(self.names)

    def __repr__(self) -> str:
        return (f"NTUCache({str(self.root)!r}: {len(self)} samples, {int(self.lengths.sum())} frames, "
                f"{self.num_classes} classes, max_bodies={self.max_bodies})")

    @property
    def all_positions(self) -> np.ndarray:
        """The read-only memmap, float32 ``[total_frames, max_bodies, 25, 3]`` metres."""
        if self._positions is None:
            self._positions = np.load(self.root / POSITIONS_FILE, mmap_mode="r")
        return self._positions

    def positions(self, i: int) -> np.ndarray:
        """Joint positions of sample ``i``: a float32 copy ``[max_bodies, T_i, 25, 3]`` in metres.

        Bodies are ordered most motion first; absent bodies and frames are zeros.
        """
        if not -len(self) <= i < len(self):
            raise IndexError(f"sample index {i} out of range for a cache of {len(self)} samples")
        start, length = int(self.offsets[i]), int(self.lengths[i])
        block = self.all_positions[start:start + length]  # [T, M, 25, 3]
        return np.ascontiguousarray(block.transpose(1, 0, 2, 3))

    def index_of(self, name: str) -> int:
        """Position of the sample called ``name`` (KeyError if absent)."""
        hits = np.flatnonzero(self.names == name)
        if len(hits) == 0:
            raise KeyError(f"sample {name!r} is not in the cache {self.root}")
        return int(hits[0])

    # Pickle without the memmap: each DataLoader worker reopens it on first access.
    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_positions"] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
