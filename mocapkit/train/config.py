"""Hydra configuration: composing ``configs/train.yaml`` and reloading a run's saved config.

``mocapkit train`` composes the config tree in ``configs/`` with Hydra's
compose API and command-line overrides (``key=value``, ``group=option``,
``+new_key=value``). ``mocapkit eval`` and ``mocapkit export`` start from the
*resolved* config saved in a run folder, so they see exactly what was trained,
and apply their own overrides on top. Unknown keys fail with Hydra's or
OmegaConf's message naming the key.
"""
from __future__ import annotations

import os
from datetime import datetime
from pathlib import Path

from hydra import compose, initialize_config_dir
from omegaconf import DictConfig, OmegaConf, open_dict

#: The configs folder: ``$MOCAPKIT_CONFIG_DIR`` or ``configs/`` at the repository root.
CONFIG_DIR = Path(os.environ.get("MOCAPKIT_CONFIG_DIR", Path(__file__).resolve().parents[2] / "configs"))

RUN_CONFIG = "config.yaml"
RUN_CONFIG_UNRESOLVED = "config.unresolved.yaml"


class ConfigError(ValueError):
    """A configuration problem; the message names the key or file."""


def compose_config(overrides: list[str] | None = None, config_name: str = "train") -> DictConfig:
    """Compose ``configs/<config_name>.yaml`` with Hydra overrides."""
    if not (CONFIG_DIR / f"{config_name}.yaml").is_file():
        raise ConfigError(f"config {config_name!r} not found in {CONFIG_DIR} (set MOCAPKIT_CONFIG_DIR)")
    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
            return compose(config_name=config_name, overrides=list(overrides or []))
    except Exception as exc:  # Hydra raises several types; all name the offending override
        if type(exc).__module__.startswith(("hydra", "omegaconf")):
            raise ConfigError(str(exc)) from exc
        raise


def apply_overrides(cfg: DictConfig, overrides: list[str]) -> DictConfig:
    """Apply ``key=value`` overrides to an existing config; unknown keys are errors naming the key.

    ``+key=value`` adds a new key (as in Hydra).
    """
    cfg = cfg.copy()
    OmegaConf.set_struct(cfg, True)
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override {item!r} is not of the form key=value")
        key, value = item.split("=", 1)
        if key.startswith("+"):
            key = key[1:]
            with open_dict(cfg):
                cfg.merge_with_dotlist([f"{key}={value}"])
            continue
        if OmegaConf.select(cfg, key, default=_ABSENT) is _ABSENT:
            raise ConfigError(f"unknown config key {key!r} (use +{key}=... to add a new key)")
        cfg.merge_with_dotlist([item])
    return cfg


_ABSENT = object()


def load_run_config(run_dir: str | Path, overrides: list[str] | None = None) -> DictConfig:
    """The config saved in ``run_dir``, with ``overrides`` applied.

    It is read from the unresolved copy when there is one, so interpolations stay
    live: ``trainer.max_epochs=50`` on resume also moves ``scheduler.T_max``.
    """
    run_dir = Path(run_dir)
    path = run_dir / RUN_CONFIG_UNRESOLVED
    if not path.is_file():
        path = run_dir / RUN_CONFIG
    if not path.is_file():
        raise ConfigError(f"{run_dir / RUN_CONFIG} not found: is {run_dir} a mocapkit run folder?")
    return apply_overrides(OmegaConf.load(path), overrides or [])


def new_run_dir(cfg: DictConfig) -> Path:
    """``<output_root>/<experiment_name>/<run_name or timestamp>``; refuses to reuse a folder with a checkpoint."""
    name = cfg.run_name or datetime.now().strftime("%Y%m%d-%H%M%S")
    run_dir = Path(cfg.output_root) / cfg.experiment_name / str(name)
    if (run_dir / "last.ckpt").exists():
        raise ConfigError(f"{run_dir} already holds a run; continue it with resume={run_dir / 'last.ckpt'} "
                          "or choose another run_name")
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def save_run_config(cfg: DictConfig, run_dir: Path) -> Path:
    """Write ``config.yaml`` (resolved, to read) and ``config.unresolved.yaml`` (to reload)."""
    path = Path(run_dir) / RUN_CONFIG
    OmegaConf.save(cfg, path, resolve=True)
    OmegaConf.save(cfg, Path(run_dir) / RUN_CONFIG_UNRESOLVED, resolve=False)
    return path
