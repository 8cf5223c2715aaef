"""HDM05 action recognition: the data module over a folder of clips (synthetic or the real cuts), one
performer held out, and the comparison's learned run and baseline scoring the same clips."""

from __future__ import annotations

import json

import numpy as np
import pytest

from mocapkit.cli import main
from mocapkit.datasets.hdm05.datamodule import HDM05ActionDataModule
from mocapkit.datasets.mocap.folders import MocapFolderError
from tests.shared_data import SHARED, needs, synthetic_hdm05_folder

CLASSES = ("walk2StepsLstart", "hopBothLegs1hops", "squat1Reps")
REAL = SHARED / "data" / "hdm05_cuts11"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return synthetic_hdm05_folder(
        tmp_path_factory, CLASSES, actors=("bd", "bk", "mm"), clips_per_actor=3, max_frames=90
    )


def test_one_performer_held_out_classes_from_file_names(folder):
    dm = HDM05ActionDataModule(str(folder), val_fraction=0.2, seed=0)
    assert dm.performers == ["bd", "bk", "mm"]
    assert dm.test_actors == ["bd"] and dm.train_actors == ["bk", "mm"]  # default: the first performer
    assert dm.class_names == sorted(CLASSES) and dm.num_classes == 3
    described = dm.describe()
    assert described["test_subjects"] == ["bd"] and set(described["val_subjects"]) <= {"bk", "mm"}
    assert not set(dm.test_idx) & (set(dm.train_idx) | set(dm.val_idx))
    assert len(dm.val_idx) > 0 and len(dm.train_idx) + len(dm.val_idx) + len(dm.test_idx) == len(dm.clips)
    names = [dm.clips[i]["name"] for i in dm.test_idx]
    assert names and all("_bd_" in n for n in names)
    batch = next(iter(dm.train_dataloader()))
    assert batch["skeletons"].shape[1:] == (1, batch["skeletons"].shape[2], 31, 3)
    assert batch["skeletons"].shape[2] <= dm.max_frames
    assert (dm.labels[batch["indices"].numpy()] == batch["labels"].numpy()).all()


def test_overrides_merged_labels_and_bad_performers(folder, tmp_path):
    dm = HDM05ActionDataModule(str(folder), test_actors=["mm"], train_actors=["bd"], labels="25", val_fraction=0)
    assert dm.class_names == ["hop", "squat", "walk"]
    assert len(dm.val_idx) == 0 and {dm.clips[i]["group"] for i in dm.train_idx} == {"bd"}
    with pytest.raises(MocapFolderError, match=r"\['tr'\] are not groups"):
        HDM05ActionDataModule(str(folder), test_actors=["tr"])
    with pytest.raises(MocapFolderError, match="no hdm05 clip found"):
        HDM05ActionDataModule(str(tmp_path))


@pytest.mark.slow
def test_compare_trains_and_scores_the_held_out_performer(folder, tmp_path):
    out = tmp_path / "cmp"
    assert (
        main(
            [
                "compare",
                "hdm05_recognition",
                f"benchmark.root={folder}",
                f"out={out}",
                "seeds=[0]",
                "protocols=[test_mm]",
                "only=[hdm05_gcn,pooled_logreg]",
                "+methods.hdm05_gcn.learned.checkpoint=last",
                "learned_overrides=['trainer.max_epochs=1','trainer.enable_progress_bar=false',"
                "'model.channels=[16,16]','model.strides=[2,1]','data.val_fraction=0']",
            ]
        )
        == 0
    )
    saved = json.loads((out / "results.json").read_text())
    cells = {c["method"]: c for c in saved["cells"]}
    run = out / "runs" / "hdm05_gcn" / "hdm05_gcn_test_mm_seed0"
    assert cells["hdm05_gcn"]["checkpoint"] == "last.ckpt"  # no validation part: no best.ckpt
    assert (run / "last.ckpt").is_file() and not (run / "best.ckpt").exists()
    assert cells["hdm05_gcn"]["test_sha1"] == cells["pooled_logreg"]["test_sha1"]
    assert cells["hdm05_gcn"]["n_test"] == 9  # 3 classes x 3 clips of mm
    assert saved["splits"]["test_mm"]["0"]["test_actors"] == ["mm"]


@needs(REAL)
def test_real_cuts_leave_one_performer_out():
    dm = HDM05ActionDataModule(str(REAL), test_actors="dg", val_fraction=0.15, seed=1)
    assert len(dm.clips) == 232 and dm.num_classes == 11 and dm.performers == ["bd", "bk", "dg", "mm"]
    assert {dm.clips[i]["group"] for i in dm.test_idx} == {"dg"}
    assert {dm.clips[i]["group"] for i in np.concatenate([dm.train_idx, dm.val_idx])} == {"bd", "bk", "mm"}
    lengths = [len(s) for s in dm.sequences]
    assert min(lengths) > 10 and dm.fps == 30.0


def test_the_hdm05_ensemble_is_the_msr_recipe_on_hdm05_data():
    """experiment=hdm05_gcn_ensemble is documented as the MSR Action3D ensemble "taken as it is": everything but the
    data source (and the layout it brings) must stay equal to msr3d_gcn_ensemble's."""
    from omegaconf import OmegaConf

    from mocapkit.train.config import compose_config

    hdm, msr = (
        OmegaConf.to_container(compose_config([f"experiment={name}"]), resolve=False)
        for name in ("hdm05_gcn_ensemble", "msr3d_gcn_ensemble")
    )
    for key in ("model", "optimizer", "scheduler", "module"):
        assert hdm[key] == msr[key], key
    assert hdm["trainer"]["max_epochs"] == msr["trainer"]["max_epochs"] == 60
    for key in ("val_fraction", "batch_size", "max_frames"):
        assert hdm["data"][key] == msr["data"][key], key
    assert {k: hdm["data"]["augment"][k] for k in ("tilt_deg", "scale", "crop")} == {
        k: msr["data"]["augment"][k] for k in ("tilt_deg", "scale", "crop")
    }
    assert "hdm05" in hdm["data"]["_target_"] and hdm["experiment_name"] == "hdm05_gcn_ensemble"
