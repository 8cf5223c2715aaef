"""``mocapkit eval`` for gait runs (``task: gait``): closed-set accuracies or cross-view rank-1 of a checkpoint.

:func:`evaluate_gait` runs the module over its data module's test part and, by the data
module's protocol, writes to ``out_dir``:

``metrics.json``
    ``closed_set``: :func:`~mocapkit.gait.metrics.closed_set_report` (subject / view / condition
    accuracy overall, per view, per condition, per sequence by vote); ``cross_subject``:
    :func:`~mocapkit.gait.metrics.cross_view_rank1` of the shared FC-512 embedding (gallery
    nm-01..04 vs probes nm-05/06, bg, cl; identical view excluded), plus the view/condition accuracy
    on the unseen subjects when the model has those heads. Both with the split (``describe()``).
``summary.md``
    the Table 6.2-style table or the OpenGait-style NM/BG/CL × probe-view table.
``per_view.png``
    accuracy (or rank-1) per probe view.
"""

from __future__ import annotations

import json
from pathlib import Path

import lightning as L
import numpy as np
from omegaconf import DictConfig

from mocapkit.datasets.formats.casia_b import VIEWS
from mocapkit.evaluation.evaluate import predict_outputs
from mocapkit.gait.metrics import (
    closed_set_markdown,
    closed_set_report,
    cross_view_markdown,
    cross_view_rank1,
    plot_per_view,
)
from mocapkit.io_atomic import atomic_write_text


def evaluate_gait(
    module: L.LightningModule, datamodule, cfg: DictConfig, out_dir: Path, ckpt_path: str | Path | None = None
) -> dict:
    """Evaluate a gait module on ``datamodule.test_dataloader()`` under ``datamodule.protocol``.

    With ``eval.part=val`` the validation side (training subjects' held-out sequences) is scored
    instead, as closed-set classification under either protocol.

    Args:
        module: a :class:`~mocapkit.gait.module.GaitRecognitionModule` (or anything whose
            ``predict_step`` returns its keys: ``embedding``, ``<task>_logits``, ``subjects``,
            ``subject_ids``, ``views`` (label 0..10), ``conditions``, ``sequences``, ``indices``).
        datamodule: a :class:`~mocapkit.datasets.casia_b.datamodule.GaitDataModule`.
        cfg: the run config (``trainer.accelerator``, ``experiment_name``, optional ``eval.metric``
            ``euc``/``cos`` and ``eval.aggregate`` ``sequence``/``gei`` for rank-1).
        out_dir: where ``metrics.json``, ``summary.md`` and ``per_view.png`` go (created).
        ckpt_path: recorded in the report as ``checkpoint`` when given.

    Returns:
        ``{"experiment", "protocol", "tasks", ["checkpoint"], the data module's ``describe()`` ("split",
        "train_subjects", "test_subjects", "sample_counts", ...), "closed_set" | "cross_view" (+
        "view_condition_on_test_subjects")}``.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    part = str(cfg.get("eval", {}).get("part", "test") or "test")
    loader = datamodule.val_dataloader() if part == "val" else datamodule.test_dataloader()
    out = predict_outputs(module, loader, cfg)
    # the validation side holds training subjects' sequences under both protocols: closed-set classification
    protocol = "closed_set" if part == "val" else datamodule.protocol
    name = str(cfg.get("experiment_name", "gait"))
    report: dict = {
        "experiment": name,
        "protocol": datamodule.protocol,
        "part": part,
        "tasks": [k[: -len("_logits")] for k in out if k.endswith("_logits")],
        **datamodule.describe(),
    }
    if ckpt_path is not None:  # (mocapkit.evaluation.evaluate.evaluate adds it itself)
        report["checkpoint"] = str(ckpt_path)
    if protocol == "closed_set":
        closed = closed_set_report(out)
        report["closed_set"] = closed
        summary = closed_set_markdown(closed, f"{name}: closed-set accuracy (%) on {closed['num_geis']} {part} GEIs")
        series = {task: entry["per_view"] for task, entry in closed["tasks"].items()}
        plot_title = f"{name}: closed-set accuracy per probe view"
    elif protocol == "cross_subject":
        metric = str(cfg.get("eval", {}).get("metric", "euc") or "euc")
        aggregate = str(cfg.get("eval", {}).get("aggregate", "sequence") or "sequence")
        cross = cross_view_rank1(
            out["embedding"],
            out["subject_ids"],
            out["conditions"],
            out["sequences"],
            np.asarray(VIEWS)[out["views"].astype(np.int64)],
            metric=metric,
            aggregate=aggregate,
        )
        report["cross_view"] = cross
        summary = cross_view_markdown(cross, f"{name}: cross-subject rank-1 (%), identical view excluded")
        heads = {k: v for k, v in out.items() if k in ("view_logits", "condition_logits")}
        if heads:  # view and condition do not depend on who walks: their heads apply to unseen subjects
            unseen = closed_set_report(
                {**heads, **{k: out[k] for k in ("views", "conditions", "subject_ids", "sequences")}}
            )
            report["view_condition_on_test_subjects"] = unseen
            summary += "\n" + closed_set_markdown(
                unseen, f"{name}: view / condition accuracy (%) on the unseen test subjects", reference=False
            )
        series = {c.upper(): entry["per_probe_view"] for c, entry in cross["conditions"].items()}
        plot_title = f"{name}: cross-subject rank-1 per probe view"
    else:
        raise ValueError(f"data.protocol={protocol!r}: expected closed_set or cross_subject")
    atomic_write_text(out_dir / "metrics.json", json.dumps(report, indent=2))
    atomic_write_text(out_dir / "summary.md", summary)
    plot_per_view(series, out_dir / "per_view.png", plot_title)
    print(summary)
    for file in ("metrics.json", "summary.md", "per_view.png"):
        print(f"[mocapkit] wrote {out_dir / file}")
    return report
