"""Evaluate search inside long takes (``mocapkit search --within``, :mod:`mocapkit.retrieval.subsequence`).

    OMP_NUM_THREADS=1 python scripts/results/retrieval_within.py [--hdm05 ../shared/data/hdm05_cuts11]
        [--cmu ../shared/data/cmu_amc] [--json OUT.json]

Long takes with known boundaries are built from real clips, in the per-frame features of ``dtw_takes`` (the
method for long takes: normalised-landmark positions and relational features at 30 fps, each divided by its
frames' spread in the takes; every step of the normalisation is per frame, so the features of a concatenation
are the concatenation of the features, the relational velocities aside):

- ``hdm05``: the clips of the held-out performers (``--take-performers``, dg and mm) shuffled (seed 0) and
  concatenated, 15 clips a take, consecutive clips cross-faded over ``--blend`` seconds (0.5 and 0.2; at most half
  a clip); each clip's segment (blends included) is its ground truth;
- ``cmu``: the CMU takes (``--cmu``: walks, runs, jumps, punches, swordplay, ...; no labels), each of the same
  held-out HDM05 clips planted at a random cut of a random CMU take with the same cross-fades; only the planted
  clips are ground truth, so a CMU walk or jump returned for an HDM05 walk or hop query counts as a miss.

Queries are the clips of the other performers (``--query-performers``, bd and bk): never the takes' performers.
A query's returned segments are its ``R`` best (``R`` = the ground-truth segments of its class in the takes);
one is correct when its IoU with a not yet matched ground-truth segment of the query's class is at least 0.5.
Reported: the precision over every returned segment (R-precision), P@1, and the search time in seconds per hour
of motion searched (search time per query / hours of takes; the features of the takes are computed once, as an
index stores them). ``--hour`` also times queries against one take of an hour (the CMU takes repeated).

The search is ``search_within`` with its defaults (subsequence DTW over every frame of the takes). Its features
(positions alone, relational alone, both scaled) and the way it picks segments were chosen on the training performers
only: queries of bd against takes of bk (docs/decisions.md#within-search-features). The DTW programme is compiled
before any timing.
Results: docs/results/retrieval.md#search-inside-long-takes.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from mocapkit.retrieval.dtw import frame_moments, moments_scale
from mocapkit.retrieval.subsequence import search_within, segment_iou
from mocapkit.train.registry import build_method

FPS = 30.0
#: ``--features``: both (``dtw_takes``), or one of them alone (the choice of docs/decisions.md#within-search-features).
FEATURES = "both"


def features(motions) -> list[np.ndarray]:
    """The raw per-frame features an index of ``dtw_takes`` stores, side by side: ``[T, 60 + F]`` (positions,
    then relational features); :func:`scaled` divides them by the scales the index learns."""
    method = build_method("retrieval", "dtw_takes")
    sequences = method.sequences(motions)
    method.features_ = method._choose_features(sequences)  # what fit learns first (positions, relational here)
    encoded = method._encode_sequences(sequences)
    if FEATURES == "positions":
        return encoded["positions"]
    if FEATURES == "relational":
        return encoded["relational"]
    return [np.hstack([p, r]) for p, r in zip(encoded["positions"], encoded["relational"])]


def scaled(takes: list[np.ndarray], *others: list[np.ndarray]) -> list[list[np.ndarray]]:
    """``takes`` and ``others`` with each feature divided by its scale learned from the takes' frames, as
    ``dtw_takes`` learns it when the takes are indexed (``scaling="frames"``)."""
    parts = (slice(0, 60), slice(60, None)) if takes[0].shape[1] > 60 and FEATURES == "both" else (slice(None),)
    scales = [moments_scale(frame_moments([t[:, part] for t in takes])) for part in parts]
    factor = np.concatenate([np.full(takes[0][:, part].shape[1], 1.0 / s) for part, s in zip(parts, scales)])
    return [[x * factor for x in group] for group in (takes, *others)]


def splice(base: np.ndarray, clip: np.ndarray, at: int, blend: int) -> tuple[np.ndarray, int]:
    """``base`` with ``clip`` inserted at frame ``at``, cross-faded over ``blend`` frames at both joins; the
    clip's first frame in the result."""
    blend = min(blend, len(clip) // 2)  # a clip shorter than two blends is faded over half its length
    head, tail = base[:at], base[at:]
    out = [head]
    start = len(head)
    piece = clip.copy()
    if len(head) >= blend and blend > 0:
        w = np.linspace(0.0, 1.0, blend)[:, None]
        piece[:blend] = (1 - w) * head[-blend:] + w * clip[:blend]
        out[0] = head[:-blend]
        start -= blend
    if len(tail) >= blend and blend > 0:
        w = np.linspace(1.0, 0.0, blend)[:, None]
        piece[-blend:] = w * clip[-blend:] + (1 - w) * tail[:blend]
        tail = tail[blend:]
    out += [piece, tail]
    return np.concatenate(out), start


def hdm05_takes(clips, labels, per_take: int, blend: int, seed: int):
    """``(takes, truth)``: the clips shuffled and concatenated ``per_take`` a take; truth ``[(take, start, end,
    label)]``."""
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(clips))
    takes, truth = [], []
    for t, first in enumerate(range(0, len(order), per_take)):
        take = np.zeros((0, clips[0].shape[1]))
        for i in order[first : first + per_take]:
            take, start = splice(take, clips[i], len(take), blend)
            truth.append((t, start, start + len(clips[i]), labels[i]))
        takes.append(take)
    return takes, truth


def planted_takes(base_takes, clips, labels, blend: int, seed: int):
    """``(takes, truth)``: each clip planted at a random cut of a random base take (cuts at least ``blend`` frames
    from the ends and from earlier plants)."""
    rng = np.random.default_rng(seed)
    takes = [b.copy() for b in base_takes]
    plants: list[list[tuple[int, int, str]]] = [[] for _ in takes]
    weights = np.array([len(b) for b in base_takes], dtype=float)
    for clip, label in zip(clips, labels):
        t = int(rng.choice(len(takes), p=weights / weights.sum()))
        for _ in range(100):
            at = int(rng.integers(blend, len(takes[t]) - blend))
            if all(not (s - blend <= at <= e + blend) for s, e, _ in plants[t]):
                break
        takes[t], start = splice(takes[t], clip, at, blend)
        shift = len(clip) - 2 * min(blend, len(clip) // 2)
        plants[t] = [(s + shift, e + shift, lab) if s >= at else (s, e, lab) for s, e, lab in plants[t]]
        plants[t].append((start, start + len(clip), label))
    truth = [(t, s, e, lab) for t, items in enumerate(plants) for s, e, lab in items]
    return takes, truth


def evaluate(queries, q_labels, takes, truth, **options) -> dict:
    """R-precision, P@1 at IoU 0.5 and seconds per hour searched (the module docstring)."""
    hours = sum(len(t) for t in takes) / FPS / 3600
    precisions, firsts, seconds = [], [], []
    per_class: dict[str, list[float]] = {}
    for query, label in zip(queries, q_labels):
        relevant = [g for g in truth if g[3] == label]
        if not relevant:
            continue
        start = time.perf_counter()
        found = search_within(query, takes, k=len(relevant), **options)
        seconds.append(time.perf_counter() - start)
        used, hits = set(), []
        for match in found:
            best = None
            for g, (t, s, e, _) in enumerate(relevant):
                if g not in used and t == match.take and segment_iou((match.start, match.end), (s, e)) >= 0.5:
                    best = g
                    break
            hits.append(best is not None)
            if best is not None:
                used.add(best)
        precisions.append(sum(hits) / len(relevant))
        firsts.append(float(bool(hits and hits[0])))
        per_class.setdefault(label, []).append(precisions[-1])
    return {
        "precision": float(np.mean(precisions)),
        "p@1": float(np.mean(firsts)),
        "queries": len(precisions),
        "segments": len(truth),
        "n_takes": len(takes),
        "hours": hours,
        "seconds_per_query": float(np.mean(seconds)),
        "seconds_per_hour": float(np.mean(seconds) / hours),
        "per_class": {k: float(np.mean(v)) for k, v in sorted(per_class.items())},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--hdm05", default="../shared/data/hdm05_cuts11")
    parser.add_argument("--cmu", default="../shared/data/cmu_amc")
    parser.add_argument("--take-performers", default="dg,mm")
    parser.add_argument("--query-performers", default="bd,bk")
    parser.add_argument("--per-take", type=int, default=15, help="clips per HDM05 take")
    parser.add_argument("--blend", default="0.5,0.2", help="cross-fades to evaluate, seconds (comma-separated)")
    parser.add_argument("--hour", type=int, default=5, help="queries timed against a one-hour take (0: none)")
    parser.add_argument("--features", default="both", choices=["both", "positions", "relational"])
    parser.add_argument("--json", default=None, help="write the results here")
    args = parser.parse_args()
    global FEATURES
    FEATURES = args.features

    from mocapkit.datasets.formats.motion_io import find_motion_files, read_motion
    from mocapkit.datasets.mocap.folders import list_clips, read_clips

    clips = list_clips("hdm05", args.hdm05)
    take_groups, query_groups = args.take_performers.split(","), args.query_performers.split(",")
    held = [c for c in clips if c["group"] in take_groups]
    asked = [c for c in clips if c["group"] in query_groups]
    start = time.perf_counter()
    held_x = features(read_clips(held))
    query_x = features(read_clips(asked))
    held_y, query_y = [c["class"] for c in held], [c["class"] for c in asked]
    cmu_paths = find_motion_files(Path(args.cmu))
    cmu_x = features([read_motion(p) for p in cmu_paths])
    print(
        f"features of {len(held) + len(asked)} clips and {len(cmu_paths)} CMU takes in "
        f"{time.perf_counter() - start:.0f} s",
        flush=True,
    )
    results = {"command": "python scripts/results/retrieval_within.py", "args": vars(args), "runs": []}
    search_within(query_x[0], query_x[1:2], k=1)  # numba compiles the DTW programme here, not in a timed query
    for seconds in [float(b) for b in args.blend.split(",")]:
        blend = int(round(seconds * FPS))
        takes, truth = hdm05_takes(held_x, held_y, args.per_take, blend, seed=0)
        takes, queries = scaled(takes, query_x)
        run = {"takes": "hdm05", "blend_s": seconds, **evaluate(queries, query_y, takes, truth)}
        results["runs"].append(run)
        print(json.dumps(run), flush=True)
        takes, truth = planted_takes(cmu_x, held_x, held_y, blend, seed=0)
        takes, queries = scaled(takes, query_x)
        run = {"takes": "cmu", "blend_s": seconds, **evaluate(queries, query_y, takes, truth)}
        run["cmu_minutes"] = sum(len(x) for x in cmu_x) / FPS / 60
        results["runs"].append(run)
        print(json.dumps(run), flush=True)

    if args.hour:  # the last CMU takes (planted), repeated to one hour
        hour = np.concatenate(takes * int(np.ceil(3600 * FPS / sum(len(t) for t in takes))))[: int(3600 * FPS)]
        rng = np.random.default_rng(0)
        times = []
        for i in rng.choice(len(queries), size=min(args.hour, len(queries)), replace=False):
            begin = time.perf_counter()
            search_within(queries[i], [hour], k=10)
            times.append(time.perf_counter() - begin)
        results["one_hour"] = {"queries": len(times), "seconds_per_query": float(np.mean(times)), "max": max(times)}
        print("one hour", json.dumps(results["one_hour"]), flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
