"""What the synthesis configs share: JSON round trips and checks that name the first bad field.

:class:`~mocapkit.datasets.synthetic.ntu.NTUSynthConfig` and
:class:`~mocapkit.datasets.synthetic.casia_b.CasiaBSynthConfig` derive from :class:`SynthConfig`
and validate with a :class:`FieldCheck`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, fields
from typing import Any, TypeVar

import numpy as np

_Config = TypeVar("_Config", bound="SynthConfig")


class SynthConfig:
    """Base of the synthesis config dataclasses: :meth:`to_dict` / :meth:`from_dict`."""

    def to_dict(self) -> dict:
        """JSON-ready dict (tuples become lists)."""
        return {k: list(v) if isinstance(v, tuple) else v for k, v in asdict(self).items()}

    @classmethod
    def from_dict(cls: type[_Config], d: dict) -> _Config:
        """Inverse of :meth:`to_dict`, e.g. for a config written as JSON; unknown keys are an error."""
        unknown = sorted(set(d) - {f.name for f in fields(cls)})
        if unknown:
            raise ValueError(f"unknown {cls.__name__} fields: {unknown}")
        return cls(**d)


class FieldCheck:
    """Checks on the fields of ``config``; each raises ``ValueError`` at the first failure,
    ``"<Config>.<field> = <value!r>: <why>"``."""

    def __init__(self, config: Any):
        self.config = config

    def require(self, ok: bool, name: str, why: str) -> None:
        """Fail on field ``name`` unless ``ok``."""
        if not ok:
            raise ValueError(f"{type(self.config).__name__}.{name} = {getattr(self.config, name)!r}: {why}")

    def integer(self, name: str, low: int, high: int, unit: str = "") -> None:
        """An integer (Python or numpy) in ``low..high`` (``unit`` ends the message, e.g. ``" pixels"``)."""
        value = getattr(self.config, name)
        self.require(
            isinstance(value, (int, np.integer)) and low <= value <= high,
            name,
            f"must be an integer in {low}..{high}{unit}",
        )

    def distinct(self, name: str, allowed: Callable[[Any], bool], why: str) -> None:
        """A non-empty collection of distinct values, each ``allowed``."""
        values = getattr(self.config, name)
        self.require(bool(values) and len(set(values)) == len(values) and all(allowed(v) for v in values), name, why)

    def seed(self, name: str = "seed") -> None:
        """A non-negative integer."""
        value = getattr(self.config, name)
        self.require(isinstance(value, (int, np.integer)) and value >= 0, name, "must be a non-negative integer")

    def non_negative(self, *names: str) -> None:
        """Finite numbers >= 0."""
        for name in names:
            value = getattr(self.config, name)
            self.require(np.isfinite(value) and value >= 0, name, "must be a finite number >= 0")

    def probability(self, *names: str) -> None:
        """Numbers in [0, 1]."""
        for name in names:
            self.require(0.0 <= getattr(self.config, name) <= 1.0, name, "must be a probability in [0, 1]")
