"""Restoring a run from one of its checkpoints: its config (composed again with overrides) and its LightningModule."""
from __future__ import annotations

from pathlib import Path

import lightning as L
from hydra.utils import get_class
from omegaconf import DictConfig

from mocapkit.train.config import ConfigError, load_run_config


def load_module(cfg: DictConfig, ckpt_path: str | Path) -> L.LightningModule:
    """The LightningModule of ``cfg.module._target_`` restored from ``ckpt_path`` (on the CPU)."""
    return get_class(cfg.module._target_).load_from_checkpoint(ckpt_path, map_location="cpu")


def checkpoint_config(ckpt_path: str | Path, overrides: list[str] | None = None) -> DictConfig:
    """The config of the run ``ckpt_path`` belongs to, composed again with ``overrides``."""
    ckpt_path = Path(ckpt_path)
    if not ckpt_path.is_file():
        raise ConfigError(f"ckpt_path={ckpt_path}: no such checkpoint")
    return load_run_config(ckpt_path.parent, overrides)
