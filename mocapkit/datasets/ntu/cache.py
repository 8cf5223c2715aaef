"""Read access to a cache written by :func:`~mocapkit.datasets.ntu.prepare.prepare_ntu`.

The per-sample metadata (a few arrays of ``len(cache)`` integers) is loaded into
memory; the joint positions stay on disk and are memory-mapped, so opening the
full NTU-120 cache is instant and costs no RAM. An :class:`NTUCache` pickles
without its memmap (cheap to send to DataLoader workers) and reopens it on first
use in each process.
"""

from __future__ import annotations

import os

import numpy as np

from mocapkit.datasets.cache_files import CacheIntegrityError, PreparedCache
from mocapkit.datasets.ntu.prepare import CACHE_FORMAT, CACHE_VERSION, INDEX_KEYS, POSITIONS_FILE


class NTUCache(PreparedCache):
    """A prepared NTU cache folder (opened and checked as :class:`~mocapkit.datasets.cache_files.PreparedCache`).

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

    _KIND, _COMMAND, _FORMAT, _VERSION = "NTU", "ntu", CACHE_FORMAT, CACHE_VERSION
    _INDEX_KEYS, _ARRAY_FILE, _ARRAY_ATTR = INDEX_KEYS, POSITIONS_FILE, "_positions"

    def __init__(self, root: str | os.PathLike):
        super().__init__(root)
        self.class_names: list[str] | None = self.meta.get("class_names")
        self.num_classes: int = int(self.meta["num_classes"])
        self.max_bodies: int = int(self.meta["max_bodies"])

    def _check_index(self, rows: int) -> None:
        """Every sample's rows ``offsets[i] : offsets[i] + lengths[i]`` lie inside ``positions.npy``."""
        offsets, lengths = self.offsets.astype(np.int64), self.lengths.astype(np.int64)
        bad = np.flatnonzero((offsets < 0) | (lengths < 0) | (offsets + lengths > rows))
        if len(bad):
            i = int(bad[0])
            raise CacheIntegrityError(
                self.root / POSITIONS_FILE,
                f"{len(bad)} samples point outside its {rows} rows, e.g. {self.names[i]} "
                f"(rows {offsets[i]}..{offsets[i] + lengths[i] - 1}): the file lost rows or "
                "does not belong to this index.npz",
            )
        total = self.meta.get("total_frames")
        if isinstance(total, int) and total != rows:
            raise CacheIntegrityError(
                self.root / POSITIONS_FILE, f"{rows} rows, meta.json says total_frames is {total}"
            )

    def __repr__(self) -> str:
        return (
            f"NTUCache({str(self.root)!r}: {len(self)} samples, {int(self.lengths.sum())} frames, "
            f"{self.num_classes} classes, max_bodies={self.max_bodies})"
        )

    all_positions = property(
        PreparedCache._array, doc="The read-only memmap, float32 ``[total_frames, max_bodies, 25, 3]`` metres."
    )

    def positions(self, i: int) -> np.ndarray:
        """Joint positions of sample ``i``: a float32 copy ``[max_bodies, T_i, 25, 3]`` in metres.

        Bodies are ordered most motion first; absent bodies and frames are zeros.
        Raises :class:`~mocapkit.datasets.cache_files.CacheIntegrityError` if the sample holds NaN.
        """
        if not -len(self) <= i < len(self):
            raise IndexError(f"sample index {i} out of range for a cache of {len(self)} samples")
        start, length = int(self.offsets[i]), int(self.lengths[i])
        block = np.ascontiguousarray(self.all_positions[start : start + length].transpose(1, 0, 2, 3))
        if np.isnan(block).any():  # [M, T, 25, 3]
            t = int(np.flatnonzero(np.isnan(block).any(axis=(0, 2, 3)))[0])
            raise CacheIntegrityError(
                self.root / POSITIONS_FILE,
                f"sample {self.names[i]} holds NaN (row {start + t}, frame {t} of the sample)",
            )
        return block

    def index_of(self, name: str) -> int:
        """Position of the sample called ``name`` (KeyError if absent)."""
        hits = np.flatnonzero(self.names == name)
        if len(hits) == 0:
            raise KeyError(f"sample {name!r} is not in the cache {self.root}")
        return int(hits[0])
