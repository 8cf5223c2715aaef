"""HDM05 cross-actor splits: leave one actor out, or train on k actors (int64 index arrays into the clips given)."""

from __future__ import annotations

import itertools

import numpy as np

from mocapkit.datasets.mocap.hdm05_classes import ACTORS, HDM05ClipName, parse_clip_name


def _actor_array(actors) -> np.ndarray:
    out = []
    for a in actors:
        a = a.actor if isinstance(a, HDM05ClipName) else str(a)
        if a not in ACTORS:
            a = parse_clip_name(a, strict=False).actor
        out.append(a)
    return np.asarray(out, dtype=object)


def leave_one_actor_out(actors, test_actor: str | None = None):
    """Leave-one-actor-out splits.

    Args:
        actors: the actor of each clip (``"bd"`` …, clip names or :class:`HDM05ClipName`).
        test_actor: the held-out actor; None for all five folds.

    Returns:
        ``(train_idx, test_idx)`` int64 arrays for one actor, or a list of
        ``(actor, train_idx, test_idx)`` for every actor in :data:`ACTORS`.
    """
    arr = _actor_array(actors)
    if test_actor is not None:
        if test_actor not in ACTORS:
            raise ValueError(f"unknown HDM05 actor {test_actor!r}; known: {ACTORS}")
        test = arr == test_actor
        return np.flatnonzero(~test).astype(np.int64), np.flatnonzero(test).astype(np.int64)
    return [(a, *leave_one_actor_out(arr, a)) for a in ACTORS]


def k_actors_train(actors, k: int = 2, seed: int | None = None):
    """Cross-actor splits that train on ``k`` actors and test on the other ``5 - k``.

    Args:
        actors: the actor of each clip.
        k: number of training actors (1–4). The thesis used 2 ("e.g. 2 train / 3 test").
        seed: None for every combination (C(5, k), e.g. 10 for k = 2, in lexicographic
            order); an int picks one combination with ``numpy.random.default_rng(seed)``.

    Returns:
        A list of ``(train_actors, train_idx, test_idx)`` (all combinations), or one such
        tuple (seeded).
    """
    if not 1 <= k <= len(ACTORS) - 1:
        raise ValueError(f"k must be between 1 and {len(ACTORS) - 1}, got {k}")
    arr = _actor_array(actors)
    combos = list(itertools.combinations(ACTORS, k))

    def split(train_actors):
        train = np.isin(arr, train_actors)
        return tuple(train_actors), np.flatnonzero(train).astype(np.int64), np.flatnonzero(~train).astype(np.int64)

    if seed is None:
        return [split(c) for c in combos]
    pick = int(np.random.default_rng(seed).integers(len(combos)))
    return split(combos[pick])
