"""Retrieval metrics: mAP, P@k, 1-NN accuracy and Zhou 2014's top-20 agreement ("TP ratio").

A query's **relevant** database clips are those of its class (``relevance = same class``); the query itself is
never in its own database here (the benchmark excludes it). With ``distances [n_queries, n_database]``
(smaller = nearer):

- ``map``: mean over queries of the average precision of the ranking, scikit-learn's
  ``average_precision_score(relevant, -distance)`` (ties are scored as sklearn does); a query with no relevant
  clip in the database is left out of the mean and counted in ``n_without_relevant``;
- ``p@k``: mean fraction of relevant clips among the ``k`` nearest (stable order, ties by database order);
- ``nn_accuracy``: the 1-nearest-neighbour classification accuracy, the class of the nearest clip against the
  query's. With relevance = same class it equals ``p@1``; both are kept because papers report either name.

``tp_ratio`` follows ``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md`` §2.8: for a query, the top ``K``
of the mixed database (MT) and the top ``K`` of the clips of the query's own class (ST, ranked by the same
method) are compared; the ratio is ``|MT_K ∩ ST_K| / K`` with ``K = min(20, clips of the class - 1)``.
"""

from __future__ import annotations

import numpy as np
from sklearn.metrics import average_precision_score


def retrieval_metrics(distances, query_labels, database_labels, ks=(1, 10)) -> dict:
    """``{"metrics": {"map", "p@k"..., "nn_accuracy", "n_queries", "n_without_relevant"},
    "per_query": {"ap", "p@1", "nearest"}}`` (see the module docstring)."""
    d = np.asarray(distances, dtype=np.float64)
    q = np.asarray(query_labels)
    db = np.asarray(database_labels)
    if d.shape != (len(q), len(db)):
        raise ValueError(f"distances {list(d.shape)} do not match {len(q)} queries × {len(db)} database clips")
    if not np.isfinite(d).all():
        raise ValueError("distances contain NaN or inf")
    relevant = q[:, None] == db[None, :]
    order = np.argsort(d, axis=1, kind="stable")
    ranked = np.take_along_axis(relevant, order, axis=1)
    ap = np.full(len(q), np.nan)
    for i in range(len(q)):
        if relevant[i].any():
            ap[i] = average_precision_score(relevant[i], -d[i])
    metrics = {"map": float(np.nanmean(ap)) if np.isfinite(ap).any() else float("nan")}
    for k in ks:
        k_eff = min(int(k), len(db))
        metrics[f"p@{k}"] = float(ranked[:, :k_eff].mean())
    metrics["nn_accuracy"] = float((db[order[:, 0]] == q).mean())
    metrics["n_queries"] = len(q)
    metrics["n_without_relevant"] = int(np.isnan(ap).sum())
    return {
        "metrics": metrics,
        "per_query": {"ap": ap.tolist(), "p@1": ranked[:, 0].astype(float).tolist(), "nearest": order[:, 0].tolist()},
    }


def tp_ratio(distances, labels, query_indices, k: int = 20) -> dict:
    """Zhou's TP ratio over leave-one-out queries of one database.

    Args:
        distances: ``[n, n]`` distances among all database clips (the diagonal is ignored: the query is
            left out of its own lists).
        labels: ``[n]`` classes. query_indices: the queries (indices into the database).
        k: the list length (20 in the thesis), shortened to ``n_class - 1`` for a smaller class.

    Returns:
        ``{"tp_ratio": mean, "per_class": {class: mean}, "k_used": {class: K}}``.
    """
    d = np.asarray(distances, dtype=np.float64)
    labels = np.asarray(labels)
    ratios, per_class, k_used = [], {}, {}
    for i in np.asarray(query_indices, dtype=np.int64):
        others = np.flatnonzero(np.arange(len(labels)) != i)
        same = others[labels[others] == labels[i]]
        kk = min(int(k), len(same))
        if kk == 0:
            continue
        mixed_top = others[np.argsort(d[i, others], kind="stable")[:kk]]
        own_top = same[np.argsort(d[i, same], kind="stable")[:kk]]
        ratio = len(set(mixed_top.tolist()) & set(own_top.tolist())) / kk
        ratios.append(ratio)
        per_class.setdefault(str(labels[i]), []).append(ratio)
        k_used[str(labels[i])] = kk
    return {
        "tp_ratio": float(np.mean(ratios)) if ratios else float("nan"),
        "per_class": {c: float(np.mean(v)) for c, v in sorted(per_class.items())},
        "k_used": k_used,
    }
