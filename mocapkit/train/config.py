"""Hydra configuration: composing ``configs/train.yaml`` and reloading a run's saved config.

``mocapkit train`` runs under ``@hydra.main`` (:func:`mocapkit.train.training.main`), so the whole
Hydra command line works: ``key=value``, ``group=option``, ``+new_key=value``, ``~key``, ``-m`` sweeps,
``--cfg job``. :func:`compose_config` composes the same tree from Python. Every run folder keeps
the config it ran with:

``config.yaml``
    resolved, to read;
``.hydra/config.yaml``
    unresolved, so interpolations stay live (``trainer.max_epochs=50`` on resume also moves
    ``scheduler.T_max``). ``mocapkit eval``, ``export`` and ``train resume=`` compose it again with
    their overrides through Hydra (:func:`load_run_config`), so the grammar and the error for an
    unknown key are Hydra's own.
"""
from __future__ import annotations

import os
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.override_parser.overrides_parser import OverridesParser
from omegaconf import DictConfig, OmegaConf, open_dict

#: The configs folder: ``$MOCAPKIT_CONFIG_DIR`` or ``configs/`` at the repository root.
CONFIG_DIR = Path(os.environ.get("MOCAPKIT_CONFIG_DIR", Path(__file__).resolve().parents[2] / "configs"))

RUN_CONFIG = "config.yaml"
#: The unresolved config of a run, relative to its folder (where Hydra keeps it).
RUN_CONFIG_UNRESOLVED = Path(".hydra") / "config.yaml"


class ConfigError(ValueError):
    """A configuration problem; the message names the key or file."""


def _compose(config_dir: Path, config_name: str, overrides: list[str]) -> DictConfig:
    """Hydra's compose API; Hydra's and OmegaConf's errors (they name the override) become ConfigError."""
    try:
        with initialize_config_dir(config_dir=str(config_dir.resolve()), version_base="1.3"):
            return compose(config_name=config_name, overrides=list(overrides))
    except Exception as exc:  # Hydra raises several types; all name the offending override
        if type(exc).__module__.startswith(("hydra", "omegaconf")):
            raise ConfigError(str(exc)) from exc
        raise


def compose_config(overrides: list[str] | None = None, config_name: str = "train") -> DictConfig:
    """Compose ``configs/<config_name>.yaml`` with Hydra overrides (what ``mocapkit train`` runs)."""
    if not (CONFIG_DIR / f"{config_name}.yaml").is_file():
        raise ConfigError(f"config {config_name!r} not found in {CONFIG_DIR} (set MOCAPKIT_CONFIG_DIR)")
    return _compose(CONFIG_DIR, config_name, list(overrides or []))


def load_run_config(run_dir: str | Path, overrides: list[str] | None = None) -> DictConfig:
    """The unresolved config saved in ``run_dir``, composed again with ``overrides`` (Hydra's grammar)."""
    run_dir = Path(run_dir)
    path = run_dir / RUN_CONFIG_UNRESOLVED
    if not path.is_file():
        raise ConfigError(f"{path} not found: is {run_dir} a mocapkit run folder?")
    return _compose(path.parent, path.stem, list(overrides or []))


def pop_override(overrides: list[str], key: str) -> tuple[str | None, list[str]]:
    """Split ``key=value`` off ``overrides`` (Hydra syntax, parsed by Hydra's own parser).

    Returns ``(value or None, the other overrides)``; the last one wins if ``key`` is given twice.
    """
    parser = OverridesParser.create()
    value, rest = None, []
    for item in overrides:
        if item.startswith("-"):  # Hydra's flags (-m, --cfg job, ...) pass through
            rest.append(item)
            continue
        try:
            parsed = parser.parse_override(item)
        except Exception as exc:
            raise ConfigError(f"override {item!r}: {exc}") from exc
        if parsed.key_or_group == key and parsed.package is None:
            value = None if parsed.value() is None else str(parsed.value())
        else:
            rest.append(item)
    return value, rest


def prepare_run_dir(cfg: DictConfig) -> Path:
    """Pin ``cfg.run_dir`` (and ``run_name``) and create the folder; refuses a folder that holds a run."""
    run_dir = Path(cfg.run_dir)
    if (run_dir / "last.ckpt").exists():
        raise ConfigError(f"{run_dir} already holds a run; continue it with resume={run_dir / 'last.ckpt'} "
                          "or choose another run_name")
    with open_dict(cfg):
        cfg.run_name = run_dir.name
        cfg.run_dir = str(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def save_run_config(cfg: DictConfig, run_dir: Path) -> Path:
    """Write ``config.yaml`` (resolved, to read) and ``.hydra/config.yaml`` (unresolved, to compose again)."""
    path = Path(run_dir) / RUN_CONFIG
    OmegaConf.save(cfg, path, resolve=True)
    (Path(run_dir) / RUN_CONFIG_UNRESOLVED).parent.mkdir(exist_ok=True)
    OmegaConf.save(cfg, Path(run_dir) / RUN_CONFIG_UNRESOLVED, resolve=False)
    return path
