"""Selection of the `mocapkit index` default's last term, on training groups only: whether plain DTW's frames (every
joint of the file, root-centred, not turned) join the default's summed distance, at which weight, and when.

Candidates (rule: docs/decisions.md#retrieval-default-plain-joints): ``D`` = the default chosen before
(positions + relational + ``world_positions`` + ``world_velocity``, the world terms gated by the starting headings'
concentration, :data:`~mocapkit.retrieval.dtw.WORLD_MIN_CONCENTRATION`), and ``D`` + ``plain`` at weight 0.25, 0.5
or 1, gated with the world terms, or at 0.25 or 0.5 always on. Each feature's DTW distance is divided by its median
among the database clips (and by 1 / weight), summed, and re-ranked by mutual proximity, as
``select_retrieval_world_frame.py`` scores its candidates, with the same validation (every fold's database groups,
each inner group querying the others; the test queries are never read). The choice: the largest worst-cell margin
over plain DTW alone; margins within 0.005 tie, broken by the higher mean over the four cells; a candidate
replaces ``D`` only if its worst-cell margin exceeds ``D``'s by more than 0.005.

Usage (from the repository root; about 3 min on 2 cores, most of it the DTW matrices)::

    OMP_NUM_THREADS=2 python scripts/selection/select_retrieval_plain_joints.py [--out checkpoints/select_retrieval_plain_joints]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import select_retrieval_world_frame as world  # noqa: E402
from select_retrieval_hubness import CELLS  # noqa: E402

DEFAULT = [("positions", 1.0), ("relational", 1.0), ("world_positions", 1.0), ("world_velocity", 1.0)]


def candidates():
    """``(name, terms, plain gated)``: the default, then the default plus plain DTW's distance."""
    yield "D (the default before)", DEFAULT, True
    for weight in (0.25, 0.5, 1.0):
        yield f"D + plain*{weight} gated", [*DEFAULT, ("plain", weight)], True
    for weight in (0.25, 0.5):
        yield f"D + plain*{weight} always", [*DEFAULT, ("plain", weight)], False


def score(dataset: str, protocol: str, data, terms, plain_gated: bool) -> float:
    """Validation mAP of ``terms``, the world terms gated (and the plain term with them when ``plain_gated``)."""
    gated_terms = world.WORLD_TERMS + (("plain",) if plain_gated else ())
    return world.score(dataset, protocol, data, terms, gated=True, world_terms=gated_terms)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--out", default="checkpoints/select_retrieval_plain_joints")
    args = parser.parse_args()
    data = {ds: world.matrices(ds) for ds in ("hdm05", "bandai", "msr")}
    plain = [world.score(ds, p, data[ds], "plain", False) for ds, p in CELLS]
    lines = world.margin_table(plain)
    rows = [
        world.margin_row(lines, name, [score(ds, p, data[ds], terms, gated) for ds, p in CELLS], plain)
        for name, terms, gated in candidates()
    ]
    world.choose(lines, rows, args.out, incumbent=rows[0])


if __name__ == "__main__":
    main()
