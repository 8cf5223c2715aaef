"""The gait Lightning module: joint loss, training on a separable cache, predictions, config wiring, ONNX export."""

from __future__ import annotations

import json

import lightning as L
import numpy as np
import onnx
import pytest
import torch
import torch.nn.functional as F

from mocapkit.datasets.casia_b.datamodule import GaitDataModule
from mocapkit.deploy.export import ParityError
from mocapkit.gait.export import export_gait_module, export_gait_onnx
from mocapkit.gait.module import GaitRecognitionModule
from mocapkit.train.config import compose_config
from mocapkit.train.training import build, build_datamodule
from tests.datasets.test_gait_datamodule import write_synthetic_gei_cache

MODEL = {"_target_": "mocapkit.models.gait_cnn.multitask_gait_cnn", "dropout": 0.2}
ADAMW = {"_target_": "torch.optim.AdamW", "_partial_": True, "lr": 1e-3}


@pytest.fixture(scope="module")
def cache_root(tmp_path_factory):
    return write_synthetic_gei_cache(tmp_path_factory.mktemp("gei") / "cache", num_subjects=6)


def _module(tasks=("subject", "view", "condition"), **kwargs) -> GaitRecognitionModule:
    torch.manual_seed(0)
    return GaitRecognitionModule(
        model={**MODEL, "tasks": list(tasks)},
        optimizer=ADAMW,
        num_subjects=6,
        num_views=11,
        num_conditions=3,
        input_size=(64, 44),
        **kwargs,
    )


def _batch(n=8, seed=0) -> dict:
    g = torch.Generator().manual_seed(seed)
    return {
        "geis": torch.rand(n, 1, 64, 44, generator=g),
        "subjects": torch.randint(0, 6, (n,), generator=g),
        "subject_ids": torch.randint(1, 7, (n,), generator=g),
        "views": torch.randint(0, 11, (n,), generator=g),
        "conditions": torch.randint(0, 3, (n,), generator=g),
        "sequences": torch.randint(1, 7, (n,), generator=g),
        "indices": torch.arange(n),
    }


def test_joint_loss_is_the_weighted_sum_of_per_task_cross_entropies():
    module = _module(task_weights={"subject": 1.0, "view": 0.5, "condition": 2.0}, label_smoothing=0.1).eval()
    batch = _batch()
    with torch.no_grad():
        out = module(batch["geis"])
        losses = module.task_losses(out, batch)
        joint = module.joint_loss(losses)
    expected = {
        task: F.cross_entropy(out[task], batch[key], label_smoothing=0.1)
        for task, key in (("subject", "subjects"), ("view", "views"), ("condition", "conditions"))
    }
    for task, value in expected.items():
        torch.testing.assert_close(losses[task], value)
    torch.testing.assert_close(joint, expected["subject"] + 0.5 * expected["view"] + 2.0 * expected["condition"])
    # unlabelled subjects (-1, cross-subject test) are left out of the subject loss only
    batch["subjects"][:3] = -1
    with torch.no_grad():
        losses = module.task_losses(out, batch)
    torch.testing.assert_close(
        losses["subject"], F.cross_entropy(out["subject"][3:], batch["subjects"][3:], label_smoothing=0.1)
    )
    torch.testing.assert_close(losses["view"], expected["view"])
    batch["subjects"][:] = -1
    with torch.no_grad():
        assert set(module.task_losses(out, batch)) == {"view", "condition"}
    # the single-task module: the subject loss alone; weights of absent tasks are ignored
    single = _module(tasks=("subject",), task_weights={"subject": 2.0, "view": 1.0}).eval()
    b = _batch(seed=1)
    with torch.no_grad():
        out = single(b["geis"])
        torch.testing.assert_close(
            single.joint_loss(single.task_losses(out, b)), 2.0 * F.cross_entropy(out["subject"], b["subjects"])
        )
    with pytest.raises(ValueError, match="task_weights: unknown tasks \\['gender'\\]"):
        _module(task_weights={"gender": 1.0})


def test_metric_term_is_the_contrastive_loss_of_the_labelled_embeddings():
    from mocapkit.train.losses import contrastive_loss

    module = _module(tasks=("subject",), metric_weight=0.5, temperature=0.2).eval()
    batch = _batch(8)
    batch["subjects"][:2] = -1  # unseen subjects: outside both terms
    with torch.no_grad():
        out = module(batch["geis"])
        losses = module.task_losses(out, batch)
    expected = contrastive_loss(F.normalize(out["embedding"][2:], dim=1), batch["subjects"][2:], 0.2)
    torch.testing.assert_close(losses["metric"], expected)
    torch.testing.assert_close(module.joint_loss(losses), losses["subject"] + 0.5 * expected)
    assert "metric" not in _module(tasks=("subject",)).task_losses(out, batch)  # off by default
    with pytest.raises(ValueError, match="metric_weight"):
        _module(metric_weight=-1.0)


def test_subject_batches_hold_k_geis_of_p_subjects():
    from mocapkit.datasets.casia_b.datamodule import SubjectBatchSampler

    labels = np.repeat(np.arange(10), [12, 12, 12, 12, 12, 12, 12, 12, 12, 3])  # subject 9 has 3 GEIs
    torch.manual_seed(0)
    sampler = SubjectBatchSampler(labels, batch_size=16, subjects_per_batch=4)
    batches = list(sampler)
    assert len(batches) == len(sampler) == len(labels) // 16
    for batch in batches:
        subjects, counts = np.unique(labels[batch], return_counts=True)
        assert len(subjects) == 4 and (counts == 4).all()
        for s in subjects:  # without replacement where the subject has enough
            picked = [i for i in batch if labels[i] == s]
            assert s == 9 or len(set(picked)) == 4
    for bad in ({"subjects_per_batch": 5}, {"subjects_per_batch": 16}, {"subjects_per_batch": 1}):
        with pytest.raises(ValueError, match="subjects_per_batch"):
            SubjectBatchSampler(labels, batch_size=16, **bad)
    with pytest.raises(ValueError, match="only 10 subjects"):
        SubjectBatchSampler(labels, batch_size=24, subjects_per_batch=12)


def test_the_metric_experiment_trains_on_subject_batches(cache_root):
    cfg = compose_config(
        ["experiment=casiab_single_metric", f"data.root={cache_root}", "data.batch_size=8", "data.subjects_per_batch=4"]
    )
    dm = build_datamodule(cfg)
    module = build(cfg.module, **dm.label_spaces())
    assert module.hparams.metric_weight == 1.0 and cfg.eval.metric == "euc" and module.tasks == ("subject",)
    batch = next(iter(dm.train_dataloader()))
    assert batch["geis"].shape[0] == 8 and len(torch.unique(batch["subjects"])) == 4
    loss = module.training_step(batch, 0)
    assert torch.isfinite(loss) and loss.requires_grad


def test_predict_step_returns_the_evaluation_keys():
    module = _module().eval()
    batch = _batch(5)
    with torch.no_grad():
        pred = module.predict_step(batch, 0)
    assert set(pred) == {
        "embedding",
        "subject_logits",
        "view_logits",
        "condition_logits",
        "subjects",
        "subject_ids",
        "views",
        "conditions",
        "sequences",
        "indices",
    }
    assert pred["embedding"].shape == (5, 512) and pred["subject_logits"].shape == (5, 6)
    assert pred["view_logits"].shape == (5, 11) and pred["condition_logits"].shape == (5, 3)
    for key in ("subjects", "subject_ids", "views", "conditions", "sequences", "indices"):
        assert torch.equal(pred[key], batch[key])
    with torch.no_grad():
        single = _module(tasks=("subject",)).eval().predict_step(batch, 0)
    assert {k for k in single if k.endswith("_logits")} == {"subject_logits"}


def test_the_experiments_build_the_module_from_its_target(cache_root):
    cfg = compose_config(["experiment=casiab_multitask", f"data.root={cache_root}"])
    assert cfg.task == "gait" and cfg.data.protocol == "closed_set"
    dm = build_datamodule(cfg)
    module = build(cfg.module, **dm.label_spaces())
    assert type(module) is GaitRecognitionModule
    assert module.tasks == ("subject", "view", "condition") and module.model.input_size == (64, 44)
    assert module.hparams.subject_names == ["001", "002", "003", "004", "005", "006"]
    assert module.task_weights == {"subject": 1.0, "view": 1.0, "condition": 1.0}
    opt = module.configure_optimizers()
    assert isinstance(opt["optimizer"], torch.optim.AdamW) and opt["optimizer"].defaults["lr"] == 1e-3
    cfg = compose_config(["experiment=casiab_single_subject", f"data.root={cache_root}", "data.protocol=cross_subject"])
    dm = build_datamodule(cfg)
    single = build(cfg.module, **dm.label_spaces())
    assert single.tasks == ("subject",) and single.model.num_classes == {"subject": 4}


@pytest.mark.slow
@pytest.mark.filterwarnings("ignore:.*does not have many workers.*")
def test_training_on_a_separable_cache_beats_chance(cache_root, tmp_path):
    L.seed_everything(0)
    dm = GaitDataModule(cache_root, batch_size=16, augment={"shift": 1}, val_fraction=0.1, seed=0)
    module = _module()
    trainer = L.Trainer(
        max_epochs=5,
        accelerator="cpu",
        logger=False,
        enable_checkpointing=False,
        enable_progress_bar=False,
        enable_model_summary=False,
    )
    trainer.fit(module, datamodule=dm)
    metrics = {k: float(v) for k, v in trainer.callback_metrics.items()}
    assert metrics["val/acc"] > 0.5  # chance: 1/6
    assert metrics["val/view_acc"] > 0.3  # chance: 1/11
    assert {
        "val/loss",
        "val/subject_loss",
        "val/view_loss",
        "val/condition_loss",
        "val/condition_acc",
        "train/loss_epoch",
        "train/acc",
    } <= set(metrics)
    # the checkpoint rebuilds the same network from its hyper-parameters
    trainer.save_checkpoint(tmp_path / "gait.ckpt")
    loaded = GaitRecognitionModule.load_from_checkpoint(tmp_path / "gait.ckpt", map_location="cpu").eval()
    batch = next(iter(dm.test_dataloader()))
    with torch.no_grad():
        torch.testing.assert_close(loaded(batch["geis"])["subject"], module.eval()(batch["geis"])["subject"])
        test_acc = (loaded(batch["geis"])["subject"].argmax(1) == batch["subjects"]).float().mean()
    assert test_acc > 0.5


def test_onnx_export_matches_pytorch_for_all_outputs(tmp_path):
    module = _module()
    cfg = {"opset": 18, "trace_batch": 2, "check_batch": 3, "atol": 1e-4, "rtol": 1e-3, "trace_frames": 64}
    module.hparams.subject_names = [f"{s:03d}" for s in range(1, 7)]
    report = export_gait_module(module, tmp_path / "gait.onnx", cfg)
    assert report["outputs"] == ["subject_logits", "view_logits", "condition_logits", "embedding"]
    assert report["traced_shape"] == [2, 1, 64, 44] and report["checked_shape"] == [3, 1, 64, 44]
    assert set(report["max_abs_diff"]) == set(report["outputs"]) and max(report["max_abs_diff"].values()) < 1e-4
    assert report["same_top1"] and report["checks"]["embedding"]["shape"] == [3, 512]
    proto = onnx.load(str(tmp_path / "gait.onnx"))
    meta = {p.key: p.value for p in proto.metadata_props}
    assert json.loads(meta["subject_names"]) == ["001", "002", "003", "004", "005", "006"]
    assert json.loads(meta["views"]) == list(range(0, 181, 18)) and json.loads(meta["conditions"]) == ["nm", "bg", "cl"]
    assert [i.name for i in proto.graph.input] == ["geis"]
    assert [o.name for o in proto.graph.output] == report["outputs"]
    # the single-task network exports one logits output and the embedding
    single = export_gait_onnx(_module(tasks=("subject",)).model, tmp_path / "single.onnx", trace_batch=2, check_batch=5)
    assert single["outputs"] == ["subject_logits", "embedding"] and single["checked_shape"][0] == 5
    assert np.isfinite(list(single["max_abs_diff"].values())).all()
    with pytest.raises(ParityError, match="onnxruntime differs"):
        export_gait_onnx(_module(tasks=("subject",)).model, tmp_path / "strict.onnx", atol=-1.0, rtol=0.0)
