"""``mocapkit eval``: evaluate a checkpoint on the held-out part of its split.

:func:`evaluate` reloads the run's config and hands over to its task's evaluation
(:mod:`mocapkit.train.tasks`); everything goes to ``<run>/eval/`` (or ``eval.out_dir``).
For action recognition (:func:`evaluate_action`) that is ``metrics.json`` (top-1,
top-5, mean-class accuracy, per-class and per-subject accuracy, the split and the
sample counts), ``confusion_matrix.png`` and a short ``summary.md``.
"""
from __future__ import annotations

import json
from pathlib import Path

import lightning as L
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from mocapkit.evaluation import classification_report, plot_confusion_matrix
from mocapkit.train.action_module import ActionRecognitionModule
from mocapkit.train.config import ConfigError, load_run_config
from mocapkit.train.tasks import get_task
from mocapkit.train.training import build_datamodule


def predict_logits(module: ActionRecognitionModule, loader, cfg: DictConfig) -> dict[str, np.ndarray]:
    """Run ``module`` over ``loader``; concatenated logits, labels, indices and subjects as numpy."""
    trainer = L.Trainer(accelerator=cfg.trainer.accelerator, devices=1, logger=False,
                        enable_progress_bar=cfg.trainer.enable_progress_bar, enable_checkpointing=False)
    batches = trainer.predict(module, dataloaders=loader)
    return {key: torch.cat([b[key] for b in batches]).cpu().numpy() for key in batches[0]}


def evaluate(ckpt_path: str | Path, overrides: list[str] | None = None) -> dict:
    """Evaluate ``ckpt_path`` (its run's config plus ``overrides``) as its task does; return the report."""
    ckpt_path = Path(ckpt_path)
    if not ckpt_path.is_file():
        raise ConfigError(f"ckpt_path={ckpt_path}: no such checkpoint")
    run_dir = ckpt_path.parent
    cfg = load_run_config(run_dir, overrides)
    if cfg.eval.part not in ("test", "val"):
        raise ConfigError(f"eval.part must be 'test' or 'val', got {cfg.eval.part!r}")
    task = get_task(cfg.get("task") or "action")  # runs from before tasks existed are action runs
    datamodule = build_datamodule(cfg)
    module = task.module_class().load_from_checkpoint(ckpt_path, map_location="cpu")
    out_dir = Path(cfg.eval.out_dir) if cfg.eval.out_dir else run_dir / "eval"
    out_dir.mkdir(parents=True, exist_ok=True)
    report = {"checkpoint": str(ckpt_path), **task.evaluate_fn()(module, datamodule, cfg, out_dir)}
    OmegaConf.save(cfg, out_dir / "eval_config.yaml", resolve=True)
    return report


def evaluate_action(module: ActionRecognitionModule, datamodule, cfg: DictConfig, out_dir: Path) -> dict:
    """Top-1/top-5/mean-class/per-class/per-subject accuracy on ``cfg.eval.part``; writes the report files."""
    part = cfg.eval.part
    loader = datamodule.test_dataloader() if part == "test" else datamodule.val_dataloader()
    out = predict_logits(module, loader, cfg)
    report = classification_report(out["logits"], out["labels"], groups={"subject": out["subjects"]},
                                   class_names=module.hparams.class_names or None)
    report.update({"part": part, **datamodule.describe()})
    (out_dir / "metrics.json").write_text(json.dumps(report, indent=2))
    title = f"{cfg.experiment_name}: {report['split']} {part}, top-1 {report['top1']:.1%}"
    plot_confusion_matrix(np.array(report["confusion_matrix"]), report["class_names"],
                          out_dir / "confusion_matrix.png", title=title)
    (out_dir / "summary.md").write_text(summary_table(report))
    print(summary_table(report))
    for name in ("metrics.json", "confusion_matrix.png", "summary.md"):
        print(f"[mocapkit] wrote {out_dir / name}")
    return report


def summary_table(report: dict) -> str:
    """A short markdown table of the headline numbers."""
    counts = report["sample_counts"]
    rows = [
        ("split / part", f"{report['split']} / {report['part']}"),
        ("samples (train / val / test)", f"{counts['train']} / {counts['val']} / {counts['test']}"),
        ("test subjects", " ".join(map(str, report["test_subjects"]))),
        ("top-1", f"{report['top1']:.2%}"),
        ("top-5", f"{report['top5']:.2%}"),
        ("mean-class accuracy", f"{report['mean_class_accuracy']:.2%}"),
        ("chance", f"{report['chance']:.2%}"),
    ]
    return "| metric | value |\n|---|---|\n" + "".join(f"| {k} | {v} |\n" for k, v in rows)
