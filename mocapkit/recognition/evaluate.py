"""Evaluation of an action-recognition checkpoint (``task: action``).

:func:`evaluate_action` writes ``metrics.json`` (top-1, top-5, mean-class accuracy, per-class and
per-subject accuracy, the split and the sample counts), ``confusion_matrix.png`` and a short
``summary.md``.

With ``eval.views`` (keyword arguments of :class:`~mocapkit.datasets.augment.TestTimeViews`, e.g.
``eval.views={crops:[1.0,0.9],rotate_deg:[0,-10,10]}``) every sample is predicted under each fixed view and its
class probabilities are averaged (test-time augmentation); the report's logits are the log of the mean
probabilities. ``eval.views=null`` (the default) predicts each sample once.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf

from mocapkit.datasets.augment import TestTimeViews
from mocapkit.evaluation.classification import (
    classification_report,
    plot_confusion_matrix,
)
from mocapkit.evaluation.evaluate import predict_outputs
from mocapkit.io_atomic import atomic_write_text
from mocapkit.train.config import ConfigError


def views_from_config(cfg: DictConfig) -> TestTimeViews | None:
    """The fixed views of ``cfg.eval.views`` (None when unset); a bad key or value names ``eval.views``."""
    spec = cfg.eval.get("views")
    if spec is None:
        return None
    spec = OmegaConf.to_container(spec, resolve=True) if OmegaConf.is_config(spec) else spec
    if not isinstance(spec, dict):
        raise ConfigError(
            f"eval.views: expected a mapping such as {{crops: [1.0, 0.9], rotate_deg: [0, -10, 10]}} "
            f"or null, got {spec!r}"
        )
    unknown = sorted(set(spec) - {"crops", "rotate_deg", "min_frames"})
    if unknown:
        raise ConfigError(f"eval.views: unknown key(s) {unknown}; it takes crops, rotate_deg, min_frames")
    try:
        return TestTimeViews(**spec)
    except (TypeError, ValueError) as exc:
        raise ConfigError(str(exc)) from exc


def mean_over_views(out: dict[str, np.ndarray], n_views: int) -> dict[str, np.ndarray]:
    """Predictions of ``n_views`` consecutive rows per sample (``ViewDataset`` order) → one row per sample.

    ``logits`` ``[N * V, C]`` become the log of the mean class probabilities ``[N, C]``; the other keys keep
    each group's first row (they are the sample's own: label, index, subject).
    """
    n = len(out["logits"]) // n_views
    if (
        len(out["logits"]) != n * n_views
        or (out["indices"].reshape(n, n_views) != out["indices"][::n_views, None]).any()
    ):
        raise RuntimeError(
            f"test-time views: the {len(out['logits'])} predictions do not come in groups of {n_views} rows per sample"
        )
    probabilities = torch.softmax(torch.from_numpy(out["logits"]).double(), dim=-1).reshape(n, n_views, -1)
    mean = {key: value[::n_views] for key, value in out.items()}
    mean["logits"] = probabilities.mean(1).log().float().numpy()
    return mean


def evaluate_action(module, datamodule, cfg: DictConfig, out_dir: Path) -> dict:
    """Top-1/top-5/mean-class/per-class/per-subject accuracy on ``cfg.eval.part``; writes the report files."""
    part = cfg.eval.part
    views = views_from_config(cfg)
    if views is None:
        out = predict_outputs(
            module, datamodule.test_dataloader() if part == "test" else datamodule.val_dataloader(), cfg
        )
    else:
        out = mean_over_views(predict_outputs(module, datamodule.views_dataloader(part, views), cfg), len(views))
    report = classification_report(
        out["logits"],
        out["labels"],
        groups={"subject": out["subjects"]},
        class_names=module.hparams.class_names or None,
    )
    report.update(
        {
            "part": part,
            "views": None
            if views is None
            else {"crops": list(views.crops), "rotate_deg": list(views.rotate_deg), "n_views": len(views)},
            **datamodule.describe(),
        }
    )
    atomic_write_text(out_dir / "metrics.json", json.dumps(report, indent=2))
    title = f"{cfg.experiment_name}: {report['split']} {part}, top-1 {report['top1']:.1%}"
    plot_confusion_matrix(
        np.array(report["confusion_matrix"]), report["class_names"], out_dir / "confusion_matrix.png", title=title
    )
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
        ("test-time views", str(report["views"]["n_views"]) if report.get("views") else "none"),
        ("top-1", f"{report['top1']:.2%}"),
        ("top-5", f"{report['top5']:.2%}"),
        ("mean-class accuracy", f"{report['mean_class_accuracy']:.2%}"),
        ("chance", f"{report['chance']:.2%}"),
    ]
    return "| metric | value |\n|---|---|\n" + "".join(f"| {k} | {v} |\n" for k, v in rows)
