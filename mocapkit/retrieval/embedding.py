"""Retrieval by a learned motion embedding: a trained encoder, cosine similarity and a FAISS index.

:class:`EmbeddingRetrieval` encodes every clip with a network trained by ``mocapkit train
experiment=retrieval_supcon`` (or, without labels, ``retrieval_dtw_neighbours`` or ``retrieval_simclr``;
:mod:`mocapkit.retrieval.module`) into a unit-norm
vector and ranks the database by cosine similarity (distance ``1 − cos``):

- ``checkpoint="RUN/best.ckpt"``: the run's network in PyTorch; a list of runs: ``fit`` picks the run whose held-out
  groups are exactly the groups (``motion.metadata["group"]``) of the run's data absent from the database (how
  leave-one-performer-out folds use one run per fold: the queries' performer was never trained on);
- ``onnx="model.onnx"`` (``mocapkit export`` of such a run): onnxruntime and numpy only, torch is never imported.

Every motion becomes :func:`~mocapkit.motion.geometry.normalised_landmarks` (``fps``, ``heading``), then
``frames`` frames by :func:`resample_frames` (the function the training data module uses). The database's
embeddings go into a FAISS index (``index``; :mod:`mocapkit.retrieval.ann`): ``"flat"`` (``IndexFlatIP``:
exact), ``"hnsw"`` (``IndexHNSWFlat`` with inner product: approximate, for large libraries) or ``"auto"`` (the
default: flat below :data:`~mocapkit.retrieval.ann.AUTO_HNSW_MIN_CLIPS` clips, HNSW from there; ``index_kind_``
says which); :meth:`EmbeddingRetrieval.search` answers from it, and the returned distances are recomputed exactly
(float64) for the returned clips.

The state (``_state``) is the embeddings, the model's SHA-1 (``model_sha1_``: of the checkpoint or ONNX file;
an index refuses a model file with another digest) and, for HNSW, the serialised FAISS index.
"""

from __future__ import annotations

import hashlib
import io
import json
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from mocapkit.motion.container import Motion
from mocapkit.retrieval import ann
from mocapkit.retrieval.ann import INDEXES
from mocapkit.retrieval.base import RetrievalMethod, file_sha1, top_k


def resample_frames(sequence: np.ndarray, frames: int) -> np.ndarray:
    """float32 ``[frames, ...]``: ``sequence`` ``[T, ...]`` linearly interpolated at ``frames`` evenly spaced times
    from its first to its last frame (a one-frame sequence is repeated)."""
    x = np.asarray(sequence, dtype=np.float64)
    total = len(x)
    if total == 0:
        raise ValueError("resample_frames: an empty sequence")
    if total == 1:
        return np.repeat(x, frames, axis=0).astype(np.float32)
    t = np.linspace(0.0, total - 1.0, int(frames))
    lo = np.minimum(np.floor(t).astype(int), total - 2)
    w = (t - lo).reshape(-1, *([1] * (x.ndim - 1)))
    return ((1.0 - w) * x[lo] + w * x[lo + 1]).astype(np.float32)


class EmbeddingRetrieval(RetrievalMethod):
    """Retrieval by a trained motion encoder; see the module docstring.

    Args:
        checkpoint: a run's ``best.ckpt``, or a list of runs (``fit`` picks the one whose held-out groups are the
            groups absent from the database).
        onnx: an exported encoder (``mocapkit export``); onnxruntime + numpy only. Give ``checkpoint`` or ``onnx``.
        frames: frames every clip is resampled to; None: the model's training ``frames``.
        index: ``"flat"`` (exact inner product), ``"hnsw"`` (approximate, large libraries) or ``"auto"`` (HNSW
            from :data:`~mocapkit.retrieval.ann.AUTO_HNSW_MIN_CLIPS` clips, flat below).
        fps, heading: of :func:`~mocapkit.motion.geometry.normalised_landmarks` (the model's training values are
            expected; another value warns).
        batch_size: clips per forward pass.

    Attributes (after ``fit`` or a restored state): ``database_`` float32 ``[n, dim]`` (unit norm), ``n_database_``,
    ``model_sha1_`` (hex digest of the model file), ``frames_``, ``model_info_`` (the model's description: fps,
    frames, heading, loss, training data), ``checkpoint_used_`` (with a checkpoint), ``index_`` (the FAISS index) and
    ``index_kind_`` (``"flat"`` or ``"hnsw"``: what ``index`` resolved to).
    """

    label_free = True
    needs_run = True
    min_frames = 2

    def __init__(
        self,
        checkpoint: str | Sequence[str] | None = None,
        onnx: str | None = None,
        frames: int | None = None,
        index: str = "auto",
        fps: float = 30.0,
        heading: str = "frame",
        batch_size: int = 64,
    ):
        self.checkpoint = checkpoint
        self.onnx = onnx
        self.frames = frames
        self.index = index
        self.fps = fps
        self.heading = heading
        self.batch_size = batch_size

    # ------------------------------------------------------------------ the model
    def _model_paths(self) -> list[Path]:
        if (self.checkpoint is None) == (self.onnx is None):
            raise ValueError(
                "EmbeddingRetrieval: give checkpoint= (a trained run's best.ckpt, or a list of runs) or "
                "onnx= (an exported encoder), not both"
            )
        if self.onnx is not None:
            return [Path(self.onnx)]
        paths = [self.checkpoint] if isinstance(self.checkpoint, (str, Path)) else list(self.checkpoint)
        if not paths:
            raise ValueError("EmbeddingRetrieval: checkpoint= is an empty list")
        return [Path(p) for p in paths]

    def _load_onnx(self, path: Path) -> None:
        from mocapkit.deploy.runtime import cpu_session

        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such ONNX file")
        try:
            session = cpu_session(str(path))
        except Exception as exc:
            raise ValueError(f"{path}: onnxruntime cannot load it: {exc}") from exc
        meta = session.get_modelmeta().custom_metadata_map
        if "mocapkit_embedding" not in meta:
            raise ValueError(
                f"{path}: not a mocapkit embedding export (no mocapkit_embedding metadata); export one with"
                " `mocapkit export ckpt_path=RUN/best.ckpt` of a retrieval embedding run (experiment=retrieval_supcon,"
                " retrieval_dtw_neighbours or retrieval_simclr)"
            )
        self.model_info_ = json.loads(meta["mocapkit_embedding"])
        self._predict = lambda x: session.run(["embedding"], {"landmarks": x})[0]

    @staticmethod
    def _read_checkpoint(path: Path):
        """``(module, sha1)`` of an embedding run's checkpoint (read with ``weights_only=True`` and vetted)."""
        from mocapkit.retrieval.module import MotionEmbeddingModule
        from mocapkit.train.checkpoints import (
            parse_checkpoint,
            read_checkpoint_bytes,
            restore_error_detail,
        )

        raw = read_checkpoint_bytes(path)
        checkpoint = parse_checkpoint(raw, path)
        hparams = checkpoint.get("hyper_parameters", {})
        if "source" not in hparams or "loss" not in hparams:
            raise ValueError(
                f"{path}: not a motion-embedding checkpoint (no source / loss in its hyper-parameters); "
                "train one with `mocapkit train experiment=retrieval_supcon`"
            )
        try:
            module = MotionEmbeddingModule.load_from_checkpoint(io.BytesIO(raw), map_location="cpu", weights_only=True)
        except Exception as exc:
            raise ValueError(f"{path}: cannot restore the motion encoder from it: {restore_error_detail(exc)}") from exc
        return module.eval(), hashlib.sha1(raw).hexdigest()

    def _use_checkpoint(self, path: Path, module) -> None:
        import torch

        from mocapkit.retrieval.export import embedding_metadata

        self.model_info_ = embedding_metadata(module)
        self.checkpoint_used_ = str(path)
        model = module.model.eval()

        def predict(x: np.ndarray) -> np.ndarray:
            with torch.inference_mode():
                return model(torch.from_numpy(x)).numpy()

        self._predict = predict

    def _matching_model(self, sha1: str) -> Path:
        """The model file of the params whose SHA-1 is ``sha1`` (what a restored index was built with)."""
        paths = self._model_paths()
        digests = {p: file_sha1(p) for p in paths if p.is_file()}
        match = [p for p, d in digests.items() if d == sha1]
        if not match:
            raise ValueError(
                f"EmbeddingRetrieval: the index was built with the model of SHA-1 {sha1}, but "
                f"{[str(p) for p in paths]} {'has' if len(paths) == 1 else 'have'} digest(s) "
                f"{sorted(set(digests.values())) or 'none (missing files)'}: encode the database again "
                "with this model (fit), or give the model the index was built with"
            )
        return match[0]

    def _load_model(self, groups: list[str] | None = None, sha1: str | None = None, fresh: bool = False) -> None:
        """Load the model of the params: the ONNX file, the only checkpoint, the run of a list whose file has digest
        ``sha1`` (a restored state) or whose held-out groups are those absent from ``groups`` (``fit``); ``fresh``
        first forgets an earlier model and index (a new fit)."""
        if fresh:
            for name in (
                "_predict",
                "model_sha1_",
                "index_",
                "index_kind_",
                "frames_",
                "model_info_",
                "checkpoint_used_",
            ):
                self.__dict__.pop(name, None)
        paths = [self._matching_model(sha1)] if sha1 is not None else self._model_paths()
        if self.onnx is not None:
            self._load_onnx(paths[0])
            self.model_sha1_ = file_sha1(paths[0])
        elif len(paths) == 1:
            module, self.model_sha1_ = self._read_checkpoint(paths[0])
            self._use_checkpoint(paths[0], module)
        else:
            if not groups:
                raise ValueError(
                    "EmbeddingRetrieval.fit: with a list of checkpoints the database motions need groups "
                    "(motion.metadata['group'], e.g. the HDM05 actor) to pick the run that held out the "
                    "groups absent from the database"
                )
            runs = []
            for path in paths:
                module, digest = self._read_checkpoint(path)
                source = dict(module.hparams.source or {})
                absent = sorted(set(map(str, source.get("groups") or [])) - set(groups))
                runs.append((path, module, digest, absent, sorted(map(str, source.get("test_groups") or []))))
            for path, module, digest, absent, held_out in runs:
                if held_out and absent == held_out:
                    self.model_sha1_ = digest
                    self._use_checkpoint(path, module)
                    break
            else:
                raise ValueError(
                    f"EmbeddingRetrieval.fit: no checkpoint held out exactly the groups absent from the "
                    f"database (database groups {groups}; checkpoints and their held-out groups: "
                    f"{ {str(p): h for p, _, _, _, h in runs} })"
                )
        if not hasattr(self, "frames_"):  # a restored state keeps the frames its database was encoded with
            self.frames_ = int(self.frames or self.model_info_.get("frames") or 64)
        for name in ("fps", "heading"):
            trained = self.model_info_.get(name)
            if trained is not None and trained != getattr(self, name):
                warnings.warn(
                    f"EmbeddingRetrieval: {name}={getattr(self, name)!r} but the model was trained with {trained!r}",
                    stacklevel=3,
                )

    def _ensure_model(self) -> None:
        if not hasattr(self, "_predict"):
            self._load_model(sha1=getattr(self, "model_sha1_", None))

    # ------------------------------------------------------------------ the contract
    def fit(self, motions: Sequence[Motion], y=None) -> EmbeddingRetrieval:
        """Load the model (with a list of runs: the one that held out the groups absent from ``motions``), encode
        the database and build the FAISS index."""
        items = [motions] if isinstance(motions, Motion) else list(motions)
        groups = sorted(
            {str(m.metadata["group"]) for m in items if isinstance(m, Motion) and m.metadata.get("group") is not None}
        )
        self._load_model(groups=groups, fresh=True)
        return super().fit(items, y)

    def fit_sequences(self, sequences, y=None) -> EmbeddingRetrieval:
        """:meth:`fit` from the database's landmark sequences; the model is the one :meth:`fit` loaded, else (called
        directly: the groups are unknown) the one ``checkpoint`` or ``onnx`` names without groups."""
        if self.index not in INDEXES:
            raise ValueError(f"EmbeddingRetrieval: index={self.index!r}, one of {list(INDEXES)}")
        if not hasattr(self, "_predict"):
            self._load_model(groups=[], fresh=True)
        super().fit_sequences(sequences, y)
        self._build_index()
        return self

    def _encode_sequences(self, sequences: list[np.ndarray]) -> np.ndarray:
        self._ensure_model()
        out = []
        step = max(1, int(self.batch_size))
        for start in range(0, len(sequences), step):
            batch = np.stack([resample_frames(s, self.frames_) for s in sequences[start : start + step]])
            out.append(np.asarray(self._predict(batch.astype(np.float32)), dtype=np.float32))
        z = np.concatenate(out)
        return (z / np.maximum(np.linalg.norm(z, axis=1, keepdims=True), 1e-12)).astype(np.float32)

    def _distances(self, queries: np.ndarray, database: np.ndarray) -> np.ndarray:
        return 1.0 - np.asarray(queries, np.float64) @ np.asarray(database, np.float64).T

    def _add_sequences(self, sequences: list[np.ndarray]) -> None:
        """Append the new clips' embeddings and add them to the FAISS index (rebuilt only when ``index`` resolves
        to another kind for the new size)."""
        n_old = len(self.database_)
        super()._add_sequences(sequences)
        self.index_, self.index_kind_ = ann.extend(self.index_, self.index_kind_, self.database_[n_old:], self.index)

    def search(self, queries: Sequence[Motion], k: int = 10) -> tuple[np.ndarray, np.ndarray]:
        """The ``k`` nearest database clips of each query from the FAISS index (``k <= 0`` or above the size: all),
        nearest first; distances ``1 − cos`` recomputed exactly, ties by database order within the ``k`` returned."""
        self._check_fitted()
        q = np.ascontiguousarray(self.encode(queries), dtype=np.float32)
        n = int(self.n_database_)
        k = n if k <= 0 or k > n else int(k)
        if self.index_kind_ == "hnsw" and k == n:  # every clip: exact (a graph search need not reach them all)
            found = top_k(self._distances(q, self.database_), k)[0]
        else:
            found = ann.search(self.index_, self.index_kind_, q, k)
        exact = None
        for row in np.flatnonzero((found < 0).any(axis=1)):  # HNSW could not reach k clips: answer exactly
            exact = self._distances(q, self.database_) if exact is None else exact
            found[row] = top_k(exact[row : row + 1], k)[0][0]
        d = 1.0 - np.einsum("qd,qkd->qk", q.astype(np.float64), np.asarray(self.database_, np.float64)[found])
        order = np.lexsort((found, d), axis=1)
        return np.take_along_axis(found, order, axis=1), np.take_along_axis(d, order, axis=1)

    # ------------------------------------------------------------------ index and state
    def _build_index(self) -> None:
        """``index_`` over ``database_``, of the kind ``index`` resolves to for its size (``index_kind_``)."""
        self.index_kind_ = ann.resolved_kind(self.index, len(self.database_))
        self.index_ = ann.build(self.database_, self.index_kind_, metric="inner_product")

    def _state(self) -> dict[str, np.ndarray]:
        self._check_fitted()
        state = {
            "embeddings": np.asarray(self.database_, dtype=np.float32),
            "model_sha1": np.frombuffer(bytes.fromhex(self.model_sha1_), dtype=np.uint8).copy(),
            "frames": np.array([self.frames_], dtype=np.int64),
        }
        if self.index_kind_ == "hnsw":
            state["hnsw_index"] = ann.serialise(self.index_)
        return state

    def _set_state(self, state: dict[str, np.ndarray]) -> None:
        if self.index not in INDEXES:
            raise ValueError(f"EmbeddingRetrieval: index={self.index!r}, one of {list(INDEXES)}")
        for name in ("_predict", "model_info_", "checkpoint_used_"):
            self.__dict__.pop(name, None)
        sha1 = bytes(np.asarray(state["model_sha1"], dtype=np.uint8)).hex()
        self._matching_model(sha1)  # refuses a model file of another digest (loaded when first needed)
        self.model_sha1_ = sha1
        self.database_ = np.asarray(state["embeddings"], dtype=np.float32)
        self.n_database_ = len(self.database_)
        self.frames_ = int(np.asarray(state["frames"]).reshape(-1)[0])
        if self.index in ("auto", "hnsw") and "hnsw_index" in state:  # a saved graph is used as it was built
            self.index_kind_ = "hnsw"
            self.index_ = ann.deserialise(state["hnsw_index"])
        else:
            self._build_index()


__all__ = ["EmbeddingRetrieval", "resample_frames"]
