"""What the prepared caches share: file names, opening and checking a cache folder, the lazy memmap.

A cache folder written by a ``prepare`` command holds ``meta.json`` (``format`` and ``version``
among its keys; written last, so a folder without it is unfinished), ``index.npz`` (per-sample
arrays) and one large ``.npy`` array read as a memmap. :class:`PreparedCache` opens one;
:class:`~mocapkit.datasets.ntu.cache.NTUCache` and :class:`~mocapkit.datasets.casia_b.cache.GEICache`
derive from it.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

INDEX_FILE = "index.npz"
META_FILE = "meta.json"


class PreparedCache:
    """A prepared cache folder: ``meta`` (the parsed ``meta.json``) and every index array as an attribute.

    A subclass names its cache in class attributes: ``_KIND`` (in messages, e.g. ``"NTU"``),
    ``_COMMAND`` (the ``mocapkit prepare`` sub-command that writes it), ``_FORMAT`` and
    ``_VERSION`` (expected in ``meta.json``), ``_INDEX_KEYS`` (arrays of ``index.npz``),
    ``_ARRAY_FILE`` (the memory-mapped ``.npy``, opened by :meth:`_array` on first use in each
    process; the cache pickles without it, cheap to send to DataLoader workers) and
    ``_ARRAY_ATTR`` (the attribute holding that memmap, None until opened).

    Raises (on opening):
        FileNotFoundError: the folder, or one of its three files, is missing.
        ValueError: ``meta.json`` names another format or version.
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
                raise FileNotFoundError(f"{self.root} is not a prepared {self._KIND} cache: {required} is missing "
                                        f"(run `mocapkit prepare {self._COMMAND} --src ... --out {self.root}`)")
        self.meta = json.loads((self.root / META_FILE).read_text(encoding="utf-8"))
        if self.meta.get("format") != self._FORMAT or self.meta.get("version") != self._VERSION:
            raise ValueError(f"{self.root / META_FILE}: cache format {self.meta.get('format')!r} version "
                             f"{self.meta.get('version')!r}, expected {self._FORMAT!r} version {self._VERSION}; "
                             "prepare the cache again")
        with np.load(self.root / INDEX_FILE, allow_pickle=False) as index:
            absent = [k for k in self._INDEX_KEYS if k not in index.files]
            if absent:
                raise KeyError(f"{self.root / INDEX_FILE}: missing arrays {absent}")
            for key in self._INDEX_KEYS:
                setattr(self, key, index[key])
        setattr(self, self._ARRAY_ATTR, None)  # the memmap, opened lazily, per process

    def __len__(self) -> int:
        return len(self.names)

    def _array(self) -> np.ndarray:
        """The read-only memmap of ``_ARRAY_FILE``."""
        if getattr(self, self._ARRAY_ATTR) is None:
            setattr(self, self._ARRAY_ATTR, np.load(self.root / self._ARRAY_FILE, mmap_mode="r"))
        return getattr(self, self._ARRAY_ATTR)

    # Pickle without the memmap: each DataLoader worker reopens it on first access.
    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state[self._ARRAY_ATTR] = None
        return state

    def __setstate__(self, state: dict) -> None:
        self.__dict__.update(state)
