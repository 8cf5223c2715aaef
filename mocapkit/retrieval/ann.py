"""The approximate-nearest-neighbour index both fast searches use: an exact FAISS flat index on small libraries,
HNSW on large ones. :class:`~mocapkit.retrieval.embedding.EmbeddingRetrieval` searches its embeddings with it
(inner product), and :class:`~mocapkit.retrieval.dtw.DTWRetrieval`'s ``prefilter`` its clips' fixed-length
descriptors (Euclidean) before DTW ranks the few it returns.
"""

from __future__ import annotations

import numpy as np

#: ``index="auto"`` builds HNSW for libraries of at least this many clips, an exact flat index below: exact search
#: grows with the library (bench/RESULTS.md#retrieval-latency: 2.2 ms a query at 10^5 clips, HNSW 0.13 ms at
#: recall@10 1.000), and below ~10^4 clips it stays under half a millisecond, without HNSW's build time and
#: approximation.
AUTO_HNSW_MIN_CLIPS = 20_000
#: HNSW graph degree and build / search breadth (FAISS parameters).
HNSW_M, HNSW_EF_CONSTRUCTION, HNSW_EF_SEARCH = 32, 80, 64
#: What ``index`` may be.
INDEXES = ("auto", "flat", "hnsw")
METRICS = ("inner_product", "l2")


def _faiss():
    """The ``faiss`` module, with ``ezc3d`` loaded before it: both are SWIG builds, and when faiss's loads first
    ezc3d's overloads of ``std::vector`` arguments no longer resolve (writing a C3D file then raises ``TypeError``
    in ``Parameter_set``); loaded in this order both work."""
    try:
        import ezc3d  # noqa: F401
    except ImportError:  # C3D writing is not installed: nothing to protect
        pass
    import faiss

    return faiss


def resolved_kind(index: str, n: int) -> str:
    """``"flat"`` or ``"hnsw"``: ``index``, with ``"auto"`` decided by the library's size ``n``."""
    if index not in INDEXES:
        raise ValueError(f"index must be one of {INDEXES}, got {index!r}")
    if index != "auto":
        return index
    return "hnsw" if n >= AUTO_HNSW_MIN_CLIPS else "flat"


def build(vectors: np.ndarray, kind: str, metric: str = "inner_product"):
    """A FAISS index of ``kind`` (``"flat"`` or ``"hnsw"``) over float32 ``vectors`` ``[n, d]``."""
    faiss = _faiss()

    if metric not in METRICS:
        raise ValueError(f"metric must be one of {METRICS}, got {metric!r}")
    x = np.ascontiguousarray(vectors, dtype=np.float32)
    faiss_metric = faiss.METRIC_INNER_PRODUCT if metric == "inner_product" else faiss.METRIC_L2
    if kind == "hnsw":
        index = faiss.IndexHNSWFlat(x.shape[1], HNSW_M, faiss_metric)
        index.hnsw.efConstruction = HNSW_EF_CONSTRUCTION
    elif kind == "flat":
        index = faiss.IndexFlatIP(x.shape[1]) if metric == "inner_product" else faiss.IndexFlatL2(x.shape[1])
    else:
        raise ValueError(f"kind must be 'flat' or 'hnsw', got {kind!r}")
    index.add(x)
    return index


def extend(index, kind: str, vectors: np.ndarray, requested: str) -> tuple[object, str]:
    """``(index, kind)``: ``index`` (of ``kind``) with float32 ``vectors`` ``[n, d]`` added, in place, and its kind;
    when ``requested`` (``"auto"``) resolves to another kind for the new size, a new index of that kind over the
    old vectors (read back from the index) and the new ones, so that a library grown past
    :data:`AUTO_HNSW_MIN_CLIPS` clips by additions is searched as one built at that size."""
    x = np.ascontiguousarray(vectors, dtype=np.float32)
    wanted = resolved_kind(requested, index.ntotal + len(x))
    if wanted == kind:
        index.add(x)
        return index, kind
    metric = "inner_product" if index.metric_type == _faiss().METRIC_INNER_PRODUCT else "l2"
    return build(np.vstack([index.reconstruct_n(0, index.ntotal), x]), wanted, metric), wanted


def search(index, kind: str, queries: np.ndarray, k: int) -> np.ndarray:
    """int64 ``[n_queries, k]`` database indices from ``index`` (−1 where HNSW reached fewer than ``k``); HNSW
    searches at least ``k`` wide (a DTW prefilter asks for hundreds, whose last few matter little: ``2k`` cost it
    a millisecond more a query at 3×10^4 clips)."""
    if kind == "hnsw":
        index.hnsw.efSearch = max(HNSW_EF_SEARCH, k)
    return index.search(np.ascontiguousarray(queries, dtype=np.float32), int(k))[1].astype(np.int64)


def serialise(index) -> np.ndarray:
    """uint8 bytes of a FAISS index (for a method's ``_state``, read back with :func:`deserialise`)."""
    return _faiss().serialize_index(index)


def deserialise(data: np.ndarray):
    return _faiss().deserialize_index(np.asarray(data, dtype=np.uint8))
