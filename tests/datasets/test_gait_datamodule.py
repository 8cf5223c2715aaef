"""The GEI data module: closed-set and cross-subject splits, validation, label spaces, batches, errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from mocapkit.datasets.casia_b.cache import write_gei_cache
from mocapkit.datasets.casia_b.datamodule import GaitDataModule, GEIShift
from mocapkit.datasets.formats.casia_b import CONDITIONS, SEQUENCES_PER_CONDITION, VIEWS


def write_synthetic_gei_cache(
    root, num_subjects: int = 6, height: int = 64, width: int = 44, cycles: int = 1, seed: int = 0, views=VIEWS
):
    """A small CASIA-B-shaped GEI cache whose classes are easy to learn.

    Each subject is a body blob with its own torso height, width and head size plus an "arm" blob at its
    own height; the view moves the body sideways and widens it towards the lateral views, a bag (``bg``)
    adds a blob at the hip and a coat (``cl``) widens the torso. Every (subject, condition, repetition,
    view) has ``cycles`` GEIs with a little pixel noise.
    """
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32) / np.float32([[[height]], [[width]]])
    geis, index = [], {k: [] for k in ("names", "subjects", "conditions", "sequences", "views", "cycles", "frames")}
    order = rng.permutation(num_subjects)
    for s in range(1, num_subjects + 1):
        k = order[s - 1] / max(num_subjects - 1, 1)  # 0..1, distinct per subject
        torso_y, torso_h, head, arm_y = 0.45 + 0.2 * k, 0.35 - 0.1 * k, 0.06 + 0.05 * (1 - k), 0.3 + 0.4 * k
        for c, condition in enumerate(CONDITIONS):
            for n in range(1, SEQUENCES_PER_CONDITION[condition] + 1):
                for v in views:
                    lateral = np.sin(np.deg2rad(v))  # 0 at 0°/180°, 1 at 90°
                    cx = 0.5 + 0.25 * np.cos(np.deg2rad(v))
                    w = 0.12 * (0.5 + lateral) * (1.5 if condition == "cl" else 1.0)
                    for cycle in range(cycles):
                        g = np.exp(-(((yy - torso_y) / torso_h) ** 2 + ((xx - cx) / w) ** 2))
                        g += np.exp(-(((yy - 0.12) / head) ** 2 + ((xx - cx) / (1.5 * head)) ** 2))
                        g += 0.7 * np.exp(-(((yy - arm_y) / 0.04) ** 2 + ((xx - cx - 1.5 * w) / 0.06) ** 2))
                        if condition == "bg":
                            g += 0.8 * np.exp(-(((yy - 0.6) / 0.08) ** 2 + ((xx - cx + 1.5 * w) / 0.1) ** 2))
                        g += rng.normal(0, 0.02, g.shape)
                        geis.append(np.clip(g, 0, 1))
                        for key, value in (
                            ("names", f"{s:03d}/{condition}-{n:02d}/{v:03d}"),
                            ("subjects", s),
                            ("conditions", c),
                            ("sequences", n),
                            ("views", v),
                            ("cycles", cycle),
                            ("frames", 25),
                        ):
                            index[key].append(value)
    return write_gei_cache(
        root,
        np.stack(geis).astype(np.float32),
        {k: np.asarray(v) for k, v in index.items()},
        {"per": "cycle" if cycles > 1 else "sequence", "source": "synthetic test"},
    )


@pytest.fixture(scope="module")
def cache_root(tmp_path_factory):
    return write_synthetic_gei_cache(tmp_path_factory.mktemp("gei") / "cache", num_subjects=6, cycles=2)


def _sequence_keys(dm, idx):
    c = dm.cache
    return {(int(c.subjects[i]), int(c.conditions[i]), int(c.sequences[i]), int(c.views[i])) for i in idx}


def test_closed_set_holds_out_one_sequence_per_subject_view_condition(cache_root):
    dm = GaitDataModule(cache_root, protocol="closed_set", holdout_seed=3, val_fraction=0.1, seed=1)
    c = dm.cache
    assert dm.num_subjects == 6 and dm.subject_names == ["001", "002", "003", "004", "005", "006"]
    assert dm.class_names == dm.subject_names and dm.num_views == 11 and dm.num_conditions == 3
    test_keys = _sequence_keys(dm, dm.test_idx)
    per_group = {}
    for s, cond, n, v in test_keys:
        per_group.setdefault((s, v, cond), set()).add(n)
    assert len(per_group) == 6 * 11 * 3 and all(len(ns) == 1 for ns in per_group.values())
    # both cycles of a held-out sequence are tested
    assert len(dm.test_idx) == 2 * len(test_keys)
    train_keys, val_keys = _sequence_keys(dm, dm.train_idx), _sequence_keys(dm, dm.val_idx)
    assert not train_keys & test_keys and not val_keys & test_keys and not train_keys & val_keys
    assert len(dm.train_idx) + len(dm.val_idx) + len(dm.test_idx) == len(c)
    # validation: 10 % of the 6·11·(10-3) training sequences, whole sequences
    assert len(val_keys) == round(0.1 * 6 * 11 * 7) and len(dm.val_idx) == 2 * len(val_keys)
    assert dm.sample_counts() == {"train": len(dm.train_idx), "val": len(dm.val_idx), "test": len(dm.test_idx)}
    info = dm.describe()
    assert info["split"] == "casia-b closed_set (holdout seed 3)" and info["protocol"] == "closed_set"
    assert info["train_subjects"] == info["test_subjects"] == [1, 2, 3, 4, 5, 6]
    # the hold-out follows holdout_seed, the validation draw follows seed
    other = GaitDataModule(cache_root, protocol="closed_set", holdout_seed=3, val_fraction=0.1, seed=2)
    assert np.array_equal(other.test_idx, dm.test_idx) and not np.array_equal(other.val_idx, dm.val_idx)
    assert not np.array_equal(GaitDataModule(cache_root, holdout_seed=4).test_idx, dm.test_idx)


def test_cross_subject_trains_on_the_lowest_ids_and_labels_test_subjects_minus_one(cache_root):
    dm = GaitDataModule(cache_root, protocol="cross_subject", val_fraction=0.2, seed=0)
    c = dm.cache
    # round(74/124 · 6) = 4 training subjects, the lowest IDs
    assert list(dm.train_subjects) == [1, 2, 3, 4] and list(dm.test_subjects) == [5, 6]
    assert dm.num_subjects == 4 and dm.subject_names == ["001", "002", "003", "004"]
    assert set(c.subjects[dm.train_idx]) | set(c.subjects[dm.val_idx]) <= {1, 2, 3, 4}
    assert set(c.subjects[dm.test_idx]) == {5, 6}
    # the test set is every GEI of the test subjects (the evaluator picks gallery and probes)
    assert len(dm.test_idx) == 2 * 11 * 10 * 2
    assert len(dm.train_idx) + len(dm.val_idx) == 4 * 11 * 10 * 2
    assert set(dm.subject_labels[dm.test_idx].tolist()) == {-1}
    assert np.array_equal(dm.subject_labels[dm.train_idx], c.subjects[dm.train_idx] - 1)
    assert not _sequence_keys(dm, dm.train_idx) & _sequence_keys(dm, dm.val_idx)
    batch = next(iter(dm.test_dataloader()))
    assert (batch["subjects"] == -1).all() and set(batch["subject_ids"].tolist()) <= {5, 6}
    assert GaitDataModule(cache_root, protocol="cross_subject", num_train_subjects=2).num_subjects == 2
    info = dm.describe()
    assert info["split"] == "casia-b cross_subject (4 train / 2 test subjects)"
    assert info["test_subjects"] == [5, 6] and info["train_subjects"] == [1, 2, 3, 4]


def test_batches_hold_the_documented_keys_dtypes_and_values(cache_root):
    dm = GaitDataModule(cache_root, batch_size=8, eval_batch_size=16, augment=None)
    batch = next(iter(dm.val_dataloader()))
    assert set(batch) == {"geis", "subjects", "subject_ids", "views", "conditions", "sequences", "indices"}
    assert batch["geis"].shape == (16, 1, 64, 44) and batch["geis"].dtype == torch.float32
    for key in ("subjects", "subject_ids", "views", "conditions", "sequences", "indices"):
        assert batch[key].dtype == torch.int64 and batch[key].shape == (16,)
    c = dm.cache
    idx = batch["indices"].numpy()
    np.testing.assert_allclose(batch["geis"][:, 0].numpy(), c.all_geis[idx] / 255.0, atol=1e-6)
    assert np.array_equal(batch["views"].numpy(), [VIEWS.index(v) for v in c.views[idx]])
    assert np.array_equal(batch["conditions"].numpy(), c.conditions[idx])
    assert np.array_equal(batch["subject_ids"].numpy(), c.subjects[idx])
    assert np.array_equal(batch["subjects"].numpy(), c.subjects[idx] - 1)
    assert np.array_equal(batch["sequences"].numpy(), c.sequences[idx])
    assert next(iter(dm.train_dataloader()))["geis"].shape == (8, 1, 64, 44)


def test_shift_augmentation_translates_without_flipping():
    gei = torch.zeros(1, 10, 8)
    gei[0, 4, 2] = 1.0
    torch.manual_seed(0)
    shift = GEIShift(shift=2)
    seen = set()
    for _ in range(60):
        out = shift(gei)
        assert out.shape == gei.shape and out.sum() == 1.0
        y, x = (int(i) for i in torch.nonzero(out[0])[0])
        assert abs(y - 4) <= 2 and abs(x - 2) <= 2
        seen.add((y - 4, x - 2))
    assert len(seen) > 10  # many of the 25 offsets occur; a flip would have moved x to 5


def test_bad_settings_and_caches_fail_with_the_parameter_named(cache_root, tmp_path):
    with pytest.raises(ValueError, match="data.protocol='leave_one_out'"):
        GaitDataModule(cache_root, protocol="leave_one_out")
    with pytest.raises(ValueError, match="num_train_subjects"):
        GaitDataModule(cache_root, protocol="closed_set", num_train_subjects=3)
    with pytest.raises(ValueError, match="num_train_subjects"):
        GaitDataModule(cache_root, protocol="cross_subject", num_train_subjects=5)
    with pytest.raises(ValueError, match="data.augment: unknown keys \\['flip'\\]"):
        GaitDataModule(cache_root, augment={"shift": 2, "flip": True})
    with pytest.raises(ValueError, match="val_fraction"):
        GaitDataModule(cache_root, val_fraction=1.0)
    with pytest.raises(FileNotFoundError, match="not a prepared GEI cache"):
        GaitDataModule(tmp_path)
    empty = write_gei_cache(
        tmp_path / "empty",
        np.zeros((0, 8, 8), np.uint8),
        {k: np.zeros(0, np.int64) for k in ("subjects", "conditions", "sequences", "views", "cycles", "frames")}
        | {"names": np.zeros(0, str)},
        {"per": "sequence"},
    )
    with pytest.raises(ValueError, match="empty"):
        GaitDataModule(empty)
    two = write_synthetic_gei_cache(tmp_path / "two", num_subjects=2, height=24, width=16, views=(90,))
    with pytest.raises(ValueError, match="at least 3 subjects"):
        GaitDataModule(two, protocol="cross_subject")
    one = write_synthetic_gei_cache(tmp_path / "one", num_subjects=1, height=24, width=16, views=(90,))
    with pytest.raises(ValueError, match="at least 2 subjects"):
        GaitDataModule(one)
    # a cache where every (subject, view, condition) has a single sequence: everything is tested
    c = GaitDataModule(two).cache
    keep = np.flatnonzero(c.sequences == 1)
    single = write_gei_cache(
        tmp_path / "single",
        c.all_geis[keep],
        {k: getattr(c, k)[keep] for k in ("names", "subjects", "conditions", "sequences", "views", "cycles", "frames")},
        {"per": "sequence"},
    )
    with pytest.raises(ValueError, match="no training GEIs"):
        GaitDataModule(single)
