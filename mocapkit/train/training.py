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

import argparse
import sys
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path

import hydra
import lightning as L
from hydra.core.hydra_config import HydraConfig
from hydra.errors import InstantiationException
from hydra.utils import instantiate
from lightning.pytorch.callbacks import LearningRateMonitor, ModelCheckpoint
from omegaconf import DictConfig, OmegaConf, open_dict

from mocapkit.train.config import (
    CONFIG_DIR,
    ConfigError,
    check_output_paths,
    check_override_names,
    check_override_types,
    compose_config,
    load_run_config,
    parse_overrides,
    pop_override,
    prepare_run_dir,
    save_run_config,
)
from mocapkit.train.trainer_schema import register_trainer_schema


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


def build_trainer(trainer: DictConfig | None = None, **arguments) -> L.Trainer:
    """The Lightning ``Trainer`` of a trainer config node (``cfg.trainer``; None: ``configs/trainer/default.yaml``),
    with ``arguments`` (Trainer arguments by name: plain values or objects such as callbacks) replacing or adding
    to the config's. ``mocapkit train`` and the learned estimators' ``fit`` (their ``trainer`` parameter) build
    their trainers here; an argument the Trainer does not take is a :class:`ConfigError` naming it."""
    import inspect

    known = set(inspect.signature(L.Trainer.__init__).parameters) - {"self"}
    unknown = sorted(str(name) for name in arguments if name not in known)
    if unknown:
        raise ConfigError(
            f"trainer: {unknown} are not arguments of lightning.Trainer (e.g. accelerator, devices, "
            f"strategy, precision, max_steps)"
        )
    if trainer is None:
        trainer = compose_config(config_name="trainer/default").trainer
    precision = arguments.get("precision", trainer.get("precision"))
    if str(precision) == "auto":
        arguments["precision"] = auto_precision(arguments.get("accelerator", trainer.get("accelerator", "auto")))
    return build(trainer, **arguments)


def cpu_has_bf16() -> bool:
    """Whether this CPU multiplies bfloat16 natively: AMX tiles (torch's own probe), or AVX-512 BF16, which torch
    does not report (``get_cpu_capability()`` says ``AVX512`` either way): ``avx512_bf16`` or ``amx_bf16`` among
    the flags of ``/proc/cpuinfo``."""
    import torch

    amx_probe = getattr(torch.cpu, "_is_amx_tile_supported", None)  # private: absent from some torch builds
    if amx_probe is not None and amx_probe():
        return True
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:  # not Linux: torch's AMX probe alone decides
        return False
    return any(flag in flags.split() for flag in ("avx512_bf16", "amx_bf16"))


def auto_precision(accelerator: str = "auto") -> str:
    """``trainer.precision=auto`` resolved: ``bf16-mixed`` where the device the run trains on has bfloat16
    arithmetic (a CUDA GPU with ``torch.cuda.is_bf16_supported()``; a CPU with AMX or AVX-512 BF16), else
    ``32-true``. ``accelerator`` is the trainer's (``auto`` picks the GPU when CUDA sees one, as Lightning does).
    The choice and its accuracy check: docs/decisions.md#bf16-mixed-precision."""
    import torch

    accelerator = str(accelerator).lower()
    gpu = accelerator in ("gpu", "cuda") or (accelerator == "auto" and torch.cuda.is_available())
    if gpu:
        return "bf16-mixed" if torch.cuda.is_available() and torch.cuda.is_bf16_supported() else "32-true"
    if accelerator in ("cpu", "auto"):
        return "bf16-mixed" if cpu_has_bf16() else "32-true"
    return "32-true"  # mps, tpu, ...: Lightning's float32 default


#: The Trainer arguments a learned estimator's ``fit`` sets over ``configs/trainer/default.yaml`` (its ``trainer``
#: parameter goes on top): ``max_steps`` counts the steps, so epochs are unbounded; nothing is written or printed.
#: Float32 unless the ``trainer`` parameter asks otherwise (``{"precision": "auto"}`` or ``"bf16-mixed"``): the
#: estimators' documented results were measured in float32.
ESTIMATOR_TRAINER = {
    "precision": "32-true",
    "max_epochs": -1,
    "logger": False,
    "enable_checkpointing": False,
    "enable_progress_bar": False,
    "enable_model_summary": False,
}


def check_trainer_parameter(trainer, owner: str) -> None:
    """A learned estimator's ``trainer`` parameter is a dict of Lightning Trainer arguments or None."""
    if trainer is not None and not isinstance(trainer, Mapping):
        raise ValueError(
            f"{owner}: trainer must be a dict of Lightning Trainer arguments or None, got {type(trainer).__name__}"
        )


def build_estimator_trainer(max_steps: int, trainer: Mapping | None = None, callbacks: Sequence = ()) -> L.Trainer:
    """The Trainer of a learned estimator's ``fit``: ``configs/trainer/default.yaml``, then :data:`ESTIMATOR_TRAINER`
    and ``max_steps``, then the estimator's ``trainer`` parameter; ``callbacks`` come before the parameter's own."""
    overrides = dict(trainer or {})
    arguments = {**ESTIMATOR_TRAINER, "max_steps": int(max_steps), **overrides}
    if callbacks:
        arguments["callbacks"] = [*callbacks, *overrides.get("callbacks", [])]
    return build_trainer(**arguments)


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
        raise ConfigError(
            f"split {datamodule.describe()['split']!r} leaves {counts}: "
            "training and validation both need samples (data.val_fraction=0: no validation)"
        )
    module = build(cfg.module, **datamodule.label_spaces())
    if cfg.get("compile"):  # in place: the state_dict keeps its names, so checkpoints load into an uncompiled network
        module.model.compile()
    callbacks = [build(node) for node in (cfg.get("callbacks") or {}).values() if node]
    if not validate:  # nothing to monitor: the run's checkpoint is last.ckpt
        callbacks = [c for c in callbacks if not (isinstance(c, ModelCheckpoint) and c.monitor)]
        print("[mocapkit] data.val_fraction=0: no validation part; the checkpoint is last.ckpt (no best.ckpt)")
    loggers = [build(node) for node in (cfg.get("logger") or {}).values() if node]
    if not loggers:  # logger=none: the learning-rate monitor has nowhere to log (Lightning would refuse the run)
        callbacks = [c for c in callbacks if not isinstance(c, LearningRateMonitor)]
    plugins = [*(cfg.trainer.get("plugins") or []), AtomicCheckpointIO()]
    extra = {} if validate else {"limit_val_batches": 0, "num_sanity_val_steps": 0}
    trainer = build_trainer(
        cfg.trainer,
        callbacks=callbacks,
        logger=loggers or False,
        deterministic=cfg.deterministic,
        default_root_dir=str(run_dir),
        plugins=plugins,
        **extra,
    )
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
                print(
                    f"[mocapkit] wrote {callback.best_model_path} "
                    f"(best {callback.monitor} {float(callback.best_model_score or 0):.4f})"
                )
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
    for _, parsed in parse_overrides(overrides, strict=False):
        if parsed is None:
            continue
        if "." in parsed.key_or_group or not (CONFIG_DIR / parsed.key_or_group).is_dir() or parsed.is_delete():
            continue
        value = (
            next(iter(parsed.sweep_string_iterator()))
            if parsed.is_sweep_override()
            else parsed.get_value_element_as_str()
        )
        groups.append(f"{'+' if parsed.is_add() else ''}{parsed.key_or_group}={value}")
    return compose_config(groups)


def hydra_arguments(argv: list[str]) -> tuple[argparse.Namespace, list[str]]:
    """``argv`` read by Hydra's own command-line parser: ``(namespace, flags)``.

    ``namespace.overrides`` holds the overrides; ``flags`` is Hydra's flags alone, each with its value
    (``--cfg job``, ``--package trainer``), in the order Hydra reads them: before the overrides. The flags may
    come anywhere on the command line and give their value as a separate word or after ``=``.
    """
    from hydra._internal.utils import get_args_parser

    parser = get_args_parser()
    parser.exit_on_error = False  # a bad flag is one line (ConfigError), not argparse's usage text
    try:
        args, unknown = parser.parse_known_intermixed_args(argv)
    except argparse.ArgumentError as exc:
        raise ConfigError(f"mocapkit train: {exc} (Hydra's flags: mocapkit train --hydra-help)") from None
    if unknown:
        raise ConfigError(
            f"mocapkit train: unrecognized arguments: {' '.join(unknown)} (Hydra's flags: mocapkit train --hydra-help)"
        )
    flags = []
    for action in parser._actions:
        value = getattr(args, action.dest, action.default)
        if action.option_strings and value != action.default:
            flags += [action.option_strings[0]] if action.nargs == 0 else [action.option_strings[0], str(value)]
    return args, flags


def _print_resumed_config(cfg: DictConfig, args: argparse.Namespace, flags: list[str]) -> None:
    """``mocapkit train resume=RUN/last.ckpt --cfg job [--resolve]``: the config the resumed run would use."""
    if args.cfg != "job" or set(flags) - {"--cfg", "job", "--resolve"}:
        raise ConfigError(
            f"resume= continues a run from its saved config: of Hydra's flags it takes --cfg job "
            f"[--resolve] (print that config) only, not {' '.join(flags)}"
        )
    print(OmegaConf.to_yaml(cfg, resolve=args.resolve))


def main(argv: list[str]) -> None:
    """``mocapkit train [FLAGS] OVERRIDES``: Hydra's command line (``-m`` sweeps, ``--cfg job``, ``--help``, ...);
    ``resume=RUN/last.ckpt [OVERRIDES]`` continues a run from its own saved config instead.

    The overrides are composed once beforehand, so that an unknown key or a bad value is reported as a
    :class:`ConfigError` naming it; the first failed job's error is raised after Hydra returns.
    """
    args, flags = hydra_arguments(argv)
    overrides = list(args.overrides)
    resume, rest = pop_override(overrides, "resume")
    if resume:  # continue a run in its own folder, from its saved config
        cfg = resume_config(resume, rest)
        if flags:
            _print_resumed_config(cfg, args, flags)
        else:
            train(cfg)
        return
    check_override_names(overrides)  # before Hydra creates any folder (every value of a sweep)
    runs = not (args.help or args.hydra_help or args.cfg or args.info or args.shell_completion)
    if not (args.config_path or args.config_name or args.config_dir or args.shell_completion):
        check_override_types(overrides, _reference_config(overrides))
        # a sweep: its first job; --cfg / --help print this config: a bad key is named here on one line
        cfg = compose_config(_first_job(overrides) if args.multirun else overrides)
        if runs:
            check_output_paths(cfg)
    register_trainer_schema()  # configs/trainer/default.yaml extends it
    _ARGV[:] = sys.argv
    _JOB_ERRORS.clear()
    sys.argv[:] = ["mocapkit train", *flags, *overrides]
    try:
        _hydra_task()
    except SystemExit as exc:  # --help and --hydra-help exit(0) once printed
        if exc.code not in (0, None):
            raise
    finally:
        sys.argv[:] = _ARGV
    if _JOB_ERRORS:
        raise _JOB_ERRORS[0]
