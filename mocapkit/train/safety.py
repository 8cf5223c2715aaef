"""What a config or a checkpoint may instantiate: the one allow-list of Hydra ``_target_`` entries.

Checkpoints and run folders describe models by *data*. Hydra's ``instantiate`` would import and call
whatever a ``_target_`` names (``builtins.open``, ``pathlib.Path.touch``, ``shutil.copyfile``, ...),
so every config tree is walked — every nested ``_target_``, inside ``_args_`` and lists too — and
checked against a policy **before anything is instantiated**; anything else is refused with a
:class:`UnsafeConfigError` (a :class:`~mocapkit.train.config.ConfigError`: one line, exit code 2)
naming the file and the offending key.

Per-key policies (:data:`RUN_POLICY`, :data:`CHECKPOINT_POLICY`, :data:`METHOD_POLICIES`): what a config
    read from a *run folder* or a *checkpoint* (``eval``, ``export``, ``train resume=``, ``compare`` reading
    its runs), the config ``train`` is about to run, or a refiner may name, key by key. ``mocapkit.`` alone is not enough
    there: a mocapkit function that writes files (``mocapkit.datasets.formats.motion_io.write_motion``)
    must not become "the model". A rule first checks the name against its prefixes (so no module outside
    them is ever imported), then imports the named object and checks what it *is* (a LightningModule
    class, a ``torch.optim.Optimizer`` class, ...), and where it was *defined*:

    ==================  =====================================================================
    key                 allowed ``_target_``
    ==================  =====================================================================
    ``module``          a ``LightningModule`` subclass defined under ``mocapkit.train.`` or a task
                        package (``mocapkit.recognition.``, ``mocapkit.refinement.``, ...)
    ``model``,          a model builder: an ``nn.Module`` subclass or a public function defined
    ``module.model``    under ``mocapkit.models.``
    ``optimizer``,      a ``torch.optim.Optimizer`` subclass under ``torch.optim.``
    ``module.optimizer``
    ``scheduler``,      an ``LRScheduler`` subclass under ``torch.optim.lr_scheduler.``
    ``module.scheduler``
    ``data``            a ``LightningDataModule`` subclass under ``mocapkit.datasets.`` or a task
                        package whose name ends in ``DataModule``
    ``trainer``         exactly ``lightning.Trainer`` (or ``lightning.pytorch.Trainer``)
    ``callbacks.*``     a ``Callback`` subclass under ``lightning.pytorch.callbacks.`` or
                        ``mocapkit.train.callbacks.``
    ``logger.*``        a ``Logger`` subclass under ``lightning.pytorch.loggers.``
    ``eval.evaluator``  exactly ``mocapkit.recognition.evaluate.evaluate_action``,
                        ``mocapkit.gait.evaluate.evaluate_gait``,
                        ``mocapkit.refinement.evaluate.evaluate_refinement``,
                        ``mocapkit.retrieval.module.evaluate_embedding`` or
                        ``mocapkit.kinect.learned.evaluate_kinect_corrector``
    ``export.exporter`` exactly ``mocapkit.recognition.export.export_action_module``,
                        ``mocapkit.gait.export.export_gait_module``,
                        ``mocapkit.deploy.refiner_export.export_refinement_module``,
                        ``mocapkit.retrieval.export.export_embedding_module`` or
                        ``mocapkit.kinect.learned.export_kinect_corrector_module``
    checkpoint          ``hyper_parameters.model`` / ``.optimizer`` / ``.scheduler``: as above;
                        no other ``_target_`` anywhere in the checkpoint, and no Lightning
                        ``_instantiator`` / ``_class_path`` keys
    method (root of     by task (:data:`METHOD_RULES`; ``configs/<task>/method/NAME.yaml``, nested targets too):
    a registry entry)   refinement: a ``MotionRefiner`` subclass under ``mocapkit.``; retrieval: a
                        ``RetrievalMethod`` subclass; synthesis: a ``MotionSynthesizer`` subclass; kinect: a
                        scikit-learn estimator class under ``mocapkit.kinect.``; depth_tracking: a
                        scikit-learn estimator class under ``mocapkit.depth_tracking.``; recognition, gait,
                        clustering: a scikit-learn estimator class under ``sklearn.`` or ``mocapkit.``, or
                        ``sklearn.pipeline.make_pipeline``
    ==================  =====================================================================

    A ``_target_`` nested inside an allowed node (say ``model.energy._target_``) must satisfy the rule
    of its nearest listed ancestor; a ``_target_`` under no listed key (``foo._target_``, the root) is
    refused. ``_partial_`` / ``_args_`` change nothing: the target itself must be allowed. A target must
    be a plain string.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from mocapkit.train.errors import ConfigError

#: Lightning's own "instantiate this" keys in checkpoint hyper-parameters: never accepted.
LIGHTNING_INSTANTIATOR_KEYS = ("_instantiator", "_class_path")


class UnsafeConfigError(ConfigError):
    """A config or checkpoint names something it may not instantiate (the message names the file and key)."""


def _locate(target: str):
    """Import the object ``target`` names (``pkg.module.attr.attr``); only called on allowed prefixes."""
    parts = target.split(".")
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:i]))
        except ImportError:
            continue
        for attr in parts[i:]:
            obj = getattr(obj, attr)
        return obj
    raise ImportError(f"cannot import {target!r}")


def _defined_under(obj, prefixes: Sequence[str]) -> bool:
    module = getattr(obj, "__module__", None) or ""
    return any(module.startswith(p) or module + "." == p for p in prefixes)


@dataclass(frozen=True)
class Rule:
    """``prefixes`` (or ``exact`` names) the target string must match, and ``accepts(obj)`` for what it names."""

    expected: str  # for messages: what the key must name
    prefixes: tuple[str, ...] = ()
    exact: tuple[str, ...] = ()
    accepts: Callable[[object], bool] | None = None

    def allows(self, target: str) -> bool:
        if target in self.exact:
            return True
        if not any(target.startswith(p) for p in self.prefixes):
            return False
        if self.accepts is None:
            return True
        try:
            obj = _locate(target)
        except Exception:  # ImportError, AttributeError: not something we can vouch for
            return False
        return _defined_under(obj, self.prefixes) and bool(self.accepts(obj))


def _subclass_of(dotted: str, alternatives: tuple[str, ...] = ()) -> Callable[[object], bool]:
    def accepts(obj) -> bool:
        bases = []
        for name in (dotted, *alternatives):
            try:
                bases.append(_locate(name))
            except Exception:
                continue
        return inspect.isclass(obj) and any(issubclass(obj, b) for b in bases)

    return accepts


def _model_builder(obj) -> bool:
    from torch import nn

    if inspect.isclass(obj):
        return issubclass(obj, nn.Module)
    return inspect.isfunction(obj) and not obj.__name__.startswith("_")


def _datamodule(obj) -> bool:
    return _subclass_of("lightning.LightningDataModule")(obj) and obj.__name__.endswith("DataModule")


#: The task packages: each holds its LightningModule (``module.py``) and, where it has one, its data module.
TASK_PACKAGES = (
    "mocapkit.recognition.",
    "mocapkit.gait.",
    "mocapkit.clustering.",
    "mocapkit.refinement.",
    "mocapkit.retrieval.",
    "mocapkit.synthesis.",
    "mocapkit.kinect.",
    "mocapkit.depth_tracking.",
)
LIGHTNING_MODULE = Rule(
    "a LightningModule class of a mocapkit task package or mocapkit.train",
    ("mocapkit.train.", *TASK_PACKAGES),
    accepts=_subclass_of("lightning.LightningModule"),
)
MODEL = Rule(
    "a model builder under mocapkit.models (an nn.Module class or a public function)",
    ("mocapkit.models.",),
    accepts=_model_builder,
)
OPTIMIZER = Rule("a torch.optim optimizer class", ("torch.optim.",), accepts=_subclass_of("torch.optim.Optimizer"))
SCHEDULER = Rule(
    "a torch.optim.lr_scheduler class",
    ("torch.optim.lr_scheduler.",),
    accepts=_subclass_of(
        "torch.optim.lr_scheduler.LRScheduler",
        ("torch.optim.lr_scheduler._LRScheduler", "torch.optim.lr_scheduler.ReduceLROnPlateau"),
    ),
)
DATAMODULE = Rule(
    "a LightningDataModule class named *DataModule under mocapkit.datasets or a task package",
    ("mocapkit.datasets.", *TASK_PACKAGES),
    accepts=_datamodule,
)
TRAINER = Rule("lightning.Trainer", exact=("lightning.Trainer", "lightning.pytorch.Trainer"))
CALLBACK = Rule(
    "a Lightning callback class (lightning.pytorch.callbacks or mocapkit.train.callbacks)",
    ("lightning.pytorch.callbacks.", "mocapkit.train.callbacks."),
    accepts=_subclass_of("lightning.Callback"),
)
LOGGER = Rule(
    "a Lightning logger class (lightning.pytorch.loggers)",
    ("lightning.pytorch.loggers.",),
    accepts=_subclass_of("lightning.pytorch.loggers.Logger"),
)
EVALUATOR = Rule(
    "mocapkit's evaluator of the task",
    exact=(
        "mocapkit.recognition.evaluate.evaluate_action",
        "mocapkit.gait.evaluate.evaluate_gait",
        "mocapkit.refinement.evaluate.evaluate_refinement",
        "mocapkit.retrieval.module.evaluate_embedding",
        "mocapkit.kinect.learned.evaluate_kinect_corrector",
    ),
)
EXPORTER = Rule(
    "mocapkit's ONNX exporter of the task",
    exact=(
        "mocapkit.recognition.export.export_action_module",
        "mocapkit.gait.export.export_gait_module",
        "mocapkit.deploy.refiner_export.export_refinement_module",
        "mocapkit.retrieval.export.export_embedding_module",
        "mocapkit.kinect.learned.export_kinect_corrector_module",
    ),
)
REFINER = Rule(
    "a mocapkit MotionRefiner class", ("mocapkit.",), accepts=_subclass_of("mocapkit.refinement.base.MotionRefiner")
)

#: A run folder's config (``.hydra/config.yaml``) and the config ``train`` runs: key → rule.
RUN_POLICY: dict[str, Rule] = {
    "module": LIGHTNING_MODULE,
    "module.model": MODEL,
    "model": MODEL,
    "module.optimizer": OPTIMIZER,
    "optimizer": OPTIMIZER,
    "module.scheduler": SCHEDULER,
    "scheduler": SCHEDULER,
    "data": DATAMODULE,
    "trainer": TRAINER,
    "callbacks.*": CALLBACK,
    "logger.*": LOGGER,
    "eval.evaluator": EVALUATOR,
    "export.exporter": EXPORTER,
}
#: A checkpoint's ``hyper_parameters`` (what the LightningModule's ``__init__`` instantiates): key → rule.
CHECKPOINT_POLICY: dict[str, Rule] = {"model": MODEL, "optimizer": OPTIMIZER, "scheduler": SCHEDULER}
RETRIEVAL = Rule(
    "a mocapkit RetrievalMethod class", ("mocapkit.",), accepts=_subclass_of("mocapkit.retrieval.base.RetrievalMethod")
)
SYNTHESIZER = Rule(
    "a mocapkit MotionSynthesizer class",
    ("mocapkit.",),
    accepts=_subclass_of("mocapkit.synthesis.base.MotionSynthesizer"),
)
KINECT = Rule(
    "a scikit-learn estimator class of mocapkit.kinect",
    ("mocapkit.kinect.",),
    accepts=_subclass_of("sklearn.base.BaseEstimator"),
)
DEPTH_TRACKING = Rule(
    "a scikit-learn estimator class of mocapkit.depth_tracking",
    ("mocapkit.depth_tracking.",),
    accepts=_subclass_of("sklearn.base.BaseEstimator"),
)
ESTIMATOR = Rule(
    "a scikit-learn estimator class (sklearn or mocapkit) or sklearn.pipeline.make_pipeline",
    ("sklearn.", "mocapkit."),
    exact=("sklearn.pipeline.make_pipeline",),
    accepts=_subclass_of("sklearn.base.BaseEstimator"),
)
#: What a method of the registry (``configs/<task>/method/NAME.yaml``, :mod:`mocapkit.train.registry`) may name,
#: by task: the rule of its root ``_target_`` and of every nested one.
METHOD_RULES: dict[str, Rule] = {
    "refinement": REFINER,
    "retrieval": RETRIEVAL,
    "synthesis": SYNTHESIZER,
    "kinect": KINECT,
    "depth_tracking": DEPTH_TRACKING,
    "recognition": ESTIMATOR,
    "gait": ESTIMATOR,
    "clustering": ESTIMATOR,
}
#: :data:`METHOD_RULES` as per-key policies for :func:`check_targets`.
METHOD_POLICIES: dict[str, dict[str, Rule]] = {task: {"": rule} for task, rule in METHOD_RULES.items()}


def _rule_for(path: tuple[str, ...], policy: Mapping[str, Rule]) -> tuple[str, Rule] | None:
    """The policy entry of the nearest ancestor-or-self of ``path`` (``*`` matches one key); None if none."""
    best = None
    for pattern, rule in policy.items():
        parts = tuple(pattern.split(".")) if pattern else ()
        if len(parts) > len(path):
            continue
        if all(p == "*" or p == k for p, k in zip(parts, path)):
            if best is None or len(parts) > len(best[0]):
                best = (parts, rule)
    return None if best is None else (".".join(best[0]), best[1])


def _walk(node, path: tuple[str, ...]):
    """Yield ``(path, node)`` for every mapping in ``node`` (lists and ``_args_`` included)."""
    if isinstance(node, Mapping):
        yield path, node
        for key, value in node.items():
            yield from _walk(value, path + (str(key),))
    elif isinstance(node, (list, tuple)):
        for i, value in enumerate(node):
            yield from _walk(value, path + (str(i),))


def plain(cfg) -> object:
    """A DictConfig / ListConfig as plain containers with interpolations resolved — what ``instantiate`` sees."""
    from omegaconf import DictConfig, ListConfig, OmegaConf

    if isinstance(cfg, (DictConfig, ListConfig)):
        try:
            return OmegaConf.to_container(cfg, resolve=True)
        except Exception as exc:
            raise ConfigError(f"cannot resolve the config: {str(exc).strip().splitlines()[0]}") from exc
    return cfg


def check_targets(cfg, policy: Mapping[str, Rule], source: str | Path, prefix: str = "") -> None:
    """Refuse (:class:`UnsafeConfigError`) any ``_target_`` in ``cfg`` that ``policy`` does not allow.

    ``cfg`` is a DictConfig (resolved first, as ``instantiate`` would) or plain dicts and lists; ``source``
    (a file, or a description such as ``"--set"``) and ``prefix`` (prepended to key names) go into the message.
    """
    tree = plain(cfg)
    for path, node in _walk(tree, ()):
        if "_target_" not in node:
            continue
        key = ".".join(([prefix] if prefix else []) + list(path)) or "<root>"
        target = node["_target_"]
        if not isinstance(target, str):
            raise UnsafeConfigError(f"{source}: {key}._target_ must be a dotted name, got {type(target).__name__}")
        found = _rule_for(path, policy)
        if found is None:
            raise UnsafeConfigError(
                f"{source}: {key}._target_={target!r} is not allowed: no object may be instantiated at {key}"
            )
        if not found[1].allows(target):
            raise UnsafeConfigError(f"{source}: {key}._target_={target!r} is not allowed: expected {found[1].expected}")


def check_run_config(cfg, source: str | Path) -> None:
    """:data:`RUN_POLICY` over a whole run config (a run folder's, or the one ``train`` is about to run)."""
    check_targets(cfg, RUN_POLICY, source)


def check_checkpoint(checkpoint: Mapping, source: str | Path) -> None:
    """Vet a checkpoint dict (read with ``weights_only=True``): :data:`CHECKPOINT_POLICY` over ``hyper_parameters``,
    no Lightning instantiator keys, and no ``_target_`` anywhere else."""
    if not isinstance(checkpoint, Mapping):
        raise UnsafeConfigError(f"{source}: not a mocapkit checkpoint (a {type(checkpoint).__name__}, not a dict)")
    hparams = checkpoint.get("hyper_parameters", {})
    if not isinstance(hparams, Mapping):
        raise UnsafeConfigError(f"{source}: hyper_parameters must be a dict, got {type(hparams).__name__}")
    for key in hparams:
        if str(key) in LIGHTNING_INSTANTIATOR_KEYS or str(key).startswith("_"):
            raise UnsafeConfigError(f"{source}: hyper_parameters.{key} is not allowed (no instantiator keys)")
    check_targets(dict(hparams), CHECKPOINT_POLICY, source, prefix="hyper_parameters")
    rest = {k: v for k, v in checkpoint.items() if k not in ("hyper_parameters", "state_dict", "optimizer_states")}
    check_targets(rest, {}, source)
