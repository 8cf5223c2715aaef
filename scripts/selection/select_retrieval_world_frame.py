"""Selection of the `mocapkit index` default's features, on training groups only: which world-frame terms join
DTW on positions + relational features (the former default), and when.

Candidates (rule: docs/decisions.md#retrieval-default-world-frame): ``B`` = positions + relational, plus one
world term ``X`` at weight 0.25, 0.5 or 1 (``world_positions``, ``world_velocity`` of
:mod:`mocapkit.retrieval.dtw`; ``clip_first`` and ``clip_world``, defined here only: the landmarks plus the pelvis
path from the clip's first frame, turned by its first half second's heading or not turned), or ``B`` +
``world_positions`` + ``Y`` at weight 0.5 or 1. Each feature's DTW distance is divided by its median among the
database clips (and by 1 / weight), summed, and re-ranked by mutual proximity. Every candidate with a world term
is scored twice: always on, and gated (the world terms dropped when the database clips' starting headings have a
mean resultant length below :data:`~mocapkit.retrieval.dtw.WORLD_MIN_CONCENTRATION`, as ``world_frame="auto"``).

Validation as ``select_retrieval_hubness.py``: every fold of the four test protocols, only the fold's database
groups, each inner group querying the others; the test queries are never read. The choice: the largest
worst-cell margin over plain DTW (every joint root-centred, no re-ranking) in the same validation; margins within
0.005 tie, broken by the higher mean over the four cells.

Usage (from the repository root; about 15 min on 2 cores, most of it the DTW matrices)::

    OMP_NUM_THREADS=2 python scripts/selection/select_retrieval_world_frame.py [--out checkpoints/select_retrieval_world_frame]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from select_retrieval_hubness import CELLS, PROTOCOLS, ROOTS, inner_folds, mp  # noqa: E402

from mocapkit.motion.geometry import turn_about_up  # noqa: E402
from mocapkit.retrieval.benchmark import RetrievalBenchmark  # noqa: E402
from mocapkit.retrieval.dtw import (  # noqa: E402
    WORLD_MIN_CONCENTRATION,
    DTWRetrieval,
    PlainDTWRetrieval,
    frame_features,
    heading_concentration,
)
from mocapkit.retrieval.metrics import retrieval_metrics  # noqa: E402

WORLD_TERMS = ("world_positions", "world_velocity", "clip_first", "clip_world")


def clip_paths(track, fps: float) -> dict[str, np.ndarray]:
    """The two candidates defined only here: the unturned landmarks plus the pelvis path from the first frame,
    ``[T, 60]``, not turned (``clip_world``) or turned by the first half second's mean heading (``clip_first``)."""
    world = frame_features(track, "world_positions", fps).reshape(-1, 20, 3)
    world = world + (track.pelvis - track.pelvis[0])[:, None]
    first = track.heading[: max(1, int(round(0.5 * fps)))]
    angle = np.arctan2(np.sin(first).mean(), np.cos(first).mean())
    return {
        "clip_world": world.reshape(len(world), -1),
        "clip_first": turn_about_up(world, angle, along="-x").reshape(len(world), -1),
    }


def matrices(dataset: str):
    """All-pairs DTW distances of every feature over every clip of the data set, and each clip's track."""
    protocols = [p for p in PROTOCOLS[dataset] if p != "zhou_tp20"]
    bench = RetrievalBenchmark(dataset, str(ROOTS[dataset]), protocols, n_folds=3 if dataset == "bandai" else None)
    method = DTWRetrieval()
    tracks = method.sequences(bench.motions)
    features = {n: [frame_features(t, n, method.fps) for t in tracks] for n in ("positions", "relational")}
    features.update({n: [frame_features(t, n, method.fps) for t in tracks] for n in WORLD_TERMS[:2]})
    paths = [clip_paths(t, method.fps) for t in tracks]
    features.update({n: [p[n] for p in paths] for n in WORLD_TERMS[2:]})
    d = {}
    for name, seqs in features.items():
        seqs = [np.ascontiguousarray(s, dtype=np.float64) for s in seqs]
        d[name] = method._feature_distances(seqs, seqs)
        print(f"{dataset}: {name} distances", flush=True)
    plain = PlainDTWRetrieval()
    joints = plain._encode_sequences(plain.sequences(bench.motions))["positions"]
    d["plain"] = plain._feature_distances(joints, joints)
    return d, tracks, bench


def score(dataset, protocol, data, terms, gated: bool, world_terms=WORLD_TERMS) -> float:
    """Validation mAP of the weighted sum ``terms`` (``[(feature, weight)]``; ``plain``: plain DTW alone); with
    ``gated``, the ``world_terms`` among them are dropped where the database clips do not start facing alike."""
    d, tracks, bench = data
    fields = bench.fields
    per_fold = []
    for database, _queries in bench.folds(protocol).values():  # the test queries are not used
        aps = []
        for db, q, label in inner_folds(dataset, fields, protocol, database):
            if terms == "plain":
                ranked = d["plain"][np.ix_(q, db)]
            else:
                use = terms
                if gated and heading_concentration([tracks[i] for i in db], 30.0) < WORLD_MIN_CONCENTRATION:
                    use = [(n, w) for n, w in terms if n not in world_terms]
                off = ~np.eye(len(db), dtype=bool)
                dq = dd = 0
                for name, weight in use:
                    among = d[name][np.ix_(db, db)]
                    scale = np.median(among[off]) / weight
                    dq, dd = dq + d[name][np.ix_(q, db)] / scale, dd + among / scale
                ranked = mp(dq, dd)
            aps += retrieval_metrics(ranked, fields[label][q], fields[label][db])["per_query"]["ap"]
        per_fold.append(np.nanmean(aps))
    return float(np.mean(per_fold))


def candidates():
    base = [("positions", 1.0), ("relational", 1.0)]
    yield "B (former default)", base, False
    for term in WORLD_TERMS:
        for weight in (0.25, 0.5, 1.0):
            for gated in (False, True):
                yield f"B + {term}*{weight}{' gated' if gated else ''}", base + [(term, weight)], gated
    for term in ("clip_first", "clip_world", "world_velocity"):
        for weight in (0.5, 1.0):
            for gated in (False, True):
                name = f"B + world_positions + {term}*{weight}{' gated' if gated else ''}"
                yield name, base + [("world_positions", 1.0), (term, weight)], gated


# ------------------------------------------------------------------------------------- the table and the choice
def margin_table(plain: list[float]) -> list[str]:
    """The validation table's header and plain DTW's line (printed): what :func:`margin_row` and :func:`choose`
    add to."""
    header = "candidate | " + " | ".join(f"{ds} {p}" for ds, p in CELLS) + " | worst margin | mean"
    lines = [header, "plain DTW | " + " | ".join(f"{x:.3f}" for x in plain) + " | | " + f"{np.mean(plain):.4f}"]
    print("\n".join(lines), flush=True)
    return lines


def margin_row(lines: list[str], name: str, scores: list[float], plain: list[float]) -> tuple[str, float, float]:
    """Appends (and prints) a candidate's line; ``(name, worst-cell margin over plain DTW, mean over the cells)``."""
    margin, mean = min(a - b for a, b in zip(scores, plain)), float(np.mean(scores))
    lines.append(f"{name} | " + " | ".join(f"{x:.3f}" for x in scores) + f" | {margin:+.3f} | {mean:.4f}")
    print(lines[-1], flush=True)
    return name, margin, mean


def choose(lines: list[str], rows: list[tuple[str, float, float]], out: str, incumbent=None) -> None:
    """The rows' choice: the largest worst-cell margin, margins within 0.005 tie, broken by the higher mean; an
    ``incumbent`` row stays unless the choice's margin exceeds its by more than 0.005. Appended to ``lines``,
    printed, and the table written to ``out/validation.txt``."""
    best = max(margin for _, margin, _ in rows)
    winner = max((r for r in rows if r[1] >= best - 0.005), key=lambda r: r[2])
    if incumbent is not None and winner[1] <= incumbent[1] + 0.005:
        winner = incumbent
    lines.append(f"choice: {winner[0]} (worst margin {winner[1]:+.3f}, mean {winner[2]:.4f})")
    print(lines[-1])
    Path(out).mkdir(parents=True, exist_ok=True)
    (Path(out) / "validation.txt").write_text("\n".join(lines) + "\n")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="checkpoints/select_retrieval_world_frame")
    args = parser.parse_args()
    data = {ds: matrices(ds) for ds in ("hdm05", "bandai", "msr")}
    plain = [score(ds, p, data[ds], "plain", False) for ds, p in CELLS]
    lines = margin_table(plain)
    rows = [
        margin_row(lines, name, [score(ds, p, data[ds], terms, gated) for ds, p in CELLS], plain)
        for name, terms, gated in candidates()
    ]
    choose(lines, rows, args.out)


if __name__ == "__main__":
    main()
