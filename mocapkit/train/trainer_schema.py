"""The schema of ``configs/trainer/``: every argument of ``lightning.Trainer`` as a config key.

:class:`TrainerConfig` is generated from ``inspect.signature(lightning.Trainer)`` with Lightning's own
defaults, so each documented ``trainer.X=...`` works without Hydra's ``+`` (``trainer.max_steps=100``,
``trainer.max_time=00:01:00:00``, ``trainer.limit_val_batches=0.5``) and a misspelt key fails naming it.
``configs/trainer/default.yaml`` extends it (``defaults: [/lightning_trainer@_here_]``) and sets this
project's values (CPU, 30 epochs, ...). Keys whose type OmegaConf can hold exactly (``int``, ``bool``,
``str``, each possibly null) are typed, so ``trainer.min_epochs=abc`` fails at composition; unions
(``devices: int | str | list``, ``limit_val_batches: int | float``) are ``Any``, as 1 and 1.0 differ there.

``precision`` takes Lightning's values (``32-true``, ``bf16-mixed``, ``16-mixed``, ...) and ``auto``, this project's
default: :func:`mocapkit.train.training.build_trainer` resolves it to ``bf16-mixed`` where the device has bfloat16
arithmetic and ``32-true`` elsewhere (:func:`mocapkit.train.training.auto_precision`).

The arguments the engine sets itself from other keys (:data:`SET_ELSEWHERE`) are left out, so setting
them under ``trainer`` is an error naming the key to use instead rather than a value silently replaced.
"""

from __future__ import annotations

import dataclasses
import inspect
import typing
from functools import cache
from typing import Any

#: The name of the schema in Hydra's ConfigStore (``configs/trainer/default.yaml`` lists it in its defaults).
SCHEMA_NAME = "lightning_trainer"

#: ``lightning.Trainer`` arguments that :func:`mocapkit.train.training.train` passes itself, and where they are set.
SET_ELSEWHERE = {
    "callbacks": "the callbacks group (callbacks=NAME, callbacks.KEY=...)",
    "logger": "the logger group (logger=tensorboard|none)",
    "deterministic": "the top-level key deterministic=true|false",
    "default_root_dir": "the run folder (output_root, experiment_name, run_name)",
}

_EXACT = (bool, int, float, str)


def _field_type(annotation, default) -> Any:
    """The annotation as a type OmegaConf checks (``int``, ``bool | None``, ...), else ``Any``."""
    if annotation in _EXACT:
        return annotation | None if default is None else annotation
    args = typing.get_args(annotation)
    if typing.get_origin(annotation) is typing.Union and len(args) == 2 and type(None) in args:
        (inner,) = [a for a in args if a is not type(None)]
        if inner in _EXACT:
            return inner | None
    return Any


def _yaml_value(value) -> bool:
    return value is None or isinstance(value, _EXACT)


@cache
def trainer_schema() -> type:
    """The dataclass ``TrainerConfig``: ``_target_: lightning.Trainer`` and one field per Trainer argument whose
    default YAML can hold (all of them in Lightning 2.x), minus :data:`SET_ELSEWHERE`."""
    import lightning

    hints = typing.get_type_hints(lightning.Trainer.__init__)
    fields = [("_target_", str, dataclasses.field(default="lightning.Trainer"))]
    for name, parameter in inspect.signature(lightning.Trainer.__init__).parameters.items():
        if name == "self" or name in SET_ELSEWHERE or parameter.default is inspect.Parameter.empty:
            continue
        if not _yaml_value(parameter.default):
            continue
        kind = _field_type(hints.get(name, Any), parameter.default)
        fields.append((name, kind, dataclasses.field(default=parameter.default)))
    schema = dataclasses.make_dataclass("TrainerConfig", fields)
    schema.__module__ = __name__
    return schema


def trainer_keys() -> list[str]:
    """The keys of the ``trainer`` node: the Trainer arguments of :func:`trainer_schema` and ``_target_``."""
    return [field.name for field in dataclasses.fields(trainer_schema())]


def schema_registered() -> bool:
    from hydra.core.config_store import ConfigStore

    return f"{SCHEMA_NAME}.yaml" in ConfigStore.instance().repo


def register_trainer_schema() -> None:
    """Store :func:`trainer_schema` in Hydra's ConfigStore as ``/lightning_trainer`` (once; it imports Lightning)."""
    from hydra.core.config_store import ConfigStore

    if not schema_registered():
        ConfigStore.instance().store(name=SCHEMA_NAME, node=trainer_schema())
