"""Index a folder of motion files once, then query it: ``mocapkit index`` / ``mocapkit search`` and their Python API.

An index is a **folder**::

    manifest.json   what was indexed and how: the method's name and parameters, the model file's SHA-1 (trained
                    methods), the landmarks every indexed clip has, each file (absolute path, frames, fps, skeleton)
                    and each file skipped with ``--skip-bad`` (and why)
    state.npz       the fitted method: learned parameters and the database encodings as plain arrays
                    (``allow_pickle=False``: loading an index runs no code from it)
    *_frames.npy    per-frame database features (DTW methods, one file per feature, listed in the manifest):
                    each its own ``.npy``, opened memory-mapped, so a large library's frames stay on disk and a
                    search reads only the clips it compares against; ``--add`` appends to them in place

:func:`build_index` reads every file under ``src`` that :func:`~mocapkit.datasets.read_motion` reads
(recursively), fits the method on them (the whole folder is the database) and writes the folder;
:meth:`MotionIndex.search` ranks the indexed files for query files or motions. A query that is itself indexed
(same resolved path) is left out of its own results. Methods are the registry's retrieval methods
(``configs/retrieval/method/NAME.yaml``, :mod:`mocapkit.train.registry`; ``mocapkit methods retrieval``), with
``--set key=value`` overrides (Hydra's grammar); the one used without ``--method`` is the registry's default
(``configs/retrieval/method.yaml``: the label-free method without a training run that won our validation).
Loading an index rebuilds its method from the registry's class of that name with the saved parameters: no class
name is read from the index.

:meth:`MotionIndex.search_within` (``mocapkit search --within``) finds a query inside the indexed files (long takes):
segments ``(file, start s, end s, distance)`` by subsequence DTW (:mod:`mocapkit.retrieval.subsequence`).
:func:`add_to_index` (``mocapkit index --add``) appends the files under another folder, or given one by one, to an
existing index without fitting it again (:meth:`~mocapkit.retrieval.base.RetrievalMethod.add`): the manifest's
method and parameters are used, a file already indexed (same resolved path) is skipped with a message, the new
clips' frames are appended to the ``*_frames.npy`` files and the other files are rewritten.

Refusals, each naming both sides: a query method (or model) other than the index's, a query whose skeleton lacks
landmarks every indexed clip has, a query shorter than the method can encode, ``--add`` with another method,
parameters or model than the index's, an index of another format version; an unreadable file fails naming it
unless ``skip_bad`` (then it is skipped and reported); an empty folder is an error.
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Sequence
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from mocapkit.io_atomic import atomic_path, atomic_write_text
from mocapkit.retrieval.base import file_sha1

FORMAT = "mocapkit-retrieval-index"
#: 2: DTW indexes keep one database per feature (and mutual-proximity statistics); 3: and the raw distances to
#: their reference clips, which ``--add`` extends; 4: and the features used (``world_frame``) with the heading
#: concentration that chose them; 5: the per-frame features in their own ``*_frames.npy`` files, memory-mapped.
VERSION = 5
#: State arrays whose key ends so are written as ``KEY.npy`` beside ``state.npz`` and loaded memory-mapped (a
#: :class:`~mocapkit.retrieval.frames.RaggedFrames` store's frames; its ``KEY`` ending ``_offsets`` says how many
#: of the file's frames it holds).
FRAMES_SUFFIX, OFFSETS_SUFFIX = "_frames", "_offsets"
#: A DTW index of more files than this is built in parts of this many (:func:`build_index`), so that only one
#: part's motions and features are in memory: the method is fitted on the first, spread over the library, its
#: frames written to the output folder, and the others are added, their frames appended to those files.
PART_FILES = 50_000


class RetrievalIndexError(ValueError):
    """An index that cannot be built, read or queried as asked; the message names the file, method or key."""


def make_method(name: str, overrides: Sequence[str] = (), ckpt: str | os.PathLike | None = None):
    """A fresh retrieval method: the registry's ``name`` with the ``--set`` Hydra ``overrides``; ``ckpt`` is the
    trained model of ``embedding`` (a ``best.ckpt`` or an exported ``.onnx``), stored resolved so that the
    manifest finds it from any working directory.

    Raises:
        ConfigError: an unknown name (the message lists the names), an unknown key or bad value, a required
            parameter left unset (``embedding`` without ``--ckpt``).
        RetrievalIndexError: ``ckpt`` for a method that needs no trained model.
    """
    from mocapkit.train.registry import build_method, method_parameters

    overrides = list(overrides)
    if ckpt is not None:
        if "checkpoint" not in method_parameters("retrieval", name):
            raise RetrievalIndexError(f"--ckpt is for --method embedding; {name} needs no trained model")
        path = str(Path(ckpt).resolve()).replace("\\", "\\\\").replace("'", "\\'")
        overrides += ["checkpoint=null", f"onnx='{path}'"] if str(ckpt).endswith(".onnx") else [f"checkpoint='{path}'"]
    return build_method("retrieval", name, overrides)


def _jsonable(value):
    if isinstance(value, (tuple, list)):
        return [_jsonable(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (np.generic,)):
        value = value.item()
    if isinstance(value, float) and not np.isfinite(value):
        return None  # JSON has no NaN
    if isinstance(value, Path):
        return str(value)
    return value


def _read(path: Path):
    from mocapkit.datasets.formats.motion_io import read_motion

    return read_motion(path)


def _progress(text: str, quiet: bool) -> None:
    if not quiet:
        print(f"[mocapkit] {text}", file=sys.stderr, flush=True)


class MotionIndex:
    """A fitted retrieval method over a list of files (see the module docstring); :meth:`load` / :meth:`save`."""

    def __init__(
        self,
        method_name: str,
        method,
        files: list[dict],
        landmarks: list[str],
        skipped: list[dict],
        src: str | None = None,
        model_sha1: str | None = None,
    ):
        self.method_name = method_name
        self.method = method
        self.files = files
        self.landmarks = landmarks
        self.skipped = skipped
        self.src = src
        self.model_sha1 = model_sha1

    @property
    def paths(self) -> list[str]:
        return [f["path"] for f in self.files]

    # ------------------------------------------------------------------ persistence
    def save(self, out: str | os.PathLike) -> Path:
        out = Path(out)
        if out.exists() and not out.is_dir():
            raise RetrievalIndexError(f"--out {out}: exists and is not a folder (an index is a folder)")
        out.mkdir(parents=True, exist_ok=True)
        state = self.method._state()
        frames = {k: v for k, v in state.items() if k.endswith(FRAMES_SUFFIX)}
        for key, array in frames.items():
            target = out / f"{key}.npy"
            if isinstance(array, np.memmap) and target.exists() and Path(array.filename).samefile(target):
                array.flush()  # the frames are that file's (loaded from it, or appended to it in place)
                continue
            with atomic_path(target) as tmp, open(tmp, "wb") as handle:
                np.save(handle, np.asarray(array), allow_pickle=False)
        for stale in out.glob(f"*{FRAMES_SUFFIX}.npy"):  # another method's or feature's, from an earlier build
            if stale.stem not in frames:
                stale.unlink()
        with atomic_path(out / "state.npz") as tmp, open(tmp, "wb") as handle:
            np.savez(handle, **{k: v for k, v in state.items() if k not in frames})
        manifest = {
            "format": FORMAT,
            "version": VERSION,
            "method": self.method_name,
            "target": f"{type(self.method).__module__}.{type(self.method).__qualname__}",
            "params": _jsonable(self.method.get_params(deep=False)),
            "learned": _jsonable(
                {k: getattr(self.method, k) for k in ("features_", "heading_concentration_") if hasattr(self.method, k)}
            ),
            "model_sha1": self.model_sha1,
            "frames": sorted(frames),
            "landmarks": self.landmarks,
            "src": self.src,
            "n_files": len(self.files),
            "files": self.files,
            "skipped": self.skipped,
            "created": time.strftime("%Y-%m-%d %H:%M:%S"),
        }
        atomic_write_text(out / "manifest.json", json.dumps(manifest, indent=1))
        return out

    @classmethod
    def load(cls, path: str | os.PathLike, writable: bool = False) -> MotionIndex:
        """The index in the folder ``path``; ``writable``: its frame files are opened for clips added to the
        method to be appended to them in place (what :func:`add_to_index` does before saving to the same folder).
        """
        from mocapkit.retrieval.frames import open_frames

        path = Path(path)
        manifest_path = path / "manifest.json"
        if not manifest_path.is_file():
            raise RetrievalIndexError(
                f"--index {path}: not an index folder (no manifest.json; build one with "
                "mocapkit index --src DIR --out INDEX)"
            )
        try:
            manifest = json.loads(manifest_path.read_text())
        except json.JSONDecodeError as exc:
            raise RetrievalIndexError(f"{manifest_path}: not valid JSON ({exc})") from exc
        if manifest.get("format") != FORMAT or manifest.get("version") != VERSION:
            raise RetrievalIndexError(
                f"{manifest_path}: format {manifest.get('format')!r} version "
                f"{manifest.get('version')!r}, expected {FORMAT!r} version {VERSION} "
                "(build it again: mocapkit index --src DIR --out INDEX)"
            )
        name = manifest["method"]
        from mocapkit.train.errors import ConfigError
        from mocapkit.train.registry import method_class

        try:  # the registry's class of that name, never a class named by the file
            method = method_class("retrieval", name)(**manifest["params"])
        except (ConfigError, TypeError) as exc:
            raise RetrievalIndexError(f"{manifest_path}: method {name!r}: {exc}") from exc
        with np.load(path / "state.npz", allow_pickle=False) as data:
            state = {k: data[k] for k in data.files}
        for key in manifest.get("frames", []):
            offsets = state.get(key[: -len(FRAMES_SUFFIX)] + OFFSETS_SUFFIX)
            try:
                rows = int(offsets[-1]) if offsets is not None and len(offsets) else None
                state[key] = open_frames(path / f"{key}.npy", rows, writable=writable)
            except (OSError, ValueError) as exc:
                raise RetrievalIndexError(
                    f"{path / f'{key}.npy'}: cannot be read ({exc}); build the index again"
                ) from exc
        method._set_state(state)
        return cls(
            name,
            method,
            manifest["files"],
            manifest["landmarks"],
            manifest.get("skipped", []),
            manifest.get("src"),
            manifest.get("model_sha1"),
        )

    # ------------------------------------------------------------------ queries
    def check_query(self, motion, path: str) -> None:
        """Refuse a query whose skeleton lacks a landmark every indexed clip has (names both)."""
        from mocapkit.motion.layouts import find_landmarks

        have = set(find_landmarks(motion.joint_names, motion.layout_name))
        lacking = [lm for lm in self.landmarks if lm not in have]
        if lacking:
            layouts = sorted({f.get("skeleton") or "?" for f in self.files})
            raise RetrievalIndexError(
                f"query {path}: its skeleton ({motion.num_joints} joints: "
                f"{', '.join(list(motion.joint_names)[:8])}...) lacks the landmarks {lacking} "
                f"that every clip of the index ({', '.join(layouts)} skeletons) has"
            )

    def search(self, queries, k: int = 10, method: str | None = None, ckpt: str | os.PathLike | None = None) -> list:
        """Rank the indexed files for each query.

        Args:
            queries: file paths (read with ``read_motion``) or ``(name, Motion)`` pairs.
            k: results per query (``k <= 0``: every indexed file).
            method, ckpt: when given, must be the index's method (and model): refused otherwise, naming both.

        Returns:
            ``[{"query": path, "results": [{"path": indexed path, "distance": float}, ...]}, ...]``, nearest
            first; a query that is itself indexed is left out of its own results.
        """
        if method is not None and method != self.method_name:
            raise RetrievalIndexError(
                f"the index was built with --method {self.method_name}; it cannot be queried "
                f"with --method {method} (build another index with that method)"
            )
        if ckpt is not None:
            sha1 = file_sha1(ckpt)
            if sha1 != self.model_sha1:
                raise RetrievalIndexError(
                    f"--ckpt {ckpt} (SHA-1 {sha1[:12]}) is not the model the index was built "
                    f"with (SHA-1 {str(self.model_sha1)[:12]})"
                )
        names, motions = [], []
        for query in queries:
            if isinstance(query, tuple):
                name, motion = query
            else:
                name, motion = str(query), _read(Path(query))
            self.check_query(motion, name)
            names.append(name)
            motions.append(motion)
        if not motions:
            raise RetrievalIndexError("no query given")
        n = len(self.files)
        own = {str(Path(p).resolve()): i for i, p in enumerate(self.paths)}
        want = n if k is None or k <= 0 else min(int(k), n)
        indices, distances = self.method.search(motions, min(n, want + 1))
        out = []
        for name, row_i, row_d in zip(names, indices, distances):
            self_index = own.get(str(Path(name).resolve()))
            results = [
                {"path": self.paths[int(i)], "distance": float(d)} for i, d in zip(row_i, row_d) if int(i) != self_index
            ]
            out.append({"query": name, "results": results[:want]})
        return out

    def search_within(self, queries, k: int = 10, method: str | None = None, **options) -> list:
        """Find each query inside the indexed files (long takes): subsequence DTW over every frame
        (:func:`~mocapkit.retrieval.subsequence.search_within`) on the per-frame features the index's DTW method
        stores, each divided by its scale (:meth:`~mocapkit.retrieval.dtw.DTWRetrieval.scaled_frames`).

        Args:
            queries: file paths or ``(name, Motion)`` pairs, as :meth:`search`.
            k: matches per query, over all files (``k <= 0``: every candidate's).
            method: when given, must be the index's method.
            options: passed to :func:`~mocapkit.retrieval.subsequence.search_within`.

        Returns:
            ``[{"query": path, "results": [{"path", "start", "end", "distance"}, ...]}, ...]``, best first;
            ``start`` / ``end`` in seconds from the start of the file; a query's own file is not searched.

        Raises:
            RetrievalIndexError: an index whose method keeps no per-frame positions (not a DTW method), another
                method than the index's.
        """
        from mocapkit.retrieval.dtw import DTWRetrieval
        from mocapkit.retrieval.subsequence import search_within

        if method is not None and method != self.method_name:
            raise RetrievalIndexError(
                f"the index was built with --method {self.method_name}; it cannot be queried "
                f"with --method {method} (build another index with that method)"
            )
        estimator = self.method
        if not isinstance(estimator, DTWRetrieval):
            raise RetrievalIndexError(
                f"--within needs an index of a DTW method (dtw_takes for long takes, the default "
                f"dtw_world_frame, dtw_positions, dtw_plain); this index was built with {self.method_name}"
            )
        takes = estimator.scaled_frames(estimator.database_)
        own = {str(Path(p).resolve()): i for i, p in enumerate(self.paths)}
        out = []
        for query in queries:
            name, motion = query if isinstance(query, tuple) else (str(query), _read(Path(query)))
            self.check_query(motion, name)
            features = estimator.scaled_frames(estimator.encode([motion]))[0]
            skip = own.get(str(Path(name).resolve()))
            searched = [i for i in range(len(takes)) if i != skip]
            if not searched:
                raise RetrievalIndexError(f"query {name}: the index holds no other file to search")
            found = search_within(features, [takes[i] for i in searched], k=k, **options)
            fps = float(estimator.fps)
            results = [
                {
                    "path": self.paths[searched[m.take]],
                    "start": m.start / fps,
                    "end": m.end / fps,
                    "distance": m.distance,
                }
                for m in found
            ]
            out.append({"query": name, "results": results})
        return out


def build_index(
    src: str | os.PathLike,
    out: str | os.PathLike | None = None,
    method: str | None = None,
    overrides: Sequence[str] = (),
    ckpt: str | os.PathLike | None = None,
    skip_bad: bool = False,
    quiet: bool = False,
    workers: int = 1,
) -> MotionIndex:
    """Index every motion file under ``src`` (see the module docstring); written to ``out`` when given.

    ``method`` is a registry name (None: the registry's default), ``overrides`` its ``--set`` Hydra overrides,
    ``ckpt`` the trained model of ``embedding`` (:func:`make_method`); ``workers`` processes read the files and
    normalise their skeletons (:func:`_read_files`). A DTW method over more than :data:`PART_FILES` files is built in
    parts (:func:`_parts`), its frames written to ``out`` as they come.

    Raises:
        RetrievalIndexError: no motion file under ``src``; a file that cannot be read or used (named) unless
            ``skip_bad``; nothing usable at all.
        ConfigError: an unknown method, parameter or value.
    """
    from mocapkit.datasets.formats.motion_io import find_motion_files
    from mocapkit.train.registry import default_method

    src = Path(src)
    if not src.is_dir():
        raise RetrievalIndexError(f"--src {src}: not a folder")
    name = method or default_method("retrieval")
    estimator = make_method(name, overrides, ckpt=ckpt)
    paths = find_motion_files(src)
    if not paths:
        raise RetrievalIndexError(
            f"--src {src}: no motion files in this folder (looked for .amc, .bvh, .c3d, "
            ".skeleton, MSR *_skeleton3D.txt, recursively)"
        )
    _progress(f"indexing {len(paths)} files under {src} with {name}", quiet)
    in_parts = len(paths) > PART_FILES and out is not None and hasattr(estimator, "store_frames")
    parts = _parts(paths) if in_parts else [paths]
    sequences, files, skipped, landmark_sets = _read_files(parts[0], estimator, skip_bad, quiet, workers)
    if not sequences:
        raise RetrievalIndexError(f"--src {src}: none of the {len(parts[0])} motion files could be indexed")
    start = time.perf_counter()
    with _naming_clips(files):
        estimator.fit_sequences(sequences)
    _progress(f"fitted {name} on {len(sequences)} clips in {time.perf_counter() - start:.1f} s", quiet)
    if in_parts:  # the frames to the output folder, then the other parts added to them
        Path(out).mkdir(parents=True, exist_ok=True)
        # the frame files are written in place from here: an index already in the folder stops being one until
        # this one is saved, rather than being read with another index's frames
        (Path(out) / "manifest.json").unlink(missing_ok=True)
        estimator.store_frames(out)
        for part in parts[1:]:
            sequences, more_files, more_skipped, more_landmarks = _read_files(part, estimator, skip_bad, quiet, workers)
            if sequences:  # (a part whose every file was skipped adds nothing)
                with _naming_clips(more_files):
                    estimator.add_sequences(sequences)
            files, skipped, landmark_sets = files + more_files, skipped + more_skipped, landmark_sets + more_landmarks
            _progress(f"added: {len(files)} clips in {time.perf_counter() - start:.1f} s", quiet)
    if hasattr(estimator, "heading_concentration_") and np.isfinite(estimator.heading_concentration_):
        _progress(
            f"features {', '.join(estimator.features_)} (the clips' starting headings: concentration "
            f"{estimator.heading_concentration_:.2f}; world_frame={estimator.world_frame})",
            quiet,
        )
    common = set.intersection(*landmark_sets)
    from mocapkit.motion.layouts import LANDMARK_NAMES

    model_sha1 = getattr(estimator, "model_sha1_", None)
    index = MotionIndex(
        name, estimator, files, [lm for lm in LANDMARK_NAMES if lm in common], skipped, str(src.resolve()), model_sha1
    )
    if out is not None:
        index.save(out)
        _progress(f"wrote {out} ({len(files)} clips, {len(skipped)} skipped)", quiet)
    return index


def _parts(paths: list[Path]) -> list[list[Path]]:
    """A library of more than :data:`PART_FILES` files in parts of that many: the first evenly spaced over the
    library (what the method is fitted on: its reference clips, scales and descriptor axes), then the others in
    order, added to it."""
    first = set(np.linspace(0, len(paths) - 1, PART_FILES).round().astype(int).tolist())
    rest = [p for i, p in enumerate(paths) if i not in first]
    return [[paths[i] for i in sorted(first)]] + [rest[i : i + PART_FILES] for i in range(0, len(rest), PART_FILES)]


def _read_files(paths: list[Path], estimator, skip_bad: bool, quiet: bool, workers: int = 1):
    """Read each file and compute ``estimator``'s sequences of it (the normalised skeleton; the checks the method
    makes: landmarks, length): ``(sequences, file entries, skipped entries, landmark sets)``, in the files' order.

    With ``workers > 1`` the files go to that many processes (each with an unfitted copy of the method: an added
    file's skeleton is then checked against the index's when the clips are added, not file by file).

    Raises:
        RetrievalIndexError: a file that cannot be read or used (named), unless ``skip_bad``.
    """
    from functools import partial

    if int(workers) < 1:
        raise RetrievalIndexError(f"--workers {workers}: must be at least 1")
    if int(workers) == 1:
        results = map(partial(_read_one, estimator=estimator), paths)
        return _collect(paths, results, skip_bad, quiet)
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from sklearn.base import clone

    # spawned, not forked: the parent may hold OpenMP threads (FAISS, BLAS), which a forked child cannot use
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(int(workers), mp_context=context) as pool:
        chunk = max(1, min(64, len(paths) // (4 * int(workers))))
        results = pool.map(partial(_read_one, estimator=clone(estimator)), paths, chunksize=chunk)
        return _collect(paths, results, skip_bad, quiet)


def _read_one(path: Path, estimator):
    """``(sequence, file entry, landmark names)`` of one file, or ``(None, why, message)`` when it cannot be used
    (run in the index's worker processes: returns the failure rather than raising it)."""
    from mocapkit.motion.layouts import find_landmarks

    try:
        motion = _read(path)
        (sequence,) = estimator.sequences([motion], what="indexed")
    except Exception as exc:
        why = f"{type(exc).__name__}: {exc}"
        return None, why, str(exc) if str(path) in str(exc) else f"{path}: {why}"
    entry = {
        "path": str(path.resolve()),
        "frames": motion.num_frames,
        "fps": motion.fps,
        "skeleton": motion.layout_name or f"{motion.num_joints} joints",
    }
    return sequence, entry, set(find_landmarks(motion.joint_names, motion.layout_name))


def _collect(paths: list[Path], results, skip_bad: bool, quiet: bool):
    """:func:`_read_files`'s lists from :func:`_read_one`'s results, failures skipped (``skip_bad``) or raised."""
    sequences, files, skipped, landmark_sets = [], [], [], []
    for n, (path, (sequence, entry, landmarks)) in enumerate(zip(paths, results), 1):
        if sequence is None:
            why, message = entry, landmarks
            if not skip_bad:
                raise RetrievalIndexError(f"cannot index {message} (--skip-bad skips such files and reports them)")
            skipped.append({"path": str(path.resolve()), "why": why})
            _progress(f"skipped {path}: {why}", quiet)
            continue
        sequences.append(sequence)
        files.append(entry)
        landmark_sets.append(landmarks)
        if n % 100 == 0 or n == len(paths):
            _progress(f"read {n}/{len(paths)} files", quiet)
    return sequences, files, skipped, landmark_sets


@contextmanager
def _naming_clips(files: list[dict]):
    """Turns a method's error about clip ``i`` (its ``clip``, set by checks made over the whole database, as plain
    DTW's joint count) into a ``RetrievalIndexError`` naming ``files[i]``."""
    try:
        yield
    except ValueError as exc:
        clip = getattr(exc, "clip", None)
        if clip is None or not 0 <= clip < len(files):
            raise
        raise RetrievalIndexError(f"cannot index {files[clip]['path']}: {exc}") from exc


def add_to_index(
    index: str | os.PathLike,
    src: str | os.PathLike | Sequence[str | os.PathLike],
    method: str | None = None,
    overrides: Sequence[str] = (),
    ckpt: str | os.PathLike | None = None,
    skip_bad: bool = False,
    quiet: bool = False,
    workers: int = 1,
) -> tuple[MotionIndex, dict]:
    """Append the motion files under ``src`` (a folder, searched recursively, or a list of files and folders) to
    the index folder ``index`` without fitting it again, and rewrite the folder.

    ``method``, ``overrides`` and ``ckpt``, when given, must be the index's method, parameters and model (they are
    checked, never applied). Files already indexed are skipped with a message.

    Returns:
        the updated index and ``{"added": [paths], "duplicates": [paths], "skipped": [{"path", "why"}]}``.

    Raises:
        RetrievalIndexError: another method, parameters or model than the index's; an index of another format
            version; no motion file under ``src``; a bad file (named) unless ``skip_bad``; a method that cannot
            append (named, with the way out).
    """
    from mocapkit.datasets.formats.motion_io import find_motion_files
    from mocapkit.motion.layouts import LANDMARK_NAMES

    loaded = MotionIndex.load(index, writable=True)
    name = loaded.method_name
    if method is not None and method != name:
        raise RetrievalIndexError(
            f"--index {index} was built with --method {name}; files cannot be added with --method {method} "
            "(leave --method out to use the index's, or build another index)"
        )
    if overrides:
        asked = _jsonable(make_method(name, overrides).get_params(deep=False))
        have = _jsonable(loaded.method.get_params(deep=False))
        differ = {k: (have.get(k), v) for k, v in asked.items() if k not in ("checkpoint", "onnx") and have.get(k) != v}
        if differ:
            listed = ", ".join(f"{k}: index {a!r}, asked {b!r}" for k, (a, b) in differ.items())
            raise RetrievalIndexError(
                f"--index {index} was built with other parameters of {name} ({listed}); --add uses the index's"
            )
    if ckpt is not None and file_sha1(ckpt) != loaded.model_sha1:
        raise RetrievalIndexError(
            f"--ckpt {ckpt} (SHA-1 {file_sha1(ckpt)[:12]}) is not the model the index {index} was built with "
            f"(SHA-1 {str(loaded.model_sha1)[:12]})"
        )
    sources = [src] if isinstance(src, (str, os.PathLike)) else list(src)
    paths: list[Path] = []
    for item in sources:
        item = Path(item)
        if item.is_dir():
            paths += find_motion_files(item)
        elif item.is_file():
            paths.append(item)
        else:
            raise RetrievalIndexError(f"--add {item}: no such file or folder")
    if not paths:
        raise RetrievalIndexError(
            f"--add {', '.join(str(s) for s in sources)}: no motion files (looked for .amc, .bvh, .c3d, "
            ".skeleton, MSR *_skeleton3D.txt, recursively)"
        )
    indexed = {str(Path(p).resolve()) for p in loaded.paths}
    fresh, duplicates, seen = [], [], set()
    for path in paths:
        key = str(path.resolve())
        if key in indexed or key in seen:
            duplicates.append(key)
            _progress(f"already indexed, skipped: {path}", quiet)
        else:
            fresh.append(path)
            seen.add(key)
    report = {"added": [], "duplicates": duplicates, "skipped": []}
    if not fresh:
        _progress(f"nothing to add: all {len(paths)} files are in the index already", quiet)
        return loaded, report
    _progress(f"adding {len(fresh)} files to {index} ({name}, {len(loaded.files)} clips)", quiet)
    sequences, files, skipped, landmark_sets = _read_files(fresh, loaded.method, skip_bad, quiet, workers)
    report["skipped"] = skipped
    if sequences:
        start = time.perf_counter()
        try:
            with _naming_clips(files):
                loaded.method.add_sequences(sequences)
        except NotImplementedError as exc:
            raise RetrievalIndexError(
                f"--index {index}: {exc}; build the index again over all the files (mocapkit index --src DIR)"
            ) from exc
        _progress(f"added {len(sequences)} clips in {time.perf_counter() - start:.1f} s", quiet)
        common = set(loaded.landmarks).intersection(*landmark_sets)
        loaded.landmarks = [lm for lm in LANDMARK_NAMES if lm in common]
        loaded.files = loaded.files + files
        report["added"] = [f["path"] for f in files]
    loaded.skipped = loaded.skipped + skipped
    loaded.save(index)
    return loaded, report


def search_index(
    index: str | os.PathLike | MotionIndex,
    queries,
    k: int = 10,
    method: str | None = None,
    ckpt: str | os.PathLike | None = None,
) -> list:
    """:meth:`MotionIndex.search` on an index folder (or a loaded index)."""
    if not isinstance(index, MotionIndex):
        index = MotionIndex.load(index)
    return index.search(queries, k=k, method=method, ckpt=ckpt)
