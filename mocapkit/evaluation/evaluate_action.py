"""Evaluation of an action-recognition checkpoint (``task: action``).

:func:`evaluate_action` writes ``metrics.json`` (top-1, top-5, mean-class accuracy, per-class and
per-subject accuracy, the split and the sample counts), ``confusion_matrix.png`` and a short
``summary.md``.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from omegaconf import DictConfig

from mocapkit.evaluation.classification import (
    classification_report,
    plot_confusion_matrix,
)
from mocapkit.evaluation.evaluate import predict_outputs
from mocapkit.io_atomic import atomic_write_text


def evaluate_action(module, datamodule, cfg: DictConfig, out_dir: Path) -> dict:
    """Top-1/top-5/mean-class/per-class/per-subject accuracy on ``cfg.eval.part``; writes the report files."""
    part = cfg.eval.part
    loader = datamodule.test_dataloader() if part == "test" else datamodule.val_dataloader()
    out = predict_outputs(module, loader, cfg)
    report = classification_report(out["logits"], out["labels"], groups={"subject": out["subjects"]},
                                   class_names=module.hparams.class_names or None)
    report.update({"part": part, **datamodule.describe()})
    atomic_write_text(out_dir / "metrics.json", json.dumps(report, indent=2))
    title = f"{cfg.experiment_name}: {report['split']} {part}, top-1 {report['top1']:.1%}"
    plot_confusion_matrix(np.array(report["confusion_matrix"]), report["class_names"],
                          out_dir / "confusion_matrix.png", title=title)
    atomic_write_text(out_dir / "summary.md", summary_table(report))
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
