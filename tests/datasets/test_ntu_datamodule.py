"""Augmentation invariants and the data module's splits over a prepared cache."""

import math

import numpy as np
import pytest
import torch

from mocapkit.datasets.augment import SkeletonAugment
from mocapkit.datasets.datamodule import pad_collate
from mocapkit.datasets.ntu.datamodule import NTUDataModule
from mocapkit.datasets.ntu.prepare import prepare_ntu
from mocapkit.datasets.synthetic.ntu import NTUSynthConfig, synthesize_ntu
from mocapkit.motion.frames import true_runs, uniform_frame_indices


def test_augment_keeps_absent_bodies_zero_and_is_rigid():
    torch.manual_seed(0)
    x = torch.randn(2, 40, 25, 3) + torch.tensor([0.0, 0.0, 3.0])
    x[1] = 0.0  # second body absent
    x[0, 30:] = 0.0  # padding frames
    out = SkeletonAugment(rotate_deg=45, crop=(0.5, 0.9), min_frames=8)(x)
    assert 8 <= out.shape[1] <= 36
    assert (out[1] == 0).all()
    present = out[0].abs().sum((-1, -2)) > 0
    assert present.sum() >= 1 and (out[0][~present] == 0).all()
    # rotation about the vertical axis: heights unchanged, pairwise distances unchanged
    start = next(
        s
        for s in range(41 - out.shape[1])
        if torch.allclose(out[0, :, :, 1], x[0, s : s + out.shape[1], :, 1], atol=1e-5)
    )
    a, b = x[0, start : start + out.shape[1]][present], out[0][present]
    assert torch.allclose(torch.cdist(a, a), torch.cdist(b, b), atol=1e-4)


def test_augment_tilt_and_scale_stay_within_their_bounds():
    torch.manual_seed(1)
    x = torch.randn(1, 30, 25, 3) + torch.tensor([0.5, 1.0, 3.0])
    x[0, 20:] = 0.0  # padding frames stay zeros
    present = x[0].abs().sum(-1) > 0
    centroid = x[0][present].mean(0)
    tilt = SkeletonAugment(tilt_deg=10)
    for _ in range(5):
        out = tilt(x)
        assert (out[0, 20:] == 0).all()
        a, b = x[0][present], out[0][present]
        exact = "donot_use_mm_for_euclid_dist"
        assert torch.allclose(
            torch.cdist(a, a, compute_mode=exact), torch.cdist(b, b, compute_mode=exact), atol=1e-5
        )  # a rotation
        assert torch.allclose(b.mean(0), centroid, atol=1e-5)  # about the centroid
        # the vertical axis tilts by at most 10 degrees about x and z each
        up = torch.linalg.lstsq(a - centroid, b - centroid).solution.T @ torch.tensor([0.0, 1.0, 0.0])
        assert math.degrees(math.acos(float(up[1]))) <= 10 * math.sqrt(2) + 1e-3
    moved = False
    for _ in range(5):
        out = SkeletonAugment(scale=0.1)(x)
        ratio = (out[0][present] - centroid).std(0) / (x[0][present] - centroid).std(0)
        assert ((ratio >= 0.9 - 1e-5) & (ratio <= 1.1 + 1e-5)).all()
        moved |= bool((ratio - 1).abs().max() > 1e-3)
    assert moved
    for bad in ({"scale": 1.0}, {"scale": -0.1}, {"tilt_deg": -5}):
        with pytest.raises(ValueError, match="augment"):
            SkeletonAugment(**bad)


def test_true_runs_are_slices():
    mask = np.array([1, 1, 0, 0, 1, 0, 1, 1, 1], dtype=bool)
    assert true_runs(mask) == [(0, 2), (4, 5), (6, 9)]
    assert all(mask[a:b].all() for a, b in true_runs(mask)) and sum(b - a for a, b in true_runs(mask)) == mask.sum()
    assert true_runs(np.zeros(4, bool)) == [] and true_runs(np.ones(3, bool)) == [(0, 3)] and true_runs([]) == []


def test_uniform_frame_indices_and_collate_padding():
    assert list(uniform_frame_indices(5, 10)) == [0, 1, 2, 3, 4]
    idx = uniform_frame_indices(100, 10)
    assert len(idx) == 10 and idx[0] == 0 and idx[-1] == 99
    items = [{"skeleton": torch.ones(2, t, 25, 3), "label": t, "index": t, "subject": 1} for t in (3, 7)]
    batch = pad_collate(items)
    assert batch["skeletons"].shape == (2, 2, 7, 25, 3)
    assert batch["lengths"].tolist() == [3, 7]
    assert (batch["skeletons"][0, :, 3:] == 0).all()


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    root = tmp_path_factory.mktemp("dm")
    config = NTUSynthConfig(
        num_classes=3, num_subjects=10, setups=(1,), cameras=(1, 2), replications=(1,), length_scale=0.5
    )
    synthesize_ntu(root / "synth", config, progress=False)
    prepare_ntu(root / "synth", root / "cache", progress=False)
    return root / "cache"


def test_cross_subject_split_never_validates_or_trains_on_test_subjects(cache):
    dm = NTUDataModule(str(cache), split="ntu60_xsub", val_fraction=0.2)
    subjects = dm.cache.subjects
    train, val, test = (set(subjects[i].tolist()) for i in (dm.train_idx, dm.val_idx, dm.test_idx))
    assert test == {3, 6, 7, 10}
    assert train | val == {1, 2, 4, 5, 8, 9} and not train & val
    assert dm.class_names == (cache.parent / "synth" / "classes.txt").read_text().split("\n")[:3]
    batch = next(iter(dm.train_dataloader()))
    assert batch["skeletons"].shape[1:] == (2, batch["skeletons"].shape[2], 25, 3)


def test_cross_view_and_custom_splits(cache):
    dm = NTUDataModule(str(cache), split="ntu60_xview")
    assert set(dm.cache.cameras[dm.test_idx].tolist()) == {1}
    assert set(dm.cache.cameras[np.concatenate([dm.train_idx, dm.val_idx])].tolist()) == {2}
    dm = NTUDataModule(str(cache), split="custom", train_subjects=[1, 2, 3], test_subjects=[9, 10])
    assert set(dm.cache.subjects[dm.test_idx].tolist()) == {9, 10}


def test_missing_root_is_named(tmp_path):
    with pytest.raises(ValueError, match="data.root"):
        NTUDataModule(None)
    with pytest.raises(FileNotFoundError, match="nowhere"):
        NTUDataModule(str(tmp_path / "nowhere"))


def test_view_change_on_a_batch_gives_each_sample_its_own_rigid_view():
    """``change_view`` turns every sample of a padded batch about its own centroid by its own angle: heights and
    distances are kept, padding and absent bodies stay zeros, and the samples do not share one angle."""
    torch.manual_seed(3)
    x = torch.randn(6, 2, 30, 25, 3) + torch.tensor([0.3, 1.0, 3.0])
    x[:, 1] = 0.0  # second bodies absent
    x[2, 0, 20:] = 0.0  # a shorter sample, padded
    out = SkeletonAugment(rotate_deg=90).change_view(x)
    assert out.shape == x.shape and (out[:, 1] == 0).all() and (out[2, 0, 20:] == 0).all()
    assert torch.allclose(out[..., 1], x[..., 1], atol=1e-5)  # a rotation about the vertical
    angles = []
    for b in range(6):
        present = x[b, 0].abs().sum(-1) > 0
        a, c = x[b, 0][present], out[b, 0][present]
        exact = "donot_use_mm_for_euclid_dist"
        assert torch.allclose(torch.cdist(a, a, compute_mode=exact), torch.cdist(c, c, compute_mode=exact), atol=1e-4)
        assert torch.allclose(a.mean(0), c.mean(0), atol=1e-5)  # about the sample's own centroid
        da, dc = a[1] - a.mean(0), c[1] - c.mean(0)
        angles.append(math.atan2(dc[2], dc[0]) - math.atan2(da[2], da[0]))
    assert max(angles) - min(angles) > 0.1
    assert SkeletonAugment(crop=(0.5, 0.5)).change_view(x) is x  # nothing to change: the same batch


def test_training_batches_get_their_views_in_the_trainer_hook(cache):
    """The data set only crops; the data module's batch hook turns training batches, not validation ones."""
    from types import SimpleNamespace

    dm = NTUDataModule(str(cache), split="ntu60_xsub", batch_size=4, augment={"rotate_deg": 45.0})
    dm.setup("fit")
    torch.manual_seed(0)
    batch = next(iter(dm.train_dataloader()))
    plain = {k: v.clone() for k, v in batch.items()}
    dm.trainer = SimpleNamespace(training=False)
    assert torch.equal(dm.on_after_batch_transfer(batch, 0)["skeletons"], plain["skeletons"])
    dm.trainer = SimpleNamespace(training=True)
    turned = dm.on_after_batch_transfer(batch, 0)["skeletons"]
    assert not torch.allclose(turned, plain["skeletons"], atol=1e-3)
    assert torch.allclose(turned[..., 1], plain["skeletons"][..., 1], atol=1e-5)


def test_loaders_pin_memory_only_for_a_cuda_trainer(cache):
    """Every data module's loaders come from ``data_loader``: persistent workers, and pinned batches when the
    Trainer runs on a CUDA device."""
    from types import SimpleNamespace

    dm = NTUDataModule(str(cache), split="ntu60_xsub", num_workers=0)
    dm.setup("fit")
    assert not dm.train_dataloader().pin_memory  # outside a Trainer
    for device, pinned in (("cpu", False), ("cuda", True)):
        dm.trainer = SimpleNamespace(strategy=SimpleNamespace(root_device=torch.device(device)), training=False)
        assert dm.train_dataloader().pin_memory is pinned and dm.val_dataloader().pin_memory is pinned
