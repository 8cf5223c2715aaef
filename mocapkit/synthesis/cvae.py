"""A small modern learned generator for the variation benchmark: an autoregressive conditional VAE (MVAE-style)
over the thesis's pose features, trained in ``fit`` on the ~10 example clips.

**Features.** Each training clip is resampled to ``fps`` frames per second (every AMC channel time-warped
linearly, :func:`~mocapkit.synthesis.clips.resample_clip`; at 120 fps consecutive frames are nearly equal and an
autoregressive model learns to extrapolate and ignore its latent code) and encoded
(:func:`~mocapkit.synthesis.representation.encode`, ``FeatureClip.flat``: ``[T, 7 + 3B]``); every dimension is
z-scored over the training frames (sd floored at 1e-3 of the largest).

**Network and training.** :class:`~mocapkit.models.motion_vae.MotionVAE` (encoder ``q(z | x_t, x_{t−1})``,
decoder ``p(x_t | z, x_{t−1}, x_{t−2})``), trained by :class:`~mocapkit.synthesis.module.MotionVAEModule`
with a Lightning ``Trainer`` for ``steps`` optimiser steps of ``batch_size`` frame triples (Adam, learning rate
``lr``), on the CPU, no logger, no checkpoint written, seeded by ``random_state``
(``lightning.seed_everything``). ``loss_curve_`` keeps the loss of every step.

**Sampling.** Per variant the first two frames of a training clip drawn uniformly, then the decoder run
autoregressively with ``z = noise_scale · ε``, ``ε ~ N(0, I)``, at every step (a torch generator seeded from the
sampling seed), for the number of model-rate frames that spans ``n_frames`` at the training rate; the features are
decoded (:func:`~mocapkit.synthesis.representation.decode`, from the drawn clip's start position and heading) and
the AMC values resampled to ``n_frames`` by a cubic spline (:func:`~mocapkit.synthesis.clips.time_warp`: velocity
and acceleration stay continuous at the model's frames, where linear interpolation would kink).
"""
from __future__ import annotations

import time

import numpy as np

from mocapkit.motion.container import Motion
from mocapkit.synthesis.base import MotionSynthesizer
from mocapkit.synthesis.clips import SMOOTHING_SECONDS, dof_values, model_frames, resample_clip, rotation_columns, time_warp
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

    min_frames = 4
    noise_scales = (1.0, 1.5, 2.0, 3.0, 4.0, 6.0)

    def __init__(self, fps: float | None = 30.0, latent: int = 16, hidden: int = 256, layers: int = 2,
                 beta: float = 0.01, condition_noise: float = 0.05, steps: int = 400, batch_size: int = 256,
                 lr: float = 1e-3, max_turn_speed: float | None = 5400.0, random_state: int | None = 0,
                 footskate_cleanup: bool = True, footskate_root: str = DEFAULT_ROOT_MOVE,
                 smoothing_seconds: float = SMOOTHING_SECONDS, noise_scale: float | str = 1.0,
                 target_variation: float = 1.28):
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

    def _fit_clips(self, clips: list[Motion]) -> None:
        import lightning as L
        import torch

        from mocapkit.synthesis.module import MotionVAEModule

        if self.fps is not None and not float(self.fps) > 0:
            raise ValueError(f"CVAESynthesizer: fps={self.fps!r} must be positive (or None)")
        self._check_noise_scale()
        self.model_fps_ = self.fps_ if self.fps is None else float(self.fps)
        resampled = [resample_clip(clip, self.model_fps_) for clip in clips]
        short = [c for c in resampled if c.num_frames < 3]
        if short:
            raise ValueError(f"CVAESynthesizer.fit: {short[0].source or short[0].name} has {short[0].num_frames} "
                             f"frames at {self.model_fps_:g} fps; the model needs 3 (raise fps)")
        cut = continuous_pieces(clips, self.model_fps_, 3, self.max_turn_speed, what="CVAESynthesizer.fit")
        self.angle_flips_ = cut.flips
        frames = [encode(c).flat() for c in cut.pieces]
        pooled = np.concatenate(frames)
        self.mean_ = pooled.mean(axis=0)
        sd = pooled.std(axis=0)
        self.scale_ = np.maximum(sd, 1e-3 * sd.max())
        self.starts_ = np.stack([f[:2] for f, first in zip(frames, cut.starts_clip) if first])
        self.start_places_ = [root_start(c) for c, first in zip(cut.pieces, cut.starts_clip) if first]
        standard = [(f - self.mean_) / self.scale_ for f in frames]
        current = np.concatenate([s[2:] for s in standard])
        previous = np.concatenate([np.stack([s[1:-1], s[:-2]], axis=1) for s in standard])

        L.seed_everything(0 if self.random_state is None else int(self.random_state), workers=False, verbose=False)
        data = torch.utils.data.TensorDataset(torch.tensor(current, dtype=torch.float32),
                                              torch.tensor(previous, dtype=torch.float32))
        loader = torch.utils.data.DataLoader(data, batch_size=int(self.batch_size), shuffle=True, drop_last=False,
                                             collate_fn=lambda items: {"current": torch.stack([i[0] for i in items]),
                                                                       "previous": torch.stack([i[1] for i in items])})
        module = MotionVAEModule(
            model={"_target_": "mocapkit.models.motion_vae.MotionVAE", "features": current.shape[1],
                   "latent": int(self.latent), "hidden": int(self.hidden), "layers": int(self.layers)},
            optimizer={"_target_": "torch.optim.Adam", "_partial_": True, "lr": float(self.lr)},
            beta=float(self.beta), condition_noise=float(self.condition_noise))
        trainer = L.Trainer(max_steps=int(self.steps), max_epochs=-1, accelerator="cpu", devices=1,
                            logger=False, enable_checkpointing=False, enable_progress_bar=False,
                            enable_model_summary=False)
        start = time.perf_counter()
        trainer.fit(module, train_dataloaders=loader)
        self.train_seconds_ = time.perf_counter() - start
        self.loss_curve_ = np.asarray(module.loss_curve, dtype=np.float64)
        self.module_ = module.eval()
        self._set_noise_scale(clips)

    def _sample_values(self, n_variants: int, n_frames: int, rng: np.random.Generator) -> list[dict[str, np.ndarray]]:
        import torch

        chosen = rng.integers(len(self.starts_), size=n_variants)
        generator = torch.Generator().manual_seed(int(rng.integers(2 ** 63 - 1)))
        frames = max(model_frames(n_frames, self.fps_, self.model_fps_), 2)
        start = torch.tensor((self.starts_[chosen] - self.mean_) / self.scale_, dtype=torch.float32)
        generated = self.module_.model.rollout(start, frames, generator=generator,
                                               scale=self._noise_scale()).double().numpy()
        generated = generated * self.scale_ + self.mean_
        angles = rotation_columns(self.layout_)
        out = []
        for k, clip in enumerate(chosen):
            start_xz, start_yaw = self.start_places_[clip]
            values = decode(generated[k], self.skeleton_, start_xz=start_xz, start_yaw=start_yaw)
            matrix = np.concatenate([values[bone] for bone in self.layout_.bones], axis=1)
            out.append(dof_values(time_warp(matrix, n_frames, angles, kind="cubic"), self.layout_))
        return out


__all__ = ["CVAESynthesizer"]
