"""The method registry: every method of every task, one Hydra config file each.

Layout::

    configs/<task>/method/<NAME>.yaml     one method: {_target_: its class or factory, its parameters with their
                                          defaults}; the file's first comment line is its one-line description
    configs/<task>/method.yaml            the task's default method: ``defaults: [method: NAME]`` (only the tasks
                                          whose commands pick one without --method)

``task`` is one of :data:`TASKS`. Every reader goes through this module: ``mocapkit refine / index / search /
synthesize / kinect-fix --method NAME --set key=value``, ``mocapkit methods`` (:func:`describe`), the comparison
configs (``configs/compare/*.yaml`` put an entry into their ``templates`` with the defaults list,
``- /refinement/method@templates.trnn: trnn``, and a method reads it as ``estimator: ${templates.trnn}``), and the
contract tests (``tests/<task>/test_contract.py`` run :mod:`mocapkit.testing.estimator_checks` on every name).
Adding a method = adding its file.

**Overrides** (``--set``) are Hydra overrides on the method's node, composed with the file as the primary config:
``--set n_inducing=64``, ``--set extrapolate=null``, ``--set "features=[positions,relational]"``,
``--set "network={hidden: 16}"``. A key that is not one of the node's parameters fails naming it and listing the
parameters (also ``_target_`` and other ``_``-keys: the class is the file's, never the command line's); a value of
the wrong type for a number or boolean parameter fails naming both.

**Two kinds of entries.** An *estimator* entry (``_target_``) is built by :func:`build_method`: its ``_target_``
(nested ones too) must pass the task's rule of :data:`mocapkit.train.safety.METHOD_POLICIES` before anything is
imported or built. A *training-run* entry names the experiment that trains it instead (``experiment: ntu_gcn``:
``mocapkit train experiment=ntu_gcn``, configs/experiment/ntu_gcn.yaml); these are the networks of recognition,
gait and clustering, which the comparison runs as ``learned: {experiment: NAME}`` (the registry entry is the
same mapping). :func:`build_method` refuses them, naming the command that trains them.

**Learned** (the ``learned`` column of :func:`describe` and ``mocapkit methods``): a method that needs a trained
model. It is read from the entry, nowhere else: a training-run entry; an entry with a required parameter
(``???``: the checkpoint or ONNX file of a trained network, e.g. ``refinement/learned``, ``retrieval/embedding``);
or an entry whose class has ``trains_network = True`` (it trains a network in ``fit``: ``synthesis/cvae``,
``kinect/bigru``).
"""

from __future__ import annotations

import typing
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from mocapkit.train.config import CONFIG_DIR, _compose, check_override_types, parse_overrides
from mocapkit.train.errors import ConfigError

#: The task packages that register methods (``configs/<task>/method/``).
TASKS = ("recognition", "gait", "clustering", "refinement", "retrieval", "synthesis", "kinect", "depth_tracking")


@dataclass(frozen=True)
class MethodInfo:
    """One row of :func:`describe`."""

    task: str
    name: str
    description: str
    learned: bool
    target: str  # the dotted class or factory, or "experiment NAME"


def _folder(task: str) -> Path:
    if task not in TASKS:
        raise ConfigError(f"unknown task {task!r}; the tasks: {', '.join(TASKS)}")
    return Path(CONFIG_DIR) / task / "method"


def method_names(task: str) -> list[str]:
    """The registered names of ``task``: the files ``configs/<task>/method/<NAME>.yaml``, sorted."""
    return sorted(p.stem for p in _folder(task).glob("*.yaml"))


def default_method(task: str) -> str | None:
    """The method ``configs/<task>/method.yaml`` names (``defaults: [method: NAME]``); None where the task has none."""
    import yaml

    path = _folder(task).parent / "method.yaml"
    if not path.is_file():
        return None
    for entry in yaml.safe_load(path.read_text()).get("defaults", []):
        if isinstance(entry, dict) and "method" in entry:
            return str(entry["method"])
    raise ConfigError(f"{path}: expected defaults: [method: NAME]")


def _check_name(task: str, name: str) -> None:
    names = method_names(task)
    if name not in names:
        raise ConfigError(f"unknown {task} method {name!r}; known: {', '.join(names)} ({_folder(task)}/NAME.yaml)")


def _file_node(task: str, name: str) -> dict:
    import yaml

    return yaml.safe_load((_folder(task) / f"{name}.yaml").read_text()) or {}


def _target(node) -> str:
    if node.get("_target_") is not None:
        return str(node["_target_"])
    if node.get("experiment") is not None:
        return f"experiment {node['experiment']}"
    return "?"


def _parameter_names(node) -> list[str]:
    """The parameters of a method's node, required ones (``???``) included: iterating a DictConfig lists them,
    where ``key in node`` is False for a key whose value is missing."""
    return [str(k) for k in node if not str(k).startswith("_")]


def method_parameters(task: str, name: str) -> list[str]:
    """The parameter names of the registry's ``name`` (``configs/<task>/method/<name>.yaml``), required ones
    included; what callers test before passing an optional setting (``random_state``, ``checkpoint``)."""
    return _parameter_names(method_config(task, name))


def method_config(task: str, name: str, overrides: Sequence[str] = ()):
    """The composed node (an OmegaConf DictConfig) of ``configs/<task>/method/<name>.yaml`` with the Hydra
    ``overrides`` (``--set``).

    Raises:
        ConfigError: an unknown task or name (the message lists the names), a key that is not a parameter (named,
            with the method's parameters), a value of the wrong type, or an override Hydra cannot parse.
    """
    _check_name(task, name)
    folder = _folder(task)  # the method folder as the config dir: the file is composed at the root
    base = _compose(folder, name, [])
    if not overrides:
        return base
    keys = _parameter_names(base)
    what = f"{task} method {name!r} ({_target(base)})"
    for item in overrides:
        if "=" not in item and not item.startswith("~"):
            raise ConfigError(f"--set {item}: expected KEY=VALUE")
    try:
        parsed_overrides = list(parse_overrides(list(overrides)))
    except ConfigError as exc:  # Hydra's parser: the message names the override
        raise ConfigError(f"--set: {what}: {exc}") from None
    for item, parsed in parsed_overrides:
        if parsed is None:
            raise ConfigError(f"--set {item}: expected KEY=VALUE")
        top = parsed.key_or_group.split(".", 1)[0]
        if top not in keys:
            raise ConfigError(
                f"--set {item}: {what} has no parameter {top!r}; its parameters: {', '.join(keys) or '(none)'}"
            )
    try:
        check_override_types(list(overrides), base, source=f"{what}: --set")
    except ConfigError as exc:
        raise ConfigError(str(exc)) from None
    try:
        cfg = _compose(folder, name, list(overrides))
    except ConfigError as exc:  # Hydra's messages span lines: keep the first, which names the override
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc.__cause__).__name__
        raise ConfigError(f"--set {' '.join(overrides)}: {what}: {first}") from exc
    _check_annotated_types(task, cfg, base, overrides, what)
    return cfg


def override_values(overrides: Sequence[str], parameters: Sequence[str], what: str) -> dict:
    """``--set key=value`` items read with Hydra's override grammar and value types (``null``, ``true``, ``0.1``,
    ``[1,2]``, ``{hidden: 16}``) as a dict, for settings that are not a registry entry: a loaded model's
    (``kinect-fix apply``), a generator's (``synth ntu``). A key not in ``parameters`` fails naming it and ``what``.
    """
    values = {}
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"--set {item}: expected KEY=VALUE")
    for item, parsed in parse_overrides(list(overrides)):
        if parsed is None or parsed.is_delete() or parsed.is_add() or parsed.package is not None:
            raise ConfigError(f"--set {item}: expected KEY=VALUE")
        if parsed.key_or_group not in parameters:
            raise ConfigError(
                f"--set {item}: {what} has no parameter {parsed.key_or_group!r}; its parameters: "
                f"{', '.join(parameters)}"
            )
        values[parsed.key_or_group] = parsed.value()
    return values


def _check_annotated_types(task: str, cfg, base, overrides: Sequence[str], what: str) -> None:
    """A number parameter that is null by default (``window: null``) still refuses a word: the class's annotation
    (``int | None``) says what it takes. Other annotations are not checked."""
    from mocapkit.train.safety import METHOD_RULES, _locate

    target = base.get("_target_")
    if target is None or not METHOD_RULES[task].allows(str(target)):  # build_method refuses it, naming it
        return
    try:
        hints = typing.get_type_hints(_locate(str(target)).__init__)
    except Exception:  # a factory, or annotations this Python cannot evaluate: nothing to check
        return
    for item, parsed in parse_overrides(list(overrides)):
        key = parsed.key_or_group
        if "." in key or parsed.is_delete() or base.get(key, 0) is not None or key not in hints:
            continue
        allowed = [t for t in typing.get_args(hints[key]) or (hints[key],) if t is not type(None)]
        value = cfg.get(key)
        if value is None or not allowed or not all(t in (int, float) for t in allowed):
            continue
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not number or (allowed == [int] and isinstance(value, float)):
            kind = "an integer" if allowed == [int] else "a number"
            raise ConfigError(f"--set {item}: {what}: {key} must be {kind} or null, got {value!r}")


def _resolved(task: str, name: str, cfg):
    """Refuse a training-run entry, a missing required parameter and a ``_target_`` the task's policy does not allow."""
    from omegaconf import OmegaConf

    from mocapkit.train.safety import METHOD_POLICIES, check_targets

    if cfg.get("_target_") is None:
        if cfg.get("experiment") is not None:
            raise ConfigError(
                f"{task} method {name!r} is a network trained by `mocapkit train "
                f"experiment={cfg.experiment}`, not an estimator built here"
            )
        raise ConfigError(f"{_folder(task)}/{name}.yaml: no _target_ (and no experiment)")
    missing = sorted(OmegaConf.missing_keys(cfg))
    if missing:
        raise ConfigError(
            f"{task} method {name!r} ({cfg._target_}) needs {', '.join(missing)}: a required "
            f"parameter (--set {missing[0]}=VALUE)"
        )
    check_targets(cfg, METHOD_POLICIES[task], f"{task} method {name!r}")


def build_method(task: str, name: str, overrides: Sequence[str] = ()):
    """The method ``name`` of ``task`` built from its config with the Hydra ``overrides`` (unfitted).

    Raises:
        ConfigError: see :func:`method_config`; also a training-run entry (it names ``mocapkit train``), a required
            parameter left unset (``???``, named), a class or factory that cannot be built from the parameters
            (named), and (:class:`~mocapkit.train.safety.UnsafeConfigError`) a ``_target_`` the task may not name.
    """
    from hydra.utils import instantiate

    cfg = method_config(task, name, overrides)
    _resolved(task, name, cfg)
    try:
        return instantiate(cfg, _convert_="all")
    except Exception as exc:  # Hydra wraps import and constructor errors in InstantiationException
        cause = exc.__cause__ or exc
        raise ConfigError(f"{task} method {name!r}: cannot build {cfg._target_}: {cause}") from exc


def method_class(task: str, name: str):
    """The class the entry names (after the task's safety check), to rebuild a saved method from its parameters
    without reading a class name from the saved file (:meth:`mocapkit.retrieval.index.MotionIndex.load`)."""
    from mocapkit.train.safety import METHOD_POLICIES, _locate, check_targets

    cfg = method_config(task, name)
    if cfg.get("_target_") is None:
        _resolved(task, name, cfg)
    check_targets({"_target_": str(cfg._target_)}, METHOD_POLICIES[task], f"{task} method {name!r}")
    return _locate(str(cfg._target_))


def _is_learned(task: str, node: dict) -> bool:
    if node.get("_target_") is None:
        return node.get("experiment") is not None
    if any(value == "???" for value in node.values()):
        return True
    from mocapkit.train.safety import METHOD_RULES, _locate

    target = str(node["_target_"])
    if not METHOD_RULES[task].allows(target):  # nothing the task's rule refuses is imported
        return False
    return bool(getattr(_locate(target), "trains_network", False))


def describe(task: str | None = None) -> list[MethodInfo]:
    """One :class:`MethodInfo` per registered method (of ``task``, or of every task), in task then name order."""
    rows = []
    for one in [task] if task is not None else TASKS:
        for name in method_names(one):
            path = _folder(one) / f"{name}.yaml"
            first = path.read_text().splitlines()[:1]
            description = first[0].lstrip("#").strip() if first and first[0].startswith("#") else ""
            node = _file_node(one, name)
            rows.append(MethodInfo(one, name, description, _is_learned(one, node), _target(node)))
    return rows


def methods_table(task: str | None = None) -> str:
    """:func:`describe` as the text table ``mocapkit methods [TASK]`` prints (the default method marked ``*``)."""
    rows = describe(task)
    defaults = {t: default_method(t) for t in {r.task for r in rows}}
    cells = [("task", "name", "learned", "description")]
    cells += [
        (r.task, r.name + (" *" if defaults[r.task] == r.name else ""), "yes" if r.learned else "no", r.description)
        for r in rows
    ]
    widths = [max(len(c[i]) for c in cells) for i in range(3)]
    lines = ["  ".join(c[i].ljust(widths[i]) for i in range(3)) + "  " + c[3] for c in cells]
    return "\n".join(
        lines + ["(* the task's default; configs/<task>/method/<name>.yaml; --set key=value overrides a parameter)"]
    )
