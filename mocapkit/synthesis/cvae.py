"""A small modern learned generator for the variation benchmark: an autoregressive conditional VAE (MVAE-style)
over the thesis's pose features, trained in ``fit`` on the ~10 example clips.

**Features.** Each training clip is resampled to ``fps`` frames per second (every AMC channel time-warped
linearly, :func:`~mocapkit.synthesis.clips.resample_clip`; at 120 fps consecutive frames are nearly equal and an
autoregressive model learns to extrapolate and ignore its latent code) and encoded
(:func:`~mocapkit.synthesis.representation.encode`, ``FeatureClip.flat``: ``[T, 7 + 3B]``); every dimension is
z-scored over the training frames (sd floored at 1e-3 of the largest).

**Network and training.** :class:`~mocapkit.models.motion_vae.MotionVAE` (encoder ``q(z | x_t, x_{t−1})``,
decoder ``p(x_t | z, x_{t−1}, x_{t−2})``), trained by :class:`~mocapkit.synthesis.module.MotionVAEModule`
for ``steps`` optimiser steps of ``batch_size`` frame triples (Adam, learning rate ``lr``; :func:`frame_loader`), no
logger, no checkpoint written, seeded by ``random_state`` (``lightning.seed_everything``). ``loss_curve_`` keeps the
loss of every step. The Lightning ``Trainer`` is the one ``mocapkit train`` builds
(:func:`~mocapkit.train.training.build_estimator_trainer`: ``configs/trainer/default.yaml``, its ``accelerator: auto``
included), with the estimator's ``trainer`` parameter on top (``trainer={"accelerator": "gpu"}``).

**Runs.** ``mocapkit train experiment=synthesis_cvae data.root=DIR data.motion_type=TYPE`` trains the same network on
the clips ``mocapkit synthesize`` would take (:class:`~mocapkit.synthesis.datamodule.SynthesisClipsDataModule`);
:meth:`CVAESynthesizer.from_checkpoint` turns its ``best.ckpt`` into a fitted synthesiser.

**Sampling.** Per variant the first two frames of a training clip drawn uniformly, then the decoder run
autoregressively with ``z = noise_scale · ε``, ``ε ~ N(0, I)``, at every step (a torch generator seeded from the
sampling seed), for the number of model-rate frames that spans ``n_frames`` at the training rate; the features are
decoded (:func:`~mocapkit.synthesis.representation.decode`, from the drawn clip's start position and heading) and
the AMC values resampled to ``n_frames`` by a cubic spline (:func:`~mocapkit.synthesis.clips.time_warp`: velocity
and acceleration stay continuous at the model's frames, where linear interpolation would kink).
"""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mocapkit.motion.container import Motion
from mocapkit.synthesis.base import MotionSynthesizer
from mocapkit.synthesis.clips import (
    SMOOTHING_SECONDS,
    dof_values,
    model_frames,
    resample_clip,
    rotation_columns,
    time_warp,
)
from mocapkit.synthesis.footskate import DEFAULT_ROOT_MOVE
from mocapkit.synthesis.representation import (
    continuous_pieces,
    decode,
    encode,
    root_start,
)


class CVAESynthesizer(MotionSynthesizer):
    """Autoregressive conditional VAE trained on the example clips (module docstring).

    Args:
        fps: the model's frame rate (frames per second; None: the clips' own).
        latent, hidden, layers: :class:`~mocapkit.models.motion_vae.MotionVAE` sizes.
        beta: KL weight; condition_noise: noise on the conditioning frames in training (standardised units).
        steps: optimiser steps; batch_size: frame triples per step; lr: Adam learning rate.
        max_turn_speed: training clips are cut at joint-angle flips faster than this (degrees per second;
            :func:`~mocapkit.synthesis.representation.continuous_pieces`, as for SLFM); None: no cutting.
        random_state: seed of the initialisation, the batches and the training noise.
        footskate_cleanup, footskate_root: the footskate cleanup after sampling, the same as SLFM's
            (:class:`~mocapkit.synthesis.base.MotionSynthesizer`).
        smoothing_seconds: the Gaussian smoothing of every variant before the cleanup, seconds (0: off;
            :class:`~mocapkit.synthesis.base.MotionSynthesizer`).
        noise_scale: the latent draws are multiplied by this (1, default: the prior; above 1 the decoder is driven
            further from the codes of the training frames, for more variation). ``"auto"``: after training, the
            smallest of :attr:`noise_scales` whose variants reach ``target_variation`` times the training clips'
            own V, as for SLFM (:class:`~mocapkit.synthesis.base.MotionSynthesizer`; training clips only).
        target_variation: the ``V / V_train`` that ``noise_scale="auto"`` asks for (default 1.28, Zhou's ratio
            as for SLFM).
        trainer: Lightning ``Trainer`` arguments over ``configs/trainer/default.yaml`` and the estimator's own
            (``max_steps=steps``, no logger, no checkpoint, no progress bar), e.g. ``{"accelerator": "gpu",
            "devices": 1, "precision": "bf16-mixed"}``; None: those defaults (``accelerator: auto``: the CPU where
            there is no GPU).

    Attributes (after ``fit``): module_: the trained :class:`~mocapkit.synthesis.module.MotionVAEModule`
    (eval mode); mean_, scale_: float64 ``[F]`` standardisation; starts_: float64 ``[C, 2, F]`` the first two
    (unstandardised) frames of every clip at the model rate; start_places_: per clip ``(start_xz, start_yaw)``;
    model_fps_: the model rate; loss_curve_: float64 ``[steps]``; train_seconds_: wall time of the training;
    angle_flips_: ``(clip, frame, bone, degrees)`` of the flips the clips were cut at; noise_scale_,
    variation_by_noise_scale_: the scale sampling uses and, with ``"auto"``, each tried scale's ``V / V_train``.

    ``noise_scales`` (what ``"auto"`` tries) reach 6 because the decoder leans little on its code: on the seed-0
    training clips of the four HDM05 types of ``configs/compare/synthesis_hdm05.yaml`` the scale 1 gave 0.84–1.23×
    the clips' V, 4 gave 1.09–1.79× (measured on those training clips only).
    """

    trains_network = True  # fit trains a network: "learned" in the method registry (mocapkit.train.registry)
    min_frames = 4
    noise_scales = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0)

    def __init__(
        self,
        fps: float | None = 30.0,
        latent: int = 16,
        hidden: int = 256,
        layers: int = 2,
        beta: float = 0.01,
        condition_noise: float = 0.05,
        steps: int = 400,
        batch_size: int = 256,
        lr: float = 1e-3,
        max_turn_speed: float | None = 5400.0,
        random_state: int | None = 0,
        footskate_cleanup: bool = True,
        footskate_root: str = DEFAULT_ROOT_MOVE,
        smoothing_seconds: float = SMOOTHING_SECONDS,
        noise_scale: float | str = 1.0,
        target_variation: float = 1.28,
        trainer: dict | None = None,
    ):
        self.fps = fps
        self.latent = latent
        self.hidden = hidden
        self.layers = layers
        self.beta = beta
        self.condition_noise = condition_noise
        self.steps = steps
        self.batch_size = batch_size
        self.lr = lr
        self.max_turn_speed = max_turn_speed
        self.random_state = random_state
        self.footskate_cleanup = footskate_cleanup
        self.footskate_root = footskate_root
        self.smoothing_seconds = smoothing_seconds
        self.noise_scale = noise_scale
        self.target_variation = target_variation
        self.trainer = trainer

    def _fit_clips(self, clips: list[Motion]) -> None:
        import lightning as L

        from mocapkit.train.training import build_estimator_trainer, check_trainer_parameter

        if self.fps is not None and not float(self.fps) > 0:
            raise ValueError(f"CVAESynthesizer: fps={self.fps!r} must be positive (or None)")
        check_trainer_parameter(self.trainer, "CVAESynthesizer")
        self._check_noise_scale()
        self.model_fps_ = self.fps_ if self.fps is None else float(self.fps)
        data = training_frames(clips, self.model_fps_, self.max_turn_speed, what="CVAESynthesizer.fit")
        self.angle_flips_, self.mean_, self.scale_ = data.flips, data.mean, data.scale
        self.starts_, self.start_places_ = data.starts, data.start_places
        module = getattr(self, "_trained_module", None)  # from_checkpoint: the run's network, no training
        if module is None:
            L.seed_everything(0 if self.random_state is None else int(self.random_state), workers=False, verbose=False)
            loader = frame_loader(data.current, data.previous, int(self.batch_size), shuffle=True)
            module = vae_module(
                data,
                latent=self.latent,
                hidden=self.hidden,
                layers=self.layers,
                lr=self.lr,
                beta=self.beta,
                condition_noise=self.condition_noise,
            )
            trainer = build_estimator_trainer(self.steps, self.trainer)
            start = time.perf_counter()
            trainer.fit(module, train_dataloaders=loader)
            self.train_seconds_ = time.perf_counter() - start
        else:
            self.train_seconds_ = float("nan")
        self.loss_curve_ = np.asarray(module.loss_curve, dtype=np.float64)
        self.module_ = module.cpu().eval()
        self._set_noise_scale(clips)

    @classmethod
    def from_checkpoint(cls, path: str | os.PathLike, clips: list[Motion] | None = None, **params) -> CVAESynthesizer:
        """A fitted synthesiser from a checkpoint of a ``mocapkit train experiment=synthesis_cvae`` run
        (``RUN/best.ckpt``, read with ``weights_only=True`` and vetted): the network and its sizes, ``beta``,
        ``condition_noise``, ``lr``, ``fps`` and ``max_turn_speed`` come from the checkpoint, ``params``
        (``noise_scale``, ``footskate_cleanup``, ``random_state``, ...) are set on top. What sampling needs from the
        training clips (the reference skeleton, the start frames, the floor) comes from ``clips``; None: the run's
        own training clips, read again through its data config. The clips' standardisation must be the one the
        run trained with (a ValueError names the checkpoint otherwise), and ``noise_scale="auto"`` chooses its
        scale on them as ``fit`` does."""
        import io

        from mocapkit.synthesis.module import MotionVAEModule
        from mocapkit.train.checkpoints import parse_checkpoint, read_checkpoint_bytes, restore_error_detail

        raw = read_checkpoint_bytes(path)
        hparams = parse_checkpoint(raw, path).get("hyper_parameters", {})
        frames = hparams.get("frames")
        if not isinstance(frames, Mapping) or "mean" not in frames:
            raise ValueError(
                f"{path}: not a motion CVAE checkpoint (no pose-feature standardisation in its "
                f"hyper-parameters); train one with `mocapkit train experiment=synthesis_cvae`"
            )
        try:
            module = MotionVAEModule.load_from_checkpoint(io.BytesIO(raw), map_location="cpu", weights_only=True)
        except Exception as exc:  # weights of another network version, hyper-parameters the class does not take
            raise ValueError(f"{path}: cannot restore the CVAE from it: {restore_error_detail(exc)}") from exc
        if clips is None:
            from mocapkit.train.config import load_run_config
            from mocapkit.train.training import build_datamodule

            clips = build_datamodule(load_run_config(Path(path).parent)).train_clips
        model = dict(module.hparams.model)
        synthesizer = cls(
            fps=frames["fps"],
            max_turn_speed=frames["max_turn_speed"],
            latent=int(model["latent"]),
            hidden=int(model["hidden"]),
            layers=int(model["layers"]),
            beta=float(module.hparams.beta),
            condition_noise=float(module.hparams.condition_noise),
            lr=float(module.hparams.optimizer.get("lr", 1e-3)),
        ).set_params(**params)
        synthesizer._trained_module = module
        try:
            synthesizer.fit(clips)
        finally:
            del synthesizer._trained_module
        if synthesizer.mean_.shape != (len(frames["mean"]),) or not (
            np.allclose(synthesizer.mean_, frames["mean"]) and np.allclose(synthesizer.scale_, frames["scale"])
        ):
            raise ValueError(
                f"{path}: the given clips are not those the run trained on (their pose-feature "
                f"standardisation differs from the checkpoint's)"
            )
        return synthesizer

    def _sample_values(self, n_variants: int, n_frames: int, rng: np.random.Generator) -> list[dict[str, np.ndarray]]:
        import torch

        chosen = rng.integers(len(self.starts_), size=n_variants)
        generator = torch.Generator().manual_seed(int(rng.integers(2**63 - 1)))
        frames = max(model_frames(n_frames, self.fps_, self.model_fps_), 2)
        start = torch.tensor((self.starts_[chosen] - self.mean_) / self.scale_, dtype=torch.float32)
        generated = (
            self.module_.model.rollout(start, frames, generator=generator, scale=self._noise_scale()).double().numpy()
        )
        generated = generated * self.scale_ + self.mean_
        angles = rotation_columns(self.layout_)
        out = []
        for k, clip in enumerate(chosen):
            start_xz, start_yaw = self.start_places_[clip]
            values = decode(generated[k], self.skeleton_, start_xz=start_xz, start_yaw=start_yaw)
            matrix = np.concatenate([values[bone] for bone in self.layout_.bones], axis=1)
            out.append(dof_values(time_warp(matrix, n_frames, angles, kind="cubic"), self.layout_))
        return out


@dataclass
class TrainingFrames:
    """The CVAE's training data from example clips (:func:`training_frames`).

    ``current`` float64 ``[N, F]`` and ``previous`` ``[N, 2, F]``: every frame ``x_t`` of every piece with its two
    predecessors ``(x_{t−1}, x_{t−2})``, standardised; ``mean``, ``scale`` ``[F]``: the standardisation;
    ``starts`` ``[C, 2, F]``: the first two unstandardised frames of every clip; ``start_places``: per clip
    ``(start_xz, start_yaw)``; ``flips``: the angle flips the clips were cut at; ``fps``: the model rate;
    ``max_turn_speed``: the cutting threshold used.
    """

    current: np.ndarray
    previous: np.ndarray
    mean: np.ndarray
    scale: np.ndarray
    starts: np.ndarray
    start_places: list
    flips: list
    fps: float
    max_turn_speed: float | None

    def standardised(self, clips: list[Motion], what: str) -> tuple[np.ndarray, np.ndarray]:
        """``(current, previous)`` of other clips (validation) with this standardisation."""
        cut = continuous_pieces(clips, self.fps, 3, self.max_turn_speed, what=what)
        standard = [(encode(c).flat() - self.mean) / self.scale for c in cut.pieces]
        if not standard:
            return np.zeros((0, len(self.mean))), np.zeros((0, 2, len(self.mean)))
        return _triples(standard)

    def describe(self) -> dict:
        """The plain values a checkpoint keeps (``MotionVAEModule``'s ``frames``): rate, cutting, standardisation."""
        return {
            "fps": float(self.fps),
            "max_turn_speed": self.max_turn_speed,
            "features": int(self.mean.shape[0]),
            "mean": [float(v) for v in self.mean],
            "scale": [float(v) for v in self.scale],
        }


def _triples(standard: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    current = np.concatenate([s[2:] for s in standard])
    previous = np.concatenate([np.stack([s[1:-1], s[:-2]], axis=1) for s in standard])
    return current, previous


def training_frames(clips: list[Motion], fps: float, max_turn_speed: float | None, what: str = "fit") -> TrainingFrames:
    """The CVAE's training data (module docstring, **Features**): the clips resampled to ``fps``, cut at angle flips
    faster than ``max_turn_speed`` (degrees per second; None: no cutting), encoded and z-scored over their frames.

    Raises:
        ValueError: a clip with fewer than 3 frames at ``fps`` (``what`` names the caller).
    """
    short = [c for c in (resample_clip(clip, fps) for clip in clips) if c.num_frames < 3]
    if short:
        raise ValueError(
            f"{what}: {short[0].source or short[0].name} has {short[0].num_frames} frames at {fps:g} "
            f"fps; the model needs 3 (raise fps)"
        )
    cut = continuous_pieces(clips, fps, 3, max_turn_speed, what=what)
    frames = [encode(c).flat() for c in cut.pieces]
    pooled = np.concatenate(frames)
    mean, sd = pooled.mean(axis=0), pooled.std(axis=0)
    scale = np.maximum(sd, 1e-3 * sd.max())
    current, previous = _triples([(f - mean) / scale for f in frames])
    return TrainingFrames(
        current,
        previous,
        mean,
        scale,
        starts=np.stack([f[:2] for f, first in zip(frames, cut.starts_clip) if first]),
        start_places=[root_start(c) for c, first in zip(cut.pieces, cut.starts_clip) if first],
        flips=cut.flips,
        fps=float(fps),
        max_turn_speed=max_turn_speed,
    )


def frame_loader(current: np.ndarray, previous: np.ndarray, batch_size: int, shuffle: bool, num_workers: int = 0):
    """A ``torch`` DataLoader of frame triples as ``{"current": [B, F], "previous": [B, 2, F]}`` float32 batches
    (the :class:`~mocapkit.synthesis.module.MotionVAEModule`'s); with ``shuffle`` (training) drawn every epoch."""
    import torch

    data = torch.utils.data.TensorDataset(
        torch.tensor(current, dtype=torch.float32), torch.tensor(previous, dtype=torch.float32)
    )
    return torch.utils.data.DataLoader(
        data,
        batch_size=int(batch_size),
        shuffle=shuffle,
        drop_last=False,
        collate_fn=_batch,
        num_workers=num_workers,
        persistent_workers=num_workers > 0,
    )


def _batch(items: list[tuple]) -> dict:
    """One batch dict of :func:`frame_loader` (a module-level function: workers pickle it)."""
    import torch

    return {"current": torch.stack([i[0] for i in items]), "previous": torch.stack([i[1] for i in items])}


def vae_module(
    data: TrainingFrames, latent: int, hidden: int, layers: int, lr: float, beta: float, condition_noise: float
):
    """A fresh :class:`~mocapkit.synthesis.module.MotionVAEModule` (Adam) for ``data``'s features; the module keeps
    ``data``'s standardisation (:meth:`TrainingFrames.describe`) in its hyper-parameters."""
    from mocapkit.synthesis.module import MotionVAEModule

    return MotionVAEModule(
        model={
            "_target_": "mocapkit.models.motion_vae.MotionVAE",
            "latent": int(latent),
            "hidden": int(hidden),
            "layers": int(layers),
        },
        optimizer={"_target_": "torch.optim.Adam", "_partial_": True, "lr": float(lr), "fused": True},
        beta=float(beta),
        condition_noise=float(condition_noise),
        frames=data.describe(),
    )


__all__ = ["CVAESynthesizer", "TrainingFrames", "frame_loader", "training_frames", "vae_module"]
