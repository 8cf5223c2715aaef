"""Hydra configuration: composing ``configs/train.yaml`` and reloading a run's saved config.

``mocapkit train`` runs under ``@hydra.main`` (:func:`mocapkit.train.training.main`), so the whole
Hydra command line works: ``key=value``, ``group=option``, ``+new_key=value``, ``~key``, ``-m`` sweeps,
``--cfg job``, ``--help``. :func:`compose_config` composes the same tree from Python. The ``trainer``
node holds every argument of ``lightning.Trainer`` (:mod:`mocapkit.train.trainer_schema`). Every run
folder keeps the config it ran with:

``config.yaml``
    resolved, to read;
``.hydra/config.yaml``
    unresolved, so interpolations stay live (``trainer.max_epochs=50`` on resume also moves
    ``scheduler.T_max``). ``mocapkit eval``, ``export`` and ``train resume=`` compose it again with
    their overrides through Hydra (:func:`load_run_config`), so the grammar and the error for an
    unknown key are Hydra's own. A run saved before the trainer schema, whose ``trainer`` holds only the
    keys it set, takes the other Trainer arguments too.
"""

from __future__ import annotations

import difflib
import os
from pathlib import Path

from hydra import compose, initialize_config_dir
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import MissingConfigException
from omegaconf import DictConfig, OmegaConf, open_dict

from mocapkit.train.errors import ConfigError
from mocapkit.train.trainer_schema import (
    SCHEMA_NAME,
    SET_ELSEWHERE,
    register_trainer_schema,
    schema_registered,
    trainer_keys,
)


def _config_dir() -> Path:
    """``$MOCAPKIT_CONFIG_DIR``; else ``mocapkit/configs/``, the copy of ``configs/`` an installed wheel ships
    (setup.py); else ``configs/`` at the root of the checkout (a source tree or ``pip install -e .``)."""
    if os.environ.get("MOCAPKIT_CONFIG_DIR"):
        return Path(os.environ["MOCAPKIT_CONFIG_DIR"])
    package = Path(__file__).resolve().parents[1]
    packaged = package / "configs"
    return packaged if packaged.is_dir() else package.parent / "configs"


#: The configs folder (:func:`_config_dir`): ``$MOCAPKIT_CONFIG_DIR``, the wheel's ``mocapkit/configs/`` or the
#: checkout's ``configs/``.
CONFIG_DIR = _config_dir()

RUN_CONFIG = "config.yaml"
#: The unresolved config of a run, relative to its folder (where Hydra keeps it).
RUN_CONFIG_UNRESOLVED = Path(".hydra") / "config.yaml"


def _path_component(text) -> str:
    """``text`` as one folder name: separators become ``_`` (a sweep job's folder is named by its overrides)."""
    text = str(text).replace("/", "_").replace("\\", "_")
    return "_" if text in (".", "..") else text


# configs/train.yaml names each sweep job's folder ${mocapkit_path_component:${hydra:job.override_dirname}}
if not OmegaConf.has_resolver("mocapkit_path_component"):
    OmegaConf.register_new_resolver("mocapkit_path_component", _path_component)


def _compose(config_dir: Path, config_name: str, overrides: list[str]) -> DictConfig:
    """Hydra's compose API; Hydra's and OmegaConf's errors (they name the override) become ConfigError."""
    try:
        with initialize_config_dir(config_dir=str(config_dir.resolve()), version_base="1.3"):
            return compose(config_name=config_name, overrides=list(overrides))
    except MissingConfigException as exc:
        # configs/trainer/default.yaml extends the Trainer schema, which imports Lightning (seconds): it is
        # registered the first time a config asks for it, not for the configs that never do (refiners, ...)
        if SCHEMA_NAME in str(exc) and not schema_registered():
            register_trainer_schema()
            return _compose(config_dir, config_name, overrides)
        raise ConfigError(str(exc)) from exc
    except Exception as exc:  # Hydra raises several types; all name the offending override
        if type(exc).__module__.startswith(("hydra", "omegaconf", "yaml")):
            # "Error merging override trainer.min_epochs=abc" says why in its cause (OmegaConf's type error)
            cause = str(exc.__cause__ or "").strip()
            raise ConfigError(f"{exc}: {cause}" if cause and cause not in str(exc) else str(exc)) from exc
        raise


def compose_config(overrides: list[str] | None = None, config_name: str = "train") -> DictConfig:
    """Compose ``configs/<config_name>.yaml`` with Hydra overrides (what ``mocapkit train`` runs)."""
    if not (CONFIG_DIR / f"{config_name}.yaml").is_file():
        raise ConfigError(f"config {config_name!r} not found in {CONFIG_DIR} (set MOCAPKIT_CONFIG_DIR)")
    if config_name == "train":
        check_trainer_keys(list(overrides or []))
    return _compose(CONFIG_DIR, config_name, list(overrides or []))


def load_run_config(run_dir: str | Path, overrides: list[str] | None = None) -> DictConfig:
    """The unresolved config saved in ``run_dir``, composed again with ``overrides`` (Hydra's grammar)."""
    run_dir = Path(run_dir)
    path = run_dir / RUN_CONFIG_UNRESOLVED
    if not path.is_file():
        raise ConfigError(f"{path} not found: is {run_dir} a mocapkit run folder?")
    overrides = list(overrides or [])
    try:
        cfg = saved = _compose(path.parent, path.stem, [])
        if overrides:
            check_trainer_keys(overrides)
            check_override_types(overrides, saved)
            cfg = _compose(path.parent, path.stem, _add_missing_trainer_keys(overrides, saved))
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from exc
    from mocapkit.train.safety import check_run_config

    check_run_config(cfg, path)  # before anything in it is instantiated (mocapkit.train.safety.RUN_POLICY)
    return cfg


def check_trainer_keys(overrides: list[str]) -> None:
    """Refuse ``trainer.KEY=...`` (``+`` or not) where KEY is not an argument of ``lightning.Trainer``, naming it,
    and the arguments the run sets from other keys (:data:`~mocapkit.train.trainer_schema.SET_ELSEWHERE`),
    naming the key to use. Lightning is imported only when an override names a ``trainer.`` key."""
    for item, parsed in parse_overrides(overrides, strict=False):
        if parsed is None or parsed.package is not None or not parsed.key_or_group.startswith("trainer."):
            continue
        name = parsed.key_or_group.split(".")[1]
        if name in SET_ELSEWHERE:
            raise ConfigError(f"override {item!r}: the run sets trainer.{name} itself; use {SET_ELSEWHERE[name]}")
        known = trainer_keys()
        if name not in known:
            close = difflib.get_close_matches(name, known, n=1)
            hint = f" (did you mean trainer.{close[0]}?)" if close else ""
            raise ConfigError(
                f"override {item!r}: lightning.Trainer has no argument {name!r}{hint}; "
                "`mocapkit train --cfg job --package trainer` lists the trainer keys"
            )


def _add_missing_trainer_keys(overrides: list[str], saved: DictConfig) -> list[str]:
    """``trainer.KEY=...`` as ``+trainer.KEY=...`` where the run's saved config lacks KEY: runs saved before the
    trainer schema (:mod:`mocapkit.train.trainer_schema`) hold only the trainer keys they set, new runs all of
    them, and :func:`check_trainer_keys` has checked that KEY is a Trainer argument."""
    trainer = saved.get("trainer") or {}
    upgraded = []
    for item, parsed in parse_overrides(overrides, strict=False):
        if (
            parsed is not None
            and parsed.package is None
            and not parsed.is_add()
            and not parsed.is_delete()
            and parsed.key_or_group.startswith("trainer.")
            and parsed.key_or_group.split(".")[1] not in trainer
        ):
            item = f"+{item}"
        upgraded.append(item)
    return upgraded


def parse_overrides(overrides: list[str], strict: bool = True):
    """``(item, parsed)`` for each Hydra override of ``overrides``, parsed by Hydra's own parser.

    Hydra's flags (``-m``, ``--cfg job``, ...) are yielded with ``parsed`` None. A line Hydra cannot
    parse raises :class:`ConfigError` naming it when ``strict``; otherwise it is skipped (Hydra reports
    it itself when it composes).
    """
    parser = OverridesParser.create()
    for item in overrides:
        if item.startswith("-"):
            yield item, None
            continue
        try:
            parsed = parser.parse_override(item)
        except Exception as exc:
            if strict:
                raise ConfigError(f"override {item!r}: {exc}") from exc
            continue
        yield item, parsed


def pop_override(overrides: list[str], key: str) -> tuple[str | None, list[str]]:
    """Split ``key=value`` off ``overrides`` (Hydra syntax, parsed by Hydra's own parser).

    Returns ``(value or None, the other overrides)``; the last one wins if ``key`` is given twice.
    """
    value, rest = None, []
    for item, parsed in parse_overrides(overrides):
        if parsed is not None and parsed.key_or_group == key and parsed.package is None:
            value = None if parsed.value() is None else str(parsed.value())
        else:
            rest.append(item)
    return value, rest


#: The config keys that name one folder level of a run's path (``<output_root>/<experiment_name>/<run_name>``).
NAME_KEYS = ("experiment_name", "run_name")


def check_path_component(value, key: str) -> str:
    """``value`` as one folder name, or a ConfigError naming ``key``: no separators, not ``.``/``..``, not empty."""
    text = str(value)
    bad = (
        not text.strip()
        or text in (".", "..")
        or "/" in text
        or "\\" in text
        or "\0" in text
        or os.sep in text
        or (os.altsep and os.altsep in text)
        or Path(text).is_absolute()
    )
    if bad:
        raise ConfigError(
            f"{key}={text!r}: expected a single folder name (no '/', '..' or absolute path); "
            f"runs are written under output_root/<experiment_name>/<run_name>"
        )
    return text


def _check_creatable(folder: Path) -> None:
    """Refuse a folder that cannot be created or written: its nearest existing ancestor must be a writable folder."""
    existing = Path(os.path.abspath(folder))
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise ConfigError(f"run_dir={folder}: {existing} is a file, not a folder (check output_root)")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise ConfigError(f"run_dir={folder}: {existing} is not writable (check output_root)")


def check_output_paths(cfg: DictConfig) -> Path:
    """Refuse a run folder outside ``output_root`` or a run / experiment name that is not one folder name.

    Returns the run folder. Called before anything is created (:func:`prepare_run_dir`, and by
    :func:`mocapkit.train.training.main` for single runs and sweeps).
    """
    for key in NAME_KEYS:
        if cfg.get(key) is not None:
            check_path_component(cfg.get(key), key)
    run_dir = Path(str(cfg.run_dir))
    _check_creatable(run_dir)
    root = cfg.get("output_root")
    if root is not None:
        root_abs, run_abs = Path(os.path.abspath(str(root))), Path(os.path.abspath(run_dir))
        try:
            inside = run_abs.resolve().is_relative_to(root_abs.resolve()) and run_abs.is_relative_to(root_abs)
        except OSError:
            inside = False
        if not inside or run_abs == root_abs:
            raise ConfigError(
                f"run_dir={run_dir}: the run folder must lie inside output_root={root} "
                f"(as <output_root>/<experiment_name>/<run_name>)"
            )
    return run_dir


def check_override_names(overrides: list[str]) -> None:
    """Check ``run_name`` / ``experiment_name`` overrides (every value of a sweep) as :func:`check_path_component`."""
    for _, parsed in parse_overrides(overrides, strict=False):
        if parsed is None or parsed.key_or_group not in NAME_KEYS or parsed.package is not None:
            continue
        values = (
            list(parsed.sweep_string_iterator()) if parsed.is_sweep_override() else [parsed.get_value_element_as_str()]
        )
        for value in values:
            check_path_component(value, parsed.key_or_group)


#: Keys whose default's type is not the only one they take: Lightning's ``devices=auto`` (or 2, or [0, 1]) and
#: ``fast_dev_run=5`` (batches; the default is false). Lightning checks them when the Trainer is built.
WORDS_ALSO = ("trainer.devices", "trainer.fast_dev_run")


def _type_error(key: str, value, reference) -> str | None:
    """Why ``value`` does not fit a key whose default is ``reference`` (None when it fits or cannot be told)."""
    if reference is None or value is None or key in WORDS_ALSO:
        return None
    if isinstance(reference, bool):
        return None if isinstance(value, bool) else "expected true or false"
    if isinstance(reference, int) and isinstance(value, str):
        return "expected an integer"
    if isinstance(reference, float) and isinstance(value, str):
        return "expected a number"
    return None


def check_override_types(overrides: list[str], reference: DictConfig, source: str = "override") -> None:
    """Refuse an override whose value has the wrong type for its key, naming both (``trainer.max_epochs=abc``:
    expected an integer). ``reference`` holds the defaults (the config without those overrides); every value
    of a sweep is checked. Keys that are new, null by default, or not numbers / booleans are not checked."""
    for _, parsed in parse_overrides(overrides, strict=False):
        if parsed is None:
            continue
        if (
            parsed.is_delete()
            or parsed.is_add()
            or parsed.package is not None
            or "." not in parsed.key_or_group
            and (CONFIG_DIR / parsed.key_or_group).is_dir()
        ):
            continue
        key = parsed.key_or_group
        try:
            ref = OmegaConf.select(reference, key, default=None, throw_on_missing=False)
        except Exception:  # an interpolation that cannot be resolved here
            continue
        if ref is not None and not isinstance(ref, (bool, int, float)):
            continue
        try:
            values = list(parsed.sweep_iterator()) if parsed.is_sweep_override() else [parsed.value()]
        except Exception:
            continue
        for value in values:
            problem = _type_error(key, value, ref)
            if problem:
                raise ConfigError(f"{source} {key}={value!r}: {problem} (the default is {ref!r})")


def prepare_run_dir(cfg: DictConfig) -> Path:
    """Pin ``cfg.run_dir`` (and ``run_name``) and create the folder; refuses a folder that holds a run, and a
    run folder outside ``output_root`` (:func:`check_output_paths`) before creating anything."""
    run_dir = check_output_paths(cfg)
    if (run_dir / "last.ckpt").exists():
        raise ConfigError(
            f"{run_dir} already holds a run; continue it with resume={run_dir / 'last.ckpt'} or choose another run_name"
        )
    with open_dict(cfg):
        cfg.run_name = run_dir.name
        cfg.run_dir = str(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    return run_dir


def save_run_config(cfg: DictConfig, run_dir: Path) -> Path:
    """Write ``config.yaml`` (resolved, to read) and ``.hydra/config.yaml`` (unresolved, to compose again)."""
    from mocapkit.io_atomic import atomic_write_text

    path = Path(run_dir) / RUN_CONFIG
    atomic_write_text(path, OmegaConf.to_yaml(cfg, resolve=True))
    (Path(run_dir) / RUN_CONFIG_UNRESOLVED).parent.mkdir(exist_ok=True)
    atomic_write_text(Path(run_dir) / RUN_CONFIG_UNRESOLVED, OmegaConf.to_yaml(cfg, resolve=False))
    return path
