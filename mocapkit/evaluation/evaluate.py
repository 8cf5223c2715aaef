"""``mocapkit eval ckpt_path=RUN/best.ckpt [overrides]``: evaluate a checkpoint on the held-out part of its split.

:func:`evaluate` composes the run's saved config again with the overrides (Hydra's grammar), builds
the data module, loads the LightningModule class named by ``module._target_`` from the checkpoint
(the run's config and the checkpoint are vetted first: :mod:`mocapkit.train.safety`),
and calls the evaluator named by ``eval.evaluator._target_`` (:func:`~mocapkit.recognition.evaluate.evaluate_action`
or :func:`~mocapkit.gait.evaluate.evaluate_gait`). Everything goes to ``<run>/eval/``
(or ``eval.out_dir``), with the config it ran with (``eval_config.yaml``).
"""

from __future__ import annotations

from pathlib import Path

import lightning as L
import numpy as np
import torch
from omegaconf import DictConfig, OmegaConf, open_dict

from mocapkit.io_atomic import atomic_write_text
from mocapkit.train.checkpoints import checkpoint_config, load_module
from mocapkit.train.config import ConfigError
from mocapkit.train.training import build, build_datamodule


def predict_outputs(module: L.LightningModule, loader, cfg: DictConfig) -> dict[str, np.ndarray]:
    """Run ``module.predict_step`` over ``loader`` on one device; every output key concatenated as numpy ``[N, ...]``."""
    trainer = L.Trainer(
        accelerator=cfg.trainer.accelerator,
        devices=1,
        logger=False,
        enable_progress_bar=bool(cfg.trainer.get("enable_progress_bar", False)),
        enable_checkpointing=False,
    )
    batches = trainer.predict(module, dataloaders=loader)
    if not batches:
        raise ValueError("the evaluation loader is empty: nothing to evaluate")
    return {key: torch.cat([b[key] for b in batches]).cpu().numpy() for key in batches[0]}


def evaluate(ckpt_path: str | Path, overrides: list[str] | None = None) -> dict:
    """Evaluate ``ckpt_path`` (its run's config plus ``overrides``) with its evaluator; return the report."""
    ckpt_path = Path(ckpt_path)
    cfg = checkpoint_config(ckpt_path, [o for o in overrides or [] if not o.startswith("ckpt_path=")])
    if cfg.eval.part not in ("test", "val"):
        raise ConfigError(f"eval.part must be 'test' or 'val', got {cfg.eval.part!r}")
    module = load_module(cfg, ckpt_path)  # vets the checkpoint before the data is read
    datamodule = build_datamodule(cfg)
    out_dir = Path(cfg.eval.out_dir) if cfg.eval.out_dir else ckpt_path.parent / "eval"
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError) as exc:
        raise ConfigError(f"eval.out_dir={out_dir}: not a folder ({exc.strerror})") from exc
    with open_dict(cfg):
        cfg.ckpt_path = str(ckpt_path)  # evaluators that hand the checkpoint on (refiners) read it here
    evaluator = build(cfg.eval.evaluator)
    report = {"checkpoint": str(ckpt_path), **evaluator(module, datamodule, cfg, out_dir)}
    atomic_write_text(out_dir / "eval_config.yaml", OmegaConf.to_yaml(cfg, resolve=True))
    return report
