"""CASIA-B evaluation protocols: the thesis's closed-set hold-out and the standard cross-subject gallery/probe split.

Closed set (thesis §6.1, "leave-one-out")
    Every subject is seen in training. For each (subject, view), one ``nm``, one
    ``bg`` and one ``cl`` sequence are drawn at random (seeded) and held out for
    testing; the task is classification over all subjects (and over views and
    conditions). All GEIs (cycles) of a sequence stay on the same side.

Cross subject (OpenGait's CASIA-B protocol, Yu et al. 2006 "LT" split)
    Subjects 001–074 train, 075–124 test (on a smaller set, the first
    ``round(74/124 · n)`` subjects in ID order train). Among the test subjects the
    gallery is ``nm-01..04`` and the probes ``nm-05/06``, ``bg-01/02`` and
    ``cl-01/02``; rank-1 is computed per (probe view, gallery view) with identical
    views excluded (:mod:`mocapkit.gait.metrics`).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mocapkit.datasets.formats.casia_b import CONDITIONS, NUM_SUBJECTS

PROTOCOLS = ("closed_set", "cross_subject")
#: OpenGait's CASIA-B partition: the first 74 of 124 subjects train.
STANDARD_TRAIN_SUBJECTS = 74
#: Gallery and probe sequences of the cross-subject protocol, by condition name.
GALLERY: dict[str, tuple[int, ...]] = {"nm": (1, 2, 3, 4)}
PROBES: dict[str, tuple[int, ...]] = {"nm": (5, 6), "bg": (1, 2), "cl": (1, 2)}


def closed_set_split(
    subjects: np.ndarray, conditions: np.ndarray, sequences: np.ndarray, views: np.ndarray, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """The thesis's hold-out: per (subject, view), one random sequence of each condition goes to test.

    Args:
        subjects, sequences, views: per-GEI integers (1-based subject and repetition, view in degrees).
        conditions: per-GEI condition labels (0 nm, 1 bg, 2 cl).
        seed: the draw.
    Returns:
        ``(train_idx, test_idx)``, sorted int64 indices into the arrays. A (subject, view, condition)
        with a single sequence keeps it for testing (so every combination is tested); the caller
        reports the resulting counts.
    """
    subjects, conditions, sequences, views = (
        np.asarray(a, dtype=np.int64) for a in (subjects, conditions, sequences, views)
    )
    rng = np.random.default_rng(seed)
    test = np.zeros(len(subjects), dtype=bool)
    groups = np.unique(np.stack([subjects, views, conditions], axis=1), axis=0)
    for subject, view, condition in groups:  # sorted, so the draw does not depend on file order
        in_group = (subjects == subject) & (views == view) & (conditions == condition)
        held_out = rng.choice(np.unique(sequences[in_group]))
        test |= in_group & (sequences == held_out)
    return np.flatnonzero(~test), np.flatnonzero(test)


def cross_subject_subjects(available: np.ndarray, num_train: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Train and test subjects of the cross-subject protocol.

    Args:
        available: subject IDs present in the data (any order, repeats allowed).
        num_train: training subjects; None: 74 on the full 124-subject set, else
            ``round(74 / 124 · n)`` of the ``n`` available, at least 1 and leaving at least 2 for testing.
    Returns:
        ``(train_subjects, test_subjects)``: sorted IDs; training takes the lowest IDs, as OpenGait does.
    """
    ids = np.unique(np.asarray(available, dtype=np.int64))
    if num_train is None:
        num_train = (
            STANDARD_TRAIN_SUBJECTS
            if len(ids) == NUM_SUBJECTS
            else int(round(STANDARD_TRAIN_SUBJECTS / NUM_SUBJECTS * len(ids)))
        )
        num_train = min(max(num_train, 1), len(ids) - 2)
    if not 1 <= num_train <= len(ids) - 2:
        raise ValueError(
            f"num_train_subjects={num_train}: needs 1 ≤ n ≤ {len(ids) - 2} "
            f"({len(ids)} subjects available; testing needs at least 2)"
        )
    return ids[:num_train], ids[num_train:]


class ProtocolSplit(NamedTuple):
    """The two sides of a CASIA-B protocol (see :func:`protocol_split`)."""

    train_idx: np.ndarray  #: int64 [n_train], sorted GEI indices of the training side (validation included)
    test_idx: np.ndarray  #: int64 [n_test], sorted GEI indices of the test side
    train_subjects: np.ndarray  #: int64, sorted subject IDs with training GEIs (the label space)
    test_subjects: np.ndarray  #: int64, sorted subject IDs with test GEIs


def protocol_split(cache, protocol: str, holdout_seed: int = 0, num_train_subjects: int | None = None) -> ProtocolSplit:
    """The train / test GEIs of ``protocol`` on a GEI cache: the one split code of the learned and classical methods.

    Args:
        cache: a :class:`~mocapkit.datasets.casia_b.cache.GEICache` (or anything with per-GEI ``subjects``,
            ``conditions``, ``sequences``, ``views`` arrays; ``root`` names it in errors).
        protocol: ``"closed_set"``: :func:`closed_set_split` drawn with ``holdout_seed``, every subject on both
            sides; ``"cross_subject"``: every GEI of the :func:`cross_subject_subjects` training subjects trains,
            every GEI of the others tests.
        holdout_seed: ``closed_set`` only: the draw of the held-out sequences.
        num_train_subjects: ``cross_subject`` only (None: 74 of 124, or the same share of a smaller cache).

    Returns:
        :class:`ProtocolSplit`. The training side still holds what a learned method keeps for validation
        (:func:`sequence_validation_split` takes it from ``train_idx``); a classical method fits on all of it.

    Raises:
        ValueError: an unknown protocol, too few subjects for it, or ``num_train_subjects`` with ``closed_set``.
    """
    root = getattr(cache, "root", "the GEI cache")
    if protocol not in PROTOCOLS:
        raise ValueError(f"data.protocol={protocol!r} is unknown; choose one of {', '.join(PROTOCOLS)}")
    if protocol != "cross_subject" and num_train_subjects is not None:
        raise ValueError(
            f"data.num_train_subjects={num_train_subjects} is only used by protocol=cross_subject, not {protocol!r}"
        )
    subjects = np.asarray(cache.subjects, dtype=np.int64)
    ids = np.unique(subjects)
    if protocol == "closed_set":
        if len(ids) < 2:
            raise ValueError(f"{root}: protocol=closed_set needs at least 2 subjects, the cache has {len(ids)}")
        train, test = closed_set_split(subjects, cache.conditions, cache.sequences, cache.views, seed=holdout_seed)
        return ProtocolSplit(train, test, ids, ids)
    if len(ids) < 3:
        raise ValueError(
            f"{root}: protocol=cross_subject needs at least 3 subjects (1 to train, 2 to test), "
            f"the cache has {len(ids)}"
        )
    train_subjects, test_subjects = cross_subject_subjects(subjects, num_train_subjects)
    return ProtocolSplit(
        np.flatnonzero(np.isin(subjects, train_subjects)),
        np.flatnonzero(np.isin(subjects, test_subjects)),
        train_subjects,
        test_subjects,
    )


def gallery_probe_masks(conditions: np.ndarray, sequences: np.ndarray) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Boolean masks of the gallery (``nm-01..04``) and of each probe set (``nm``, ``bg``, ``cl``).

    Args:
        conditions: per-GEI condition labels (0 nm, 1 bg, 2 cl); sequences: 1-based repetitions.
    """
    conditions, sequences = np.asarray(conditions), np.asarray(sequences)

    def mask(spec: dict[str, tuple[int, ...]], name: str) -> np.ndarray:
        return (conditions == CONDITIONS.index(name)) & np.isin(sequences, spec[name])

    return mask(GALLERY, "nm"), {name: mask(PROBES, name) for name in PROBES}


def sequence_validation_split(
    train_idx: np.ndarray, sequence_keys: np.ndarray, val_fraction: float, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Hold out ``round(val_fraction · n)`` of the ``n`` training sequences (all their GEIs) for validation.

    Args:
        train_idx: training GEI indices.
        sequence_keys: per GEI of the whole cache, an integer row identifying its sequence ``[N, k]``.
        val_fraction: in [0, 1); at least one sequence is held out when it is > 0 and there are ≥ 2 sequences.
        seed: the draw.
    Returns:
        ``(train_idx, val_idx)``, sorted.
    """
    if not 0.0 <= val_fraction < 1.0:
        raise ValueError(f"data.val_fraction={val_fraction}: must be in [0, 1)")
    train_idx = np.sort(np.asarray(train_idx, dtype=np.int64))
    if val_fraction == 0 or len(train_idx) == 0:
        return train_idx, np.zeros(0, dtype=np.int64)
    unique, inverse = np.unique(sequence_keys[train_idx], axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    n_val = round(val_fraction * len(unique))
    n_val = min(max(n_val, 1), len(unique) - 1)
    held = np.random.default_rng(seed).choice(len(unique), size=n_val, replace=False) if n_val > 0 else []
    in_val = np.isin(inverse, held)
    return train_idx[~in_val], train_idx[in_val]
