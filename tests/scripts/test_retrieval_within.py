"""scripts/results/retrieval_within.py: long takes built from clips with known boundaries, and the score of search
inside them; a clip of the takes, given as the query, is found where it was put."""

import numpy as np

from mocapkit.datasets import read_motion
from tests.scripts import load_script
from tests.shared_data import synthetic_hdm05_folder


def test_a_clip_of_the_takes_finds_itself_where_it_was_spliced(tmp_path_factory):
    script = load_script("scripts/results/retrieval_within.py")
    folder = synthetic_hdm05_folder(tmp_path_factory, ("walk2StepsLstart", "squat1Reps"), max_frames=160)
    paths = sorted(folder.glob("*/*.amc"))
    clips = script.features([read_motion(p) for p in paths])
    labels = [p.name.split("_")[2] for p in paths]
    assert all(x.ndim == 2 and x.shape[1] > 60 and np.isfinite(x).all() for x in clips)  # positions + relational
    takes, truth = script.hdm05_takes(clips, labels, per_take=4, blend=6, seed=0)
    assert len(takes) == 2 and len(truth) == len(clips)
    for t, start, end, _ in truth:  # each clip's segment lies inside its take
        assert 0 <= start < end <= len(takes[t])
    takes, queries = script.scaled(takes, clips)
    result = script.evaluate(queries, labels, takes, truth)
    assert result["p@1"] == 1.0 and 0.5 <= result["precision"] <= 1.0 and result["queries"] == len(clips)
