"""Selection of a label-free re-ranking of DTW retrieval distances, on training groups only.

Candidates: three base distances (DTW on normalised positions, on relational features, and the sum of the two
each divided by its median among the database clips) × five re-rankings (none; Gaussian mutual proximity,
:mod:`mocapkit.retrieval.hubness`; local scaling, the distance divided by the geometric mean of both clips'
distance to their k-th neighbour, k 5 or 10; k-reciprocal re-ranking, Zhong et al. CVPR 2017, k1 20, k2 6,
λ 0.3, run per query on the query and the database). The last two exist only here, as candidates.

Validation: for every fold of the four test protocols of the retrieval benchmark (HDM05 cross-performer, Bandai
content and style, MSR cross-subject; :class:`~mocapkit.retrieval.benchmark.RetrievalBenchmark`), only
the fold's **database** groups are used: each of them in turn queries the others (HDM05: the other three
performers; Bandai: the database styles or contents dealt into 3 inner folds; MSR: the training subjects 1 3 5 7
9, one at a time). mAP pooled over the inner queries, averaged over the outer folds. The test queries are never
read by this script. The rule and its result: docs/decisions.md#retrieval-default-mutual-proximity
(the rule file was written into the git-ignored ``checkpoints/select_retrieval_rerank/``).

Usage (from the repository root; about 2 min, most of it the DTW matrices)::

    OMP_NUM_THREADS=2 python scripts/selection/select_retrieval_hubness.py [--out checkpoints/select_retrieval_rerank]
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

import numpy as np

from mocapkit.retrieval.benchmark import PROTOCOLS, RetrievalBenchmark
from mocapkit.retrieval.dtw import DTWRetrieval
from mocapkit.retrieval.hubness import database_statistics, mutual_proximity
from mocapkit.retrieval.metrics import retrieval_metrics

SHARED = Path(os.environ.get("MOCAPKIT_SHARED", "../shared")) / "data"
ROOTS = {"hdm05": SHARED / "hdm05_cuts11", "bandai": SHARED / "bandai_motion_1", "msr": SHARED / "msr_action3d"}
CELLS = (("hdm05", "cross_performer"), ("bandai", "content"), ("bandai", "style"), ("msr", "cross_subject"))


# ------------------------------------------------------------------------------------- re-rankings (candidates)
def mp(dq, dd):
    mean, std = database_statistics(dd, np.arange(len(dd)))
    return mutual_proximity(dq, mean, std)


def local_scaling(dq, dd, k):
    sigma_q = np.sort(dq, 1)[:, k - 1]
    sigma_d = np.sort(dd + np.diag(np.full(len(dd), np.inf)), 1)[:, k - 1]
    return dq / np.sqrt(sigma_q[:, None] * sigma_d[None, :])


def k_reciprocal(dq, dd, k1=20, k2=6, lam=0.3):
    n = len(dd) + 1
    out = np.empty_like(dq)
    for i in range(len(dq)):
        d = np.zeros((n, n))
        d[0, 1:] = d[1:, 0] = dq[i]
        d[1:, 1:] = dd
        d = (d / d.max(0, keepdims=True)).T
        rank = np.argsort(d, 1, kind="stable")
        v = np.zeros((n, n))
        for a in range(n):
            forward = rank[a, : k1 + 1]
            recip = forward[np.any(rank[forward, : k1 + 1] == a, 1)]
            expanded = recip
            for c in recip:
                half = round(k1 / 2) + 1
                cf = rank[c, :half]
                c_recip = cf[np.any(rank[cf, :half] == c, 1)]
                if len(np.intersect1d(c_recip, recip)) > 2 / 3 * len(c_recip):
                    expanded = np.append(expanded, c_recip)
            expanded = np.unique(expanded)
            w = np.exp(-d[a, expanded])
            v[a, expanded] = w / w.sum()
        v = np.stack([v[rank[a, :k2]].mean(0) for a in range(n)])
        jaccard = 1 - np.minimum(v[0], v[1:]).sum(1) / np.maximum(np.maximum(v[0], v[1:]).sum(1), 1e-12)
        out[i] = (1 - lam) * jaccard + lam * d[0, 1:]
    return out


RERANKINGS = {
    "none": lambda dq, dd: dq,
    "mutual_proximity": mp,
    "local_scaling_5": lambda dq, dd: local_scaling(dq, dd, 5),
    "local_scaling_10": lambda dq, dd: local_scaling(dq, dd, 10),
    "k_reciprocal": k_reciprocal,
}
BASES = ("positions", "relational", "sum")


# ------------------------------------------------------------------------------------- data and folds
def matrices(dataset: str) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], RetrievalBenchmark]:
    protocols = [p for p in PROTOCOLS[dataset] if p != "zhou_tp20"]
    bench = RetrievalBenchmark(
        dataset, str(ROOTS[dataset]), protocols, n_folds=3 if dataset == "bandai" else None
    )  # as configs/compare/retrieval_*.yaml
    out = {}
    for feature in ("positions", "relational"):
        method = DTWRetrieval(features=feature).fit(bench.motions)
        out[feature] = method.distances(bench.motions)
    return out, bench.fields, bench


def inner_folds(dataset, fields, protocol, database):
    label, group = PROTOCOLS[dataset][protocol]
    values = fields[group][database]
    groups = sorted(set(values.tolist()))
    held = [groups[i::3] for i in range(3)] if dataset == "bandai" else [[g] for g in groups]
    return [(database[~np.isin(values, h)], database[np.isin(values, h)], label) for h in held]


def base_distances(d, name, q, db):
    if name != "sum":
        return d[name][np.ix_(q, db)], d[name][np.ix_(db, db)]
    dq, dd = 0, 0
    off = ~np.eye(len(db), dtype=bool)
    for feature in ("positions", "relational"):
        among = d[feature][np.ix_(db, db)]
        scale = np.median(among[off])
        dq, dd = dq + d[feature][np.ix_(q, db)] / scale, dd + among / scale
    return dq, dd


def validation_map(dataset, protocol, d, fields, bench, base, reranking) -> float:
    per_fold = []
    for database, _queries in bench.folds(protocol).values():  # the test queries are not used
        aps = []
        for db, q, label in inner_folds(dataset, fields, protocol, database):
            dq, dd = base_distances(d, base, q, db)
            ranked = RERANKINGS[reranking](dq, dd)
            aps += retrieval_metrics(ranked, fields[label][q], fields[label][db])["per_query"]["ap"]
        per_fold.append(np.nanmean(aps))
    return float(np.mean(per_fold))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="checkpoints/select_retrieval_rerank")
    args = parser.parse_args()
    data = {ds: matrices(ds) for ds in ("hdm05", "bandai", "msr")}
    lines = ["base reranking  " + "  ".join(f"{ds}:{p}" for ds, p in CELLS) + "  mean"]
    for base in BASES:
        for reranking in RERANKINGS:
            scores = [validation_map(ds, p, *data[ds], base, reranking) for ds, p in CELLS]
            lines.append(f"{base} {reranking} " + " ".join(f"{x:.4f}" for x in scores) + f" mean {np.mean(scores):.4f}")
            print(lines[-1], flush=True)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "validation.txt").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
