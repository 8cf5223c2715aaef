"""``mocapkit train``: fit a LightningModule as a Hydra config describes it.

Everything is built from ``_target_`` entries of the composed config (``configs/train.yaml``):
the data module (``data``), the LightningModule (``module``, given the data module's
``label_spaces()``), the ``trainer``, its ``callbacks`` and ``logger``. Each run writes to
``<output_root>/<experiment_name>/<run_name>/``::

    config.yaml          the resolved configuration
    .hydra/config.yaml   the unresolved one (eval / export / resume compose it again)
    last.ckpt            the latest checkpoint (resume with ``resume=<this file>``)
    best.ckpt            the checkpoint with the best validation accuracy (val/acc); not written by a run
                         without a validation part (``data.val_fraction=0``), whose checkpoint is last.ckpt
    tensorboard/         TensorBoard logs
"""
from __future__ import annotations

import sys
import warnings
from pathlib import Path

import hydra
import lightning as L
from hydra.core.hydra_config import HydraConfig
from hydra.errors import InstantiationException
from hydra.utils import instantiate
from lightning.pytorch.callbacks import ModelCheckpoint
from omegaconf import DictConfig, open_dict

from mocapkit.train.config import (
    CONFIG_DIR,
    ConfigError,
    check_output_paths,
    check_override_names,
    check_override_types,
    compose_config,
    load_run_config,
    parse_overrides,
    prepare_run_dir,
    save_run_config,
)


def build(node: DictConfig, **kwargs):
    """``instantiate(node, **kwargs)``; an error raised by the target itself (a missing folder, an
    unknown split) is re-raised as it is, without Hydra's wrapper, so its message reaches the user."""
    try:
        return instantiate(node, **kwargs)
    except InstantiationException as exc:
        if isinstance(exc.__cause__, Exception):
            raise exc.__cause__ from None
        raise


def build_datamodule(cfg: DictConfig):
    """The data module of ``cfg.data``, seeded with ``cfg.seed``."""
    return build(cfg.data, seed=cfg.seed)


def resume_config(resume: str | Path, overrides: list[str]) -> DictConfig:
    """The config of the run that ``resume`` (a ``last.ckpt``) belongs to, with ``overrides`` applied.

    Both the run's saved config and the checkpoint are vetted (:mod:`mocapkit.train.safety`) before
    anything is built; a file that is not a checkpoint is refused naming it.
    """
    from mocapkit.train.checkpoints import load_checkpoint

    resume = Path(resume)
    if not resume.is_file():
        raise ConfigError(f"resume={resume}: no such checkpoint")
    cfg = load_run_config(resume.parent, overrides)
    load_checkpoint(resume)  # read with weights_only=True and vetted; Lightning reads it again the same way
    with open_dict(cfg):
        cfg.resume = str(resume)
        cfg.run_dir = str(resume.parent)
    return cfg


def train(cfg: DictConfig) -> Path:
    """Train as configured; return the run folder.

    Every ``_target_`` of ``cfg`` is checked against :data:`mocapkit.train.safety.RUN_POLICY` first (a run
    that ``eval`` / ``export`` / ``resume`` could not load again is refused before it starts); checkpoints
    are written atomically (:class:`~mocapkit.train.checkpoint_io.AtomicCheckpointIO`).
    """
    from mocapkit.train.checkpoint_io import AtomicCheckpointIO
    from mocapkit.train.config import RUN_CONFIG_UNRESOLVED
    from mocapkit.train.safety import check_run_config

    source = Path(cfg.resume).parent / RUN_CONFIG_UNRESOLVED if cfg.resume else "the training config"
    check_run_config(cfg, source)
    L.seed_everything(cfg.seed, workers=True)
    run_dir = Path(cfg.resume).parent if cfg.resume else prepare_run_dir(cfg)
    # saved before anything is instantiated: instantiate resolves interpolations it follows in place
    save_run_config(cfg, run_dir)
    datamodule = build_datamodule(cfg)
    counts = datamodule.sample_counts()
    validate = counts["val"] > 0
    if counts["train"] == 0 or (counts["val"] == 0 and cfg.data.get("val_fraction", 1) != 0):
        raise ConfigError(f"split {datamodule.describe()['split']!r} leaves {counts}: "
                          "training and validation both need samples (data.val_fraction=0: no validation)")
    module = build(cfg.module, **datamodule.label_spaces())
    callbacks = [build(node) for node in (cfg.get("callbacks") or {}).values() if node]
    if not validate:  # nothing to monitor: the run's checkpoint is last.ckpt
        callbacks = [c for c in callbacks if not (isinstance(c, ModelCheckpoint) and c.monitor)]
        print("[mocapkit] data.val_fraction=0: no validation part; the checkpoint is last.ckpt (no best.ckpt)")
    loggers = [build(node) for node in (cfg.get("logger") or {}).values() if node]
    plugins = [*(cfg.trainer.get("plugins") or []), AtomicCheckpointIO()]
    extra = {} if validate else {"limit_val_batches": 0, "num_sanity_val_steps": 0}
    trainer = build(cfg.trainer, callbacks=callbacks, logger=loggers or False, deterministic=cfg.deterministic,
                    default_root_dir=str(run_dir), plugins=plugins, **extra)
    # the run folder already holds config.yaml, by design
    warnings.filterwarnings("ignore", message=r"Checkpoint directory .* exists and is not empty")
    print(f"[mocapkit] run folder: {run_dir}")
    classes = f"{len(datamodule.class_names)} classes" if datamodule.class_names else "no classes"
    print(f"[mocapkit] task {cfg.task}, samples: {counts} (split {datamodule.describe()['split']}), {classes}")
    trainer.fit(module, datamodule=datamodule, ckpt_path=cfg.resume, weights_only=True)
    if trainer.is_global_zero:
        print(f"[mocapkit] wrote {run_dir / 'config.yaml'}")
        for callback in callbacks:
            if isinstance(callback, ModelCheckpoint) and callback.monitor:
                print(f"[mocapkit] wrote {callback.best_model_path} "
                      f"(best {callback.monitor} {float(callback.best_model_score or 0):.4f})")
            elif isinstance(callback, ModelCheckpoint) and (callback.last_model_path or callback.best_model_path):
                print(f"[mocapkit] wrote {callback.last_model_path or callback.best_model_path}")
        if loggers:
            print(f"[mocapkit] logs: tensorboard --logdir {run_dir}")
    return run_dir


#: ``sys.argv`` as the user typed it, restored inside the task (see :func:`main`).
_ARGV: list[str] = []
#: Errors of the jobs of one ``main`` call, raised once Hydra has returned (so the CLI can name them).
_JOB_ERRORS: list[Exception] = []
#: Errors a job reports to the user as one line (the CLI's exit code 2); anything else is a bug and propagates.
USER_ERRORS = (ConfigError, OSError, ValueError)


@hydra.main(config_path=str(CONFIG_DIR), config_name="train", version_base="1.3")
def _hydra_task(cfg: DictConfig) -> None:
    # Lightning's DDP launcher re-runs sys.argv in each extra process: give it the user's command line
    # (with the subcommand), not the overrides-only one Hydra parsed.
    sys.argv[:] = _ARGV
    with open_dict(cfg):  # a sweep job's folder is Hydra's, not the single-run default
        cfg.run_dir = HydraConfig.get().runtime.output_dir
    try:
        check_output_paths(cfg)  # a sweep job's folder (named by its overrides) stays under output_root too
        train(cfg)
    except Exception as exc:  # raised by main() once Hydra returns: the CLI reports it on one line
        _JOB_ERRORS.append(exc)
        if HydraConfig.get().mode.name == "MULTIRUN":
            print(f"[mocapkit] job {HydraConfig.get().job.override_dirname} failed: {exc}", file=sys.stderr)
            if not isinstance(exc, USER_ERRORS):  # a bug: stop the sweep
                raise


def _first_job(overrides: list[str]) -> list[str]:
    """The overrides of a sweep's first job: every swept key at its first value, Hydra's flags left out."""
    job = []
    for item, parsed in parse_overrides(overrides):
        if parsed is None:
            continue
        if not parsed.is_sweep_override():
            job.append(item)
            continue
        prefix = "++" if parsed.is_force_add() else "+" if parsed.is_add() else ""
        job.append(f"{prefix}{parsed.get_key_element()}={next(iter(parsed.sweep_string_iterator()))}")
    return job


def _reference_config(overrides: list[str]) -> DictConfig:
    """The defaults the overrides' types are checked against: the config with only its group choices
    (``experiment=...``, ``model=...``; the first value of a swept group) applied."""
    groups = []
    for item, parsed in parse_overrides(overrides, strict=False):
        if parsed is None:
            continue
        if "." in parsed.key_or_group or not (CONFIG_DIR / parsed.key_or_group).is_dir() or parsed.is_delete():
            continue
        value = next(iter(parsed.sweep_string_iterator())) if parsed.is_sweep_override() \
            else parsed.get_value_element_as_str()
        groups.append(f"{'+' if parsed.is_add() else ''}{parsed.key_or_group}={value}")
    return compose_config(groups)


def main(overrides: list[str]) -> None:
    """``mocapkit train OVERRIDES``: Hydra's command line (``-m`` sweeps, ``--cfg job``, ``--help``).

    A single run's overrides are composed once beforehand, so that an unknown key or a bad value is
    reported as a :class:`ConfigError` naming it; the first failed job's error is raised after Hydra returns.
    """
    flags = [o for o in overrides if o.startswith("-")]
    check_override_names(overrides)  # before Hydra creates any folder (every value of a sweep)
    if not flags:
        check_output_paths(compose_config(overrides))
    elif {"-m", "--multirun"} & set(flags):  # a sweep: its first job composed, so a bad key is named here
        check_output_paths(compose_config(_first_job(overrides)))
    check_override_types(overrides, _reference_config(overrides))
    _ARGV[:] = sys.argv
    _JOB_ERRORS.clear()
    sys.argv[:] = ["mocapkit train", *overrides]
    try:
        _hydra_task()
    finally:
        sys.argv[:] = _ARGV
    if _JOB_ERRORS:
        raise _JOB_ERRORS[0]
