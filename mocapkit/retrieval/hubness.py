"""Hubness reduction for retrieval distances: Gaussian mutual proximity (Schnitzer et al., JMLR 2012).

In a space of many dimensions, or under DTW whose distances grow with a clip's length and jitter, a few
database clips ("hubs") are near to almost every query and crowd the top of every ranking, while others are
near to none. Mutual proximity rescales a distance ``d(q, x)`` by how unusual it is **for both ends**: with
``D_q`` the distances from ``q`` to the database and ``D_x`` those from ``x`` to the database, each modelled as
a normal distribution with its own mean and standard deviation,

    MP(q, x) = P(D_q > d(q, x)) · P(D_x > d(q, x))          (similarity in [0, 1])
    distance = −log MP(q, x)                                 (0 for the nearest possible, no upper bound)

(the logarithm ranks exactly as ``1 − MP`` but keeps its resolution where ``MP`` underflows or rounds to 1).

A hub, near to everyone, has a small mean ``D_x``, so being near it is not unusual and is discounted. It needs no
labels and no parameter; its only state is the mean and standard deviation of each database clip's distances to
the database (to a reference subset of at most ``n_reference`` clips on large libraries), computed at ``fit``.
The query's own statistics come from its distances to the same reference clips (the DTW methods: the whole
database when it has at most ``n_reference`` clips), so that a search that ranks only some clips computes them too.

Chosen for the label-free retrieval default on training groups only (the rule, its outcome and the validation
table: docs/decisions.md#retrieval-default-mutual-proximity).
"""

from __future__ import annotations

import numpy as np
from scipy.special import log_ndtr

METHODS = ("mutual_proximity",)


def reference_indices(n_database: int, n_reference: int) -> np.ndarray:
    """int64 ``[min(n_database, n_reference)]``: the database clips the statistics are taken against, evenly
    spaced in database order (all of them when the database is not larger than ``n_reference``)."""
    if n_reference < 2:
        raise ValueError(f"n_reference must be at least 2, got {n_reference}")
    if n_database <= n_reference:
        return np.arange(n_database, dtype=np.int64)
    return np.unique(np.linspace(0, n_database - 1, int(n_reference)).round().astype(np.int64))


def database_statistics(database_to_reference: np.ndarray, reference: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation ``[n_database]`` of each database clip's distances to the reference clips,
    its distance to itself left out.

    Args:
        database_to_reference: float ``[n_database, n_reference]``.
        reference: int ``[n_reference]``, the database index of each reference column.
    """
    d = np.array(database_to_reference, dtype=np.float64)
    if d.shape[1] != len(reference):
        raise ValueError(f"{d.shape[1]} reference columns for {len(reference)} reference clips")
    if d.shape[1] < 2:
        raise ValueError("mutual proximity needs a database of at least 2 clips")
    d[reference, np.arange(len(reference))] = np.nan
    return np.nanmean(d, axis=1), np.nanstd(d, axis=1)


def mutual_proximity(
    distances: np.ndarray,
    database_mean: np.ndarray,
    database_std: np.ndarray,
    query_mean: np.ndarray | None = None,
    query_std: np.ndarray | None = None,
) -> np.ndarray:
    """float64 ``[n_queries, n_database]``: ``−log MP`` of query-to-database distances (see the module docstring).

    Args:
        distances: ``[n_queries, n_database]`` raw distances (smaller = nearer).
        database_mean, database_std: ``[n_database]`` from :func:`database_statistics`.
        query_mean, query_std: ``[n_queries]``, each query's statistics when ``distances`` holds only some of the
            database (a prefiltered search); None: taken from the rows of ``distances``.
    """
    d = np.asarray(distances, dtype=np.float64)
    tiny = np.finfo(np.float64).tiny
    query_mean = d.mean(axis=1, keepdims=True) if query_mean is None else np.asarray(query_mean).reshape(-1, 1)
    query_std = np.maximum(d.std(axis=1, keepdims=True) if query_std is None else np.reshape(query_std, (-1, 1)), tiny)
    # log P(D > d) of a normal, as scipy.stats.norm.logsf computes it, without its per-call overhead (a prefiltered
    # search calls this once per batch of candidates)
    log_beyond_query = log_ndtr(-(d - query_mean) / query_std)
    database_std = np.maximum(np.asarray(database_std), tiny)[None, :]
    log_beyond_database = log_ndtr(-(d - np.asarray(database_mean)[None, :]) / database_std)
    return -(log_beyond_query + log_beyond_database)
