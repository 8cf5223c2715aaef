"""Selection of a heading-free term for the `mocapkit index` default, on training groups only: whether each
landmark's speed in the body's frame (``speeds`` of :mod:`mocapkit.retrieval.dtw`) joins the default's sum, and at
which weight.

Candidates (rule: docs/decisions.md#retrieval-default-speeds): ``DJ`` = the default chosen before (positions +
relational + the world terms and plain DTW's joints at half weight, gated; docs/decisions.md#retrieval-default-plain-joints),
and ``DJ`` + ``speeds`` at weight 0.25, 0.5 or 1, never gated (the speeds read no frame). Distances, validation and
mutual proximity as ``select_retrieval_plain_joints.py`` (every fold's database groups, each inner group querying the
others; the test queries are never read). The choice: the largest worst-cell margin over plain DTW alone; margins
within 0.005 tie, broken by the higher mean over the four cells; a candidate replaces ``DJ`` only if its worst-cell
margin exceeds ``DJ``'s by more than 0.005.

Usage (from the repository root; about 3 min on 2 cores, most of it the DTW matrices)::

    OMP_NUM_THREADS=2 python scripts/selection/select_retrieval_speeds.py [--out checkpoints/select_retrieval_speeds]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import select_retrieval_world_frame as world  # noqa: E402
from select_retrieval_hubness import CELLS  # noqa: E402
from select_retrieval_plain_joints import DEFAULT, score  # noqa: E402

from mocapkit.retrieval.dtw import DTWRetrieval, frame_features  # noqa: E402

WITH_JOINTS = [*DEFAULT, ("plain", 0.5)]


def candidates():
    """``(name, terms)``: the default, then the default plus the landmarks' speeds."""
    yield "DJ (the default before)", WITH_JOINTS
    for weight in (0.25, 0.5, 1.0):
        yield f"DJ + speeds*{weight}", [*WITH_JOINTS, ("speeds", weight)]


def with_speeds(dataset: str):
    """:func:`select_retrieval_world_frame.matrices` plus the all-pairs DTW distances of the speeds."""
    d, tracks, bench = world.matrices(dataset)
    method = DTWRetrieval()
    speeds = [np.ascontiguousarray(frame_features(t, "speeds", method.fps)) for t in tracks]
    d["speeds"] = method._feature_distances(speeds, speeds)
    print(f"{dataset}: speeds distances", flush=True)
    return d, tracks, bench


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="checkpoints/select_retrieval_speeds")
    args = parser.parse_args()
    data = {ds: with_speeds(ds) for ds in ("hdm05", "bandai", "msr")}
    plain = [world.score(ds, p, data[ds], "plain", False) for ds, p in CELLS]
    lines = world.margin_table(plain)
    rows = [
        world.margin_row(lines, name, [score(ds, p, data[ds], terms, plain_gated=True) for ds, p in CELLS], plain)
        for name, terms in candidates()
    ]
    world.choose(lines, rows, args.out, incumbent=rows[0])


if __name__ == "__main__":
    main()
