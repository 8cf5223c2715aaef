"""MSR Action3D: the text reader, the dataset listing, its protocols and the data module (real files)."""

import numpy as np
import pytest
import torch

from mocapkit.datasets.formats.msr_action3d import MSRFormatError, parse_msr_name, read_msr_skeleton
from mocapkit.datasets.msr_action3d.dataset import ACTION_SUBSETS, MSRAction3D
from mocapkit.datasets.msr_action3d.splits import msr_split_indices
from mocapkit.motion.layouts import MSR20
from tests.shared_data import SHARED, needs

MSR_ROOT = SHARED / "data" / "msr_action3d"
MSR_SAMPLES = SHARED / "samples" / "msr3d"


@pytest.fixture(scope="module")
def dataset():
    return MSRAction3D(MSR_ROOT)


# ---------------------------------------------------------------- reader on written files


def _write(path, rows):
    path.write_text("".join(" ".join(f"{v:.6f}" for v in row) + "\n" for row in rows))
    return path


def test_reader_shapes_units_and_missing(tmp_path):
    rng = np.random.default_rng(0)
    rows = np.concatenate([rng.normal(size=(40, 3)) + [0, 0, 2.5], rng.uniform(size=(40, 1))], axis=1)
    rows[20 + 5, :3] = 0.0  # frame 2, joint 5 untracked
    motion = read_msr_skeleton(_write(tmp_path / "a02_s03_e01_skeleton3D.txt", rows))
    assert motion.positions.shape == (2, 20, 3) and motion.fps == 15
    assert motion.joint_names == MSR20.joint_names and motion.parents == MSR20.parents
    assert motion.layout_name == "msr20" and motion.source_units == "m"
    assert motion.missing.sum() == 1 and motion.missing[1, 5] and np.isnan(motion.positions[1, 5]).all()
    np.testing.assert_allclose(motion.metadata["confidence"].ravel(), rows[:, 3], atol=1e-6)
    assert (motion.metadata["action"], motion.metadata["subject"], motion.metadata["take"]) == (2, 3, 1)
    assert motion.metadata["all_zero"] is False


def test_row_count_not_multiple_of_20_names_file_and_line(tmp_path):
    path = _write(tmp_path / "a01_s01_e01_skeleton3D.txt", np.ones((47, 4)))
    with pytest.raises(MSRFormatError, match=r"a01_s01_e01_skeleton3D\.txt, line 41: .*47 rows, not a multiple of 20"):
        read_msr_skeleton(path)


def test_non_numeric_and_short_rows_name_the_line(tmp_path):
    lines = ["0.1 0.2 2.5 1.0"] * 20
    lines[6] = "0.1 abc 2.5 1.0"
    path = tmp_path / "a01_s01_e01_skeleton3D.txt"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MSRFormatError, match=r"line 7: not a number"):
        read_msr_skeleton(path)
    lines[6] = "0.1 2.5 1.0"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(MSRFormatError, match=r"line 7: expected 4 numbers"):
        read_msr_skeleton(path)


def test_name_parsing():
    name = parse_msr_name("some/dir/a13_s09_e02_skeleton3D.txt")
    assert (name.action, name.subject, name.take, name.kind, name.stem) == (13, 9, 2, "real3d", "a13_s09_e02")
    assert parse_msr_name("a01_s10_e02_skeleton.txt").kind == "screen"
    with pytest.raises(ValueError, match="not an MSR Action3D"):
        parse_msr_name("S001C001P001R001A001.skeleton")


# ---------------------------------------------------------------- real files


@needs(MSR_SAMPLES)
def test_real_samples_and_all_zero_file():
    motion = read_msr_skeleton(MSR_SAMPLES / "a01_s01_e01_skeleton3D.txt")
    assert motion.num_frames == 54 and not motion.missing.any()
    assert 2.0 < np.nanmean(motion.positions[..., 2]) < 3.5  # depth in metres
    head, pelvis = motion.positions[:, MSR20.index("Head")], motion.positions[:, MSR20.index("HipCenter")]
    assert (head[:, 1] > pelvis[:, 1]).all()  # y is up
    zero = read_msr_skeleton(MSR_SAMPLES / "a13_s09_e02_skeleton3D.txt")
    assert zero.metadata["all_zero"] is True and zero.num_frames == 38 and zero.missing.all()
    screen = read_msr_skeleton(MSR_SAMPLES / "a01_s01_e01_skeleton.txt")
    assert screen.num_frames == 54 and screen.metadata["coordinates"] == "screen"
    assert "pixels" in screen.source_units
    assert 100 <= np.nanmin(screen.positions[..., 0]) and np.nanmax(screen.positions[..., 0]) <= 240


@needs(MSR_ROOT)
def test_all_567_files_listed_and_the_all_zero_file_excluded_with_reason(dataset, caplog):
    assert dataset.listed == 567
    assert len(dataset) == 566
    assert list(dataset.excluded) == ["a13_s09_e02_skeleton3D.txt"]
    assert "all values are zero" in dataset.excluded["a13_s09_e02_skeleton3D.txt"]
    assert "a13_s09_e02" not in dataset.names
    assert set(dataset.actions.tolist()) == set(range(1, 21))
    assert set(dataset.subjects.tolist()) == set(range(1, 11))
    assert (dataset.subjects == 4).sum() == 38 and (dataset.actions == 15).sum() == 20
    assert sum(m.num_frames for m in dataset.motions) == 23478 - 38
    with caplog.at_level("WARNING"):
        MSRAction3D(MSR_ROOT)
    assert any("a13_s09_e02" in r.getMessage() for r in caplog.records)  # the exclusion is logged


@needs(MSR_ROOT)
def test_second_joint_of_each_pair_is_the_right_side(dataset):
    """Subjects used the right arm / leg for one-limb actions (Li et al. 2010): the MSR20 right joints move."""

    def moving_right(actions, left, right):
        votes = []
        for i in np.flatnonzero(np.isin(dataset.actions, actions)):
            p = dataset.motions[i].positions
            votes.append(np.nanstd(p[:, MSR20.index(right)], 0).sum() > np.nanstd(p[:, MSR20.index(left)], 0).sum())
        return np.mean(votes)

    assert moving_right([1, 2, 3, 4, 5, 6, 7], "WristLeft", "WristRight") > 0.95  # one-arm actions
    assert moving_right([14, 15], "AnkleLeft", "AnkleRight") > 0.95  # kicks


@needs(MSR_ROOT)
def test_cross_subject_and_as_subsets(dataset):
    train, test = msr_split_indices(dataset)
    assert set(dataset.subjects[train].tolist()) == {1, 3, 5, 7, 9}
    assert set(dataset.subjects[test].tolist()) == {2, 4, 6, 8, 10}
    assert len(train) + len(test) == len(dataset)
    assert (len(train), len(test)) == (291, 275)
    for name, actions in ACTION_SUBSETS.items():
        assert len(actions) == 8 and len(set(actions)) == 8
        tr, te = msr_split_indices(dataset, subset=name)
        assert set(dataset.actions[tr].tolist()) == set(actions) == set(dataset.actions[te].tolist())
        assert set(dataset.subjects[te].tolist()) == {2, 4, 6, 8, 10}
    assert ACTION_SUBSETS["AS1"] == (2, 3, 5, 6, 10, 13, 18, 20)
    assert set(ACTION_SUBSETS["AS2"]) == {1, 4, 7, 8, 9, 11, 12, 14}
    assert ACTION_SUBSETS["AS3"] == (6, 14, 15, 16, 17, 18, 19, 20)
    tr, te = msr_split_indices(dataset, train_subjects=[1, 2], test_subjects=[3])
    assert set(dataset.subjects[tr].tolist()) == {1, 2} and set(dataset.subjects[te].tolist()) == {3}
    with pytest.raises(ValueError, match="both"):
        msr_split_indices(dataset, train_subjects=[1, 2], test_subjects=[2])
    with pytest.raises(ValueError, match="unknown MSR Action3D subset"):
        msr_split_indices(dataset, subset="AS4")


@needs(MSR_ROOT)
def test_random_half_per_class_is_seeded(dataset):
    train, test = msr_split_indices(dataset, "random_half", seed=3)
    assert len(np.intersect1d(train, test)) == 0 and len(train) + len(test) == len(dataset)
    for action in range(1, 21):
        n = (dataset.actions == action).sum()
        assert (dataset.actions[train] == action).sum() == round(n / 2)
    again, _ = msr_split_indices(dataset, "random_half", seed=3)
    other, _ = msr_split_indices(dataset, "random_half", seed=4)
    assert np.array_equal(train, again) and not np.array_equal(train, other)


@needs(MSR_ROOT)
def test_datamodule_contract():
    from mocapkit.datasets.msr_action3d.datamodule import MSRAction3DDataModule

    dm = MSRAction3DDataModule(
        MSR_ROOT, subset="AS1", batch_size=8, max_frames=32, seed=1, augment={"rotate_deg": 10.0, "crop": [0.8, 1.0]}
    )
    assert dm.num_classes == 8 and len(dm.class_names) == 8 and dm.class_names[0].startswith("a02")
    info = dm.describe()
    assert info["split"] == "AS1_cross_subject" and info["test_subjects"] == [2, 4, 6, 8, 10]
    assert len(info["val_subjects"]) == 1 and set(info["val_subjects"]) <= {1, 3, 5, 7, 9}
    assert not set(info["val_subjects"]) & set(info["train_subjects"])
    assert sum(info["sample_counts"].values()) == 119 + 106
    batch = next(iter(dm.test_dataloader()))
    sk = batch["skeletons"]
    assert sk.dtype == torch.float32 and sk.shape[1:] == (1, sk.shape[2], 20, 3) and sk.shape[2] <= 32
    assert batch["labels"].max() < 8 and set(batch["subjects"].tolist()) <= {2, 4, 6, 8, 10}
    for b, length in enumerate(batch["lengths"].tolist()):
        assert (sk[b, :, length:] == 0).all()  # zero padding
    assert not torch.isnan(sk).any()
    train = next(iter(dm.train_dataloader()))
    assert train["skeletons"].shape[0] == 8


def test_listing_excludes_defective_files_with_reasons(tmp_path):
    rng = np.random.default_rng(1)
    for name in ("a01_s01_e01", "a01_s02_e01"):
        _write(tmp_path / f"{name}_skeleton3D.txt", np.c_[rng.normal(size=(60, 3)), np.ones(60)])
    _write(tmp_path / "a02_s01_e01_skeleton3D.txt", np.zeros((40, 4)))
    _write(tmp_path / "a03_s01_e01_skeleton3D.txt", np.ones((30, 4)))
    with pytest.raises(MSRFormatError, match="a03_s01_e01_skeleton3D.txt, line 21"):
        MSRAction3D(tmp_path)
    data = MSRAction3D(tmp_path, skip_bad=True)
    assert data.listed == 4 and len(data) == 2 and data.names == ["a01_s01_e01", "a01_s02_e01"]
    assert "all values are zero" in data.excluded["a02_s01_e01_skeleton3D.txt"]
    assert "line 21" in data.excluded["a03_s01_e01_skeleton3D.txt"]
    assert data.positions(0).shape == (3, 20, 3)
    with pytest.raises(FileNotFoundError, match="not found"):
        MSRAction3D(tmp_path / "absent")
