"""Selection of ``dtw_large``'s distance, on training groups only: how the default's features are weighed when the
library is too large for mutual proximity's statistics.

Candidates (rule and outcome: docs/decisions.md#retrieval-large-libraries): the default's features (positions +
relational, plus the world terms gated by the starting headings, as ``world_frame="auto"``), each DTW distance
divided by its scale and summed, **without** mutual proximity (its exact statistics need every query's distance to
the whole library, and a prefiltered search can only sample them), the scale taken

- ``frames``: from the database's frames (root-mean-square distance to their mean frame; a build linear in the
  frames), or
- ``dtw``: as the median DTW distance among the database clips (``n_reference`` clips against the library).

Reported beside them, not candidates: the default (``dtw`` scales, mutual proximity) and plain DTW.

Validation as ``select_retrieval_world_frame.py``: every fold of the four test protocols, only the fold's database
groups, each inner group querying the others; the test queries are never read. The choice: the largest worst-cell
margin over plain DTW; margins within 0.005 tie, broken by the higher mean over the four cells.

Usage (from the repository root; about 2 min on 2 cores)::

    OMP_NUM_THREADS=2 python scripts/selection/select_retrieval_large.py [--out checkpoints/select_retrieval_large]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from select_retrieval_hubness import CELLS, inner_folds, mp  # noqa: E402
from select_retrieval_world_frame import choose, margin_row, matrices  # noqa: E402

from mocapkit.retrieval.dtw import (  # noqa: E402
    WORLD_FEATURES,
    WORLD_MIN_CONCENTRATION,
    frame_features,
    frame_moments,
    heading_concentration,
    moments_scale,
)
from mocapkit.retrieval.metrics import retrieval_metrics  # noqa: E402

FEATURES = ("positions", "relational", "world_positions", "world_velocity")


def score(dataset, protocol, data, frames, scaling: str | None, rerank: bool) -> float:
    """Validation mAP of the gated default features scaled by ``scaling`` (None: plain DTW), optionally re-ranked
    by mutual proximity."""
    d, tracks, bench = data
    fields = bench.fields
    per_fold = []
    for database, _queries in bench.folds(protocol).values():  # the test queries are not used
        aps = []
        for db, q, label in inner_folds(dataset, fields, protocol, database):
            if scaling is None:
                ranked = d["plain"][np.ix_(q, db)]
            else:
                use = list(FEATURES)
                if heading_concentration([tracks[i] for i in db], 30.0) < WORLD_MIN_CONCENTRATION:
                    use = [n for n in use if n not in WORLD_FEATURES]
                off = ~np.eye(len(db), dtype=bool)
                dq = dd = 0
                for name in use:
                    among = d[name][np.ix_(db, db)]
                    if scaling == "dtw":
                        scale = np.median(among[off])
                    else:
                        scale = moments_scale(frame_moments([frames[name][i] for i in db]))
                    dq, dd = dq + d[name][np.ix_(q, db)] / scale, dd + among / scale
                ranked = mp(dq, dd) if rerank else dq
            aps += retrieval_metrics(ranked, fields[label][q], fields[label][db])["per_query"]["ap"]
        per_fold.append(np.nanmean(aps))
    return float(np.mean(per_fold))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="checkpoints/select_retrieval_large")
    args = parser.parse_args()
    data, frames = {}, {}
    for ds in ("hdm05", "bandai", "msr"):
        data[ds] = matrices(ds)
        tracks = data[ds][1]
        frames[ds] = {n: [frame_features(t, n, 30.0) for t in tracks] for n in FEATURES}
    rows = [
        ("plain DTW (reference)", None, False, False),
        ("the default: dtw scales + mutual proximity (reference)", "dtw", True, False),
        ("frames scales, no re-ranking", "frames", False, True),
        ("dtw scales, no re-ranking", "dtw", False, True),
    ]
    lines = ["candidate | " + " | ".join(f"{ds} {p}" for ds, p in CELLS) + " | worst margin | mean"]
    plain, scored = None, []
    for name, scaling, rerank, candidate in rows:
        s = [score(ds, p, data[ds], frames[ds], scaling, rerank) for ds, p in CELLS]
        plain = s if plain is None else plain
        row = margin_row(lines, name, s, plain)
        if candidate:
            scored.append(row)
    choose(lines, scored, args.out)


if __name__ == "__main__":
    main()
