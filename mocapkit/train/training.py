"""``mocapkit train``: fit a model with Lightning from a Hydra config.

Each run writes to ``<output_root>/<experiment_name>/<run>/``::

    config.yaml       the resolved configuration
    last.ckpt         the latest checkpoint (resume with ``resume=<this file>``)
    best.ckpt         the checkpoint with the best validation accuracy
    tensorboard/      TensorBoard logs
"""
from __future__ import annotations

import warnings
from pathlib import Path

import lightning as L
from hydra.errors import InstantiationException
from hydra.utils import instantiate
from lightning.pytorch.callbacks import LearningRateMonitor, ModelCheckpoint
from lightning.pytorch.loggers import TensorBoardLogger
from omegaconf import DictConfig

from mocapkit.train.config import ConfigError, load_run_config, new_run_dir, save_run_config
from mocapkit.train.callbacks import EpochSummary
from mocapkit.train.tasks import get_task


def build_datamodule(cfg: DictConfig):
    """The data module of ``cfg.data`` (its ``_target_``), seeded with ``cfg.seed``.

    Errors raised by the data module (a missing folder, an unknown split) are
    re-raised as they are, without Hydra's wrapper, so their message reaches the user.
    """
    try:
        return instantiate(cfg.data, seed=cfg.seed)
    except InstantiationException as exc:
        if isinstance(exc.__cause__, Exception):
            raise exc.__cause__ from None
        raise


def resume_config(resume: str | Path, overrides: list[str]) -> DictConfig:
    """The config of the run that ``resume`` (a ``last.ckpt``) belongs to, with ``overrides`` applied."""
    resume = Path(resume)
    if not resume.is_file():
        raise ConfigError(f"resume={resume}: no such checkpoint")
    overrides = [o for o in overrides if not o.startswith("resume=")]
    cfg = load_run_config(resume.parent, overrides)
    cfg.resume = str(resume)
    return cfg


def train(cfg: DictConfig) -> Path:
    """Train as configured; return the run folder."""
    L.seed_everything(cfg.seed, workers=True)
    run_dir = Path(cfg.resume).parent if cfg.resume else new_run_dir(cfg)
    datamodule = build_datamodule(cfg)
    counts = datamodule.sample_counts()
    if counts["train"] == 0 or counts["val"] == 0:
        raise ConfigError(f"split {datamodule.describe()['split']!r} leaves {counts}: "
                          "training and validation both need samples")
    module = get_task(cfg.task).module_class().from_config(cfg, datamodule)
    save_run_config(cfg, run_dir)
    checkpoint = ModelCheckpoint(dirpath=run_dir, filename="best", monitor="val/acc", mode="max",
                                 enable_version_counter=False)
    # A second, unmonitored callback rewrites last.ckpt every epoch: Lightning's save_last only
    # refreshes it in epochs where the monitored checkpoint was saved.
    last = ModelCheckpoint(dirpath=run_dir, filename="last", save_top_k=1, enable_version_counter=False)
    trainer = L.Trainer(**cfg.trainer, deterministic=cfg.deterministic, default_root_dir=run_dir,
                        logger=TensorBoardLogger(save_dir=str(run_dir), name="tensorboard", version=""),
                        callbacks=[checkpoint, last, LearningRateMonitor(logging_interval="epoch"), EpochSummary()])
    # the run folder already holds config.yaml, by design
    warnings.filterwarnings("ignore", message=r"Checkpoint directory .* exists and is not empty")
    print(f"[mocapkit] run folder: {run_dir}")
    print(f"[mocapkit] task {cfg.task}, samples: {counts} (split {datamodule.describe()['split']}), "
          f"{len(datamodule.class_names)} classes")
    trainer.fit(module, datamodule=datamodule, ckpt_path=cfg.resume)
    print(f"[mocapkit] wrote {run_dir / 'config.yaml'}")
    print(f"[mocapkit] wrote {run_dir / 'last.ckpt'}")
    print(f"[mocapkit] wrote {checkpoint.best_model_path or run_dir / 'best.ckpt'} "
          f"(best val/acc {float(checkpoint.best_model_score or 0):.4f})")
    print(f"[mocapkit] TensorBoard logs: tensorboard --logdir {run_dir / 'tensorboard'}")
    return run_dir
