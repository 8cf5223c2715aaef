"""Restoring a run from one of its checkpoints: its config (composed again with overrides) and its LightningModule.

A checkpoint is data, not code: it is read once, with ``torch.load(..., weights_only=True)`` (never the
torch default), its ``hyper_parameters`` are vetted against :data:`~mocapkit.train.safety.CHECKPOINT_POLICY`
before anything is built, and the module class comes from the run's (vetted) config. A file that is not a
checkpoint — empty, text, a zip of something else — is refused with one line naming it.
"""

from __future__ import annotations

import io
from collections.abc import Mapping
from pathlib import Path

import lightning as L
from omegaconf import DictConfig

from mocapkit.train.config import ConfigError, load_run_config


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return (text.splitlines()[0] if text else type(exc).__name__)[:300]


def restore_error_detail(exc: BaseException) -> str:
    """One line saying why a module could not be restored from a checkpoint: for weights of another network
    version (torch's "Error(s) in loading state_dict", whose first line names nothing) the missing, unexpected and
    mismatched keys; otherwise the error's first line."""
    lines = [line.strip() for line in str(exc).strip().splitlines() if line.strip()]
    if lines and lines[0].startswith("Error(s) in loading state_dict") and len(lines) > 1:
        return ("weights of another network version (retrain the run): " + "; ".join(lines[1:]))[:500]
    return _first_line(exc)


def read_checkpoint_bytes(ckpt_path: str | Path) -> bytes:
    """The bytes of ``ckpt_path``; a missing file, a folder or an unreadable file is a ConfigError naming it."""
    ckpt_path = Path(ckpt_path)
    if not ckpt_path.is_file():
        raise ConfigError(f"{ckpt_path}: no such checkpoint file")
    try:
        return ckpt_path.read_bytes()
    except OSError as exc:
        raise ConfigError(f"{ckpt_path}: cannot read the checkpoint: {exc.strerror or exc}") from exc


def parse_checkpoint(raw: bytes, source: str | Path) -> dict:
    """``torch.load(weights_only=True)`` of ``raw``, vetted (:func:`~mocapkit.train.safety.check_checkpoint`)."""
    import torch

    from mocapkit.train.safety import check_checkpoint

    if not raw:
        raise ConfigError(f"{source}: not a checkpoint (the file is empty)")
    try:
        checkpoint = torch.load(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except Exception as exc:  # UnpicklingError, RuntimeError (not a zip / bad archive), EOFError, ...
        flat = " ".join(str(exc).split())
        start = flat.find("WeightsUnpickler error:")
        detail = flat[start:].split(". ")[0].split(" Check the documentation")[0][:200] if start >= 0 else None
        if detail is None and "weights only load failed" in str(exc).lower():
            detail = "it holds objects other than tensors and plain data"
        raise ConfigError(
            f"{source}: not a PyTorch checkpoint that loads with weights_only=True (no code is "
            f"run from a checkpoint): {detail or _first_line(exc)}"
        ) from exc
    if not isinstance(checkpoint, Mapping) or not isinstance(checkpoint.get("state_dict"), Mapping):
        raise ConfigError(f"{source}: not a Lightning checkpoint (no state_dict)")
    check_checkpoint(checkpoint, source)
    return checkpoint


def load_checkpoint(ckpt_path: str | Path) -> dict:
    """The vetted checkpoint dict of ``ckpt_path`` (see :func:`parse_checkpoint`)."""
    return parse_checkpoint(read_checkpoint_bytes(ckpt_path), ckpt_path)


def load_module(cfg: DictConfig, ckpt_path: str | Path) -> L.LightningModule:
    """The LightningModule of ``cfg.module._target_`` restored from ``ckpt_path`` (on the CPU).

    The module target is checked against :data:`~mocapkit.train.safety.RUN_POLICY` and the checkpoint's
    hyper-parameters against :data:`~mocapkit.train.safety.CHECKPOINT_POLICY` before the class is built;
    the file is read once and handed to Lightning from memory with ``weights_only=True``.
    """
    from mocapkit.train.safety import LIGHTNING_MODULE, UnsafeConfigError, _locate

    ckpt_path = Path(ckpt_path)
    target = cfg.module.get("_target_") if isinstance(cfg.get("module"), Mapping) else None
    if not isinstance(target, str) or not LIGHTNING_MODULE.allows(target):
        raise UnsafeConfigError(
            f"{ckpt_path.parent}: module._target_={target!r} is not allowed: expected {LIGHTNING_MODULE.expected}"
        )
    raw = read_checkpoint_bytes(ckpt_path)
    parse_checkpoint(raw, ckpt_path)  # vetted before anything is built
    try:
        return _locate(target).load_from_checkpoint(io.BytesIO(raw), map_location="cpu", weights_only=True)
    except ConfigError:
        raise
    except Exception as exc:  # hyper-parameters that do not fit the class, a state dict of another network, ...
        raise ConfigError(f"{ckpt_path}: cannot restore {target} from it: {restore_error_detail(exc)}") from exc


def checkpoint_config(ckpt_path: str | Path, overrides: list[str] | None = None) -> DictConfig:
    """The config of the run ``ckpt_path`` belongs to, composed again with ``overrides`` (and vetted)."""
    ckpt_path = Path(ckpt_path)
    if not ckpt_path.is_file():
        raise ConfigError(f"ckpt_path={ckpt_path}: no such checkpoint")
    return load_run_config(ckpt_path.parent, overrides)
