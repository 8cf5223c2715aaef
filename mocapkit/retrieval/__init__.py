"""Motion retrieval: query by example over a library of motion files.

- :mod:`~mocapkit.motion.geometry`: the 20-landmark normalised skeleton every method works on (any layout);
- :mod:`~mocapkit.retrieval.base`: the contract (``fit`` on a database, ``distances`` / ``search`` for queries);
- methods: :mod:`~mocapkit.retrieval.dtw` (DTW on positions or relational features, the baseline),
  :mod:`~mocapkit.retrieval.selected_features` (HOD and GPF bag-of-words views, AMFS and Laplacian-score
  selection; Wang 2017 ch. 5), :mod:`~mocapkit.retrieval.tsr_stpm` (Zhou 2014 ch. 3),
  :mod:`~mocapkit.retrieval.embedding` (a trained encoder with a FAISS index);
- :mod:`~mocapkit.retrieval.index`: index a folder once and search it (``mocapkit index`` / ``mocapkit search``).

Metrics live in :mod:`mocapkit.retrieval.metrics`, the benchmark in :mod:`mocapkit.retrieval.benchmark`.
"""

from mocapkit.motion.geometry import SkeletonInputError, normalised_landmarks
from mocapkit.retrieval.base import RetrievalMethod
from mocapkit.retrieval.index import (
    MotionIndex,
    RetrievalIndexError,
    build_index,
    make_method,
    search_index,
)

__all__ = [
    "MotionIndex",
    "RetrievalIndexError",
    "SkeletonInputError",
    "RetrievalMethod",
    "build_index",
    "make_method",
    "normalised_landmarks",
    "search_index",
]
