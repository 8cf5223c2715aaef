"""Learned refiners behind the one refiner contract: ``fit(motions)`` and ``refine(motion) -> Motion``.

:class:`LearnedRefiner` wraps a network of :mod:`mocapkit.models.refiners`:

- ``LearnedRefiner(checkpoint="RUN/best.ckpt")`` loads a trained run (``mocapkit train experiment=refine_bigru``);
  with a list of checkpoints, ``fit(motions)`` picks the one trained on exactly the groups (performers) of
  ``motions`` — how the comparison runner's leave-one-performer-out folds use runs trained per fold, and checks
  that no run saw its fold's test performer;
- ``LearnedRefiner(experiment="refine_bigru")`` trains in ``fit(motions)`` with that experiment's recipe.

:class:`OnnxRefiner` runs an exported refiner (``mocapkit export``) with onnxruntime and numpy only.

Both refine a take of any length in overlapping windows (``window`` frames, by default
:data:`INFERENCE_WINDOW_FACTOR` times the training window; ``overlap`` frames shared by neighbours, blended with
linear ramps), all windows in one batch. What they do
not invent: frames in which **every** joint is missing before the first or after the last observed frame, and
interior runs of such frames longer than ``max_empty_frames``, stay missing and are reported as unfilled.
Observed entries come back bit-identical unless the network moves them by more than ``repair_threshold``
(metres): those are the repaired outliers / noisy samples of the contract (``mocapkit refine`` writes them only
with ``--repair-outliers``).

A motion whose joints are those of the training layout in another order (a C3D whose point labels are the
joint names, with or without extra markers) is refined on those joints; extra markers come back untouched. A take
in another frame than the run's (``up_axis_``, ``fps_``: a z-up lab C3D given to a model trained on y-up HDM05) is
turned and resampled to it and back, as every fixed-sampling refiner does
(:meth:`~mocapkit.refinement.base.MotionRefiner.refine`); positions are metres whatever the file's units.
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from mocapkit.motion.container import Motion, point_distance
from mocapkit.motion.frames import refine_windows, true_runs
from mocapkit.refinement.base import MotionRefiner, RefinementError

#: Default inference window in training windows. Both networks run on any length, and with twice the training
#: window they filled long gaps better on the runs' validation clips (training performers only; 2 s gaps: 32 → 25 cm
#: RMS) at the cost of up to 0.3 mm under 20 % random loss for the transformer
#: (``scripts/selection/refiner_inference_settings.py --setting window``; docs/decisions.md#refiner-inference-window).
INFERENCE_WINDOW_FACTOR = 2

#: Default ``short_gap_frames``: interior gaps of up to 24 frames (0.2 s at 120 fps) are filled by the cubic spline,
#: longer ones by the network. Chosen on the runs' validation clips (training performers only; values 0, 4, 8, 12,
#: 24; mean RMS over random loss 0.2 / 0.5 and 10-, 20-, 40-frame gaps: 8.41 → 8.11 mm for the BiGRU, 8.40 → 8.11
#: for the transformer; ``scripts/selection/refiner_inference_settings.py --setting short_gaps``;
#: docs/decisions.md#refiner-short-gaps).
SHORT_GAP_FRAMES = 24

#: Default ``short_gap_points``: the short-gap spline passes through the take's samples with the ones the network
#: repairs at its values. Chosen on the same validation clips with ``mxcrypt`` (gaps in noisy data) added to the
#: protocols, after the test table showed the spline through the raw samples losing there (mean RMS over the six
#: protocols: BiGRU 10.18 mm without the spline, 10.82 through the observed samples, 10.09 through the repaired ones;
#: transformer 10.27, 10.81, 10.10; ``--setting short_gap_points``; docs/decisions.md#refiner-short-gap-points).
SHORT_GAP_POINTS = "repaired"


# ------------------------------------------------------------------------------------------ windows (numpy only)
def short_gaps(missing: np.ndarray, longest: int) -> np.ndarray:
    """bool ``[T, J]``: the missing entries in interior gaps (a joint observed before and after) of at most
    ``longest`` consecutive frames."""
    out = np.zeros_like(missing)
    if longest <= 0:
        return out
    for j in np.flatnonzero(missing.any(axis=0)):
        for a, b in true_runs(missing[:, j]):  # [a, b)
            if a > 0 and b < len(missing) and b - a <= longest:
                out[a:b, j] = True
    return out


def spline_fill(positions: np.ndarray, missing: np.ndarray, fill: np.ndarray) -> np.ndarray:
    """``positions [T, J, 3]`` with the entries ``fill [T, J]`` (interior gaps) from a cubic spline (scipy
    ``CubicSpline``, not-a-knot) through every observed frame of their joint, as
    :class:`~mocapkit.refinement.gap_filling.SplineInterpolation` fills them (that module imports torch; this one is
    on the onnxruntime-only path of :class:`OnnxRefiner`)."""
    from scipy.interpolate import CubicSpline

    out = np.array(positions, dtype=np.float64)
    t = np.arange(len(positions), dtype=np.float64)
    for j in np.flatnonzero(fill.any(axis=0)):
        seen = ~missing[:, j]
        if seen.sum() >= 2:
            out[fill[:, j], j] = CubicSpline(t[seen], out[seen, j], extrapolate=False)(t[fill[:, j]])
    return out


def empty_frames_kept(missing: np.ndarray, max_empty_frames: int) -> np.ndarray:
    """bool ``[T]``: frames with every joint missing that stay unfilled (leading, trailing, or in an interior run
    longer than ``max_empty_frames``)."""
    empty = missing.all(axis=1)
    keep = np.zeros_like(empty)
    observed = np.flatnonzero(~empty)
    if observed.size == 0:
        return empty
    keep[: observed[0]] = True
    keep[observed[-1] + 1 :] = True
    start = None
    for t in range(observed[0], observed[-1] + 2):
        if t <= observed[-1] and empty[t]:
            start = t if start is None else start
        elif start is not None:
            if t - start > max_empty_frames:
                keep[start:t] = True
            start = None
    return keep


# ------------------------------------------------------------------------------------------ the refiners
class _WindowedRefiner(MotionRefiner):
    """Shared by :class:`LearnedRefiner` and :class:`OnnxRefiner`: layout matching, windows, repairs, reports."""

    requires_fit = True
    fixed_sampling = True
    min_frames = 2

    def _predict(self, positions: np.ndarray, missing: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def _set_skeleton(self, skeleton: dict) -> None:
        self.skeleton_ = dict(skeleton)
        self.joint_names_ = tuple(skeleton["joint_names"])
        self.fps_, self.up_axis_ = float(skeleton["fps"]), str(skeleton["up_axis"])
        self.window_ = int(self.window or INFERENCE_WINDOW_FACTOR * int(skeleton.get("window") or 120))
        self.overlap_ = int(self.window_ // 4 if self.overlap is None else self.overlap)
        if not 0 <= self.overlap_ < self.window_:
            raise ValueError(f"{type(self).__name__}: overlap={self.overlap_} must be in [0, window={self.window_})")

    def refine(self, motion: Motion) -> Motion:
        """See :class:`~mocapkit.refinement.base.MotionRefiner` and the module docstring."""
        trained = getattr(self, "joint_names_", None)
        if (
            trained is not None
            and tuple(motion.joint_names) != tuple(trained)
            and set(trained) <= set(motion.joint_names)
        ):
            order = [motion.joint_names.index(name) for name in trained]
            sub = replace(
                motion,
                positions=motion.positions[:, order],
                missing=motion.missing[:, order],
                joint_names=tuple(trained),
                parents=None,
                rotations=None,
                layout_name=None,
            )
            done = super().refine(sub)
            positions, missing = motion.positions.copy(), motion.missing.copy()
            positions[:, order], missing[:, order] = done.positions, done.missing
            return replace(
                motion,
                positions=positions,
                missing=missing,
                rotations=None,
                metadata={**motion.metadata, "refinement": done.metadata["refinement"]},
            )
        return super().refine(motion)

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray):
        frames = X.shape[0]
        joints = X.shape[1] // 3
        positions = X.reshape(frames, joints, 3)
        missing = ~observed.reshape(frames, joints, 3)[..., 0]
        refined = refine_windows(self._predict, positions, missing, self.window_, self.overlap_)
        moved = point_distance(refined, positions)
        repaired = ~missing & (moved > float(self.repair_threshold))
        if self.short_gap_frames:
            if self.short_gap_points not in ("observed", "repaired"):
                raise ValueError(
                    f"{type(self).__name__}: short_gap_points must be 'observed' or 'repaired', got "
                    f"{self.short_gap_points!r}"
                )
            short = short_gaps(missing, int(self.short_gap_frames))
            through = (
                positions if self.short_gap_points == "observed" else np.where(repaired[..., None], refined, positions)
            )
            refined[short] = spline_fill(through, missing, short)[short]
        refined[empty_frames_kept(missing, int(self.max_empty_frames))] = np.nan
        return refined.reshape(frames, 3 * joints), repaired


class LearnedRefiner(_WindowedRefiner):
    """A refiner network of :mod:`mocapkit.models.refiners`; see the module docstring.

    Args:
        checkpoint: a run's checkpoint, or a list of them (``fit`` picks the one trained on the fit motions'
            groups); None: ``fit`` trains with ``experiment``.
        experiment: the training recipe ``fit`` uses when ``checkpoint`` is None (``configs/experiment/NAME``).
        overrides: Hydra overrides of that recipe (e.g. ``["trainer.max_epochs=5"]``).
        window: frames per window (None: :data:`INFERENCE_WINDOW_FACTOR` × the training window). overlap: frames
            shared by neighbouring windows (None: a quarter of the window).
        repair_threshold: an observed entry the network moves farther than this (metres) is replaced (repaired).
        short_gap_frames: interior gaps of a joint up to this many frames are filled by the cubic spline
            (:class:`~mocapkit.refinement.gap_filling.SplineInterpolation`) instead of the network (default
            :data:`SHORT_GAP_FRAMES`, chosen on validation clips); 0: every gap by the network.
        short_gap_points: the samples that spline passes through: ``"observed"`` (the take's own) or
            ``"repaired"`` (the take's, with the samples the network repairs replaced by its values; default
            :data:`SHORT_GAP_POINTS`, chosen on validation clips).
        max_empty_frames: interior runs of frames with every joint missing up to this long are filled.
        device: torch device of the network.
        first_guess: None (the network's own) or keyword arguments of the network's ``set_first_guess``, e.g.
            ``{"tangents": "zero", "extrapolate": 0}``: the first guess of runs trained before those options
            (:class:`~mocapkit.models.refiners.BiGRURefiner`).
    """

    def __init__(
        self,
        checkpoint: str | Sequence[str] | None = None,
        experiment: str | None = None,
        overrides: Sequence[str] = (),
        window: int | None = None,
        overlap: int | None = None,
        repair_threshold: float = 0.02,
        max_empty_frames: int = 12,
        device: str = "cpu",
        first_guess: dict | None = None,
        short_gap_frames: int = SHORT_GAP_FRAMES,
        short_gap_points: str = SHORT_GAP_POINTS,
    ):
        self.checkpoint = checkpoint
        self.experiment = experiment
        self.overrides = overrides
        self.window = window
        self.overlap = overlap
        self.repair_threshold = repair_threshold
        self.max_empty_frames = max_empty_frames
        self.device = device
        self.first_guess = first_guess
        self.short_gap_frames = short_gap_frames
        self.short_gap_points = short_gap_points

    # -------------------------------------------------------------- loading / training
    @staticmethod
    def _load(path: str | Path):
        from mocapkit.train.checkpoints import (
            parse_checkpoint,
            read_checkpoint_bytes,
            restore_error_detail,
        )
        from mocapkit.train.refine_module import MotionRefinementModule

        raw = read_checkpoint_bytes(path)
        checkpoint = parse_checkpoint(raw, path)
        if "skeleton" not in checkpoint.get("hyper_parameters", {}):
            raise RefinementError(
                f"{path}: not a refiner checkpoint (no skeleton in its hyper-parameters); train one "
                "with `mocapkit train experiment=refine_bigru`"
            )
        try:
            return MotionRefinementModule.load_from_checkpoint(io.BytesIO(raw), map_location="cpu", weights_only=True)
        except Exception as exc:  # weights of another network version, hyper-parameters the class does not take
            raise RefinementError(f"{path}: cannot restore the refiner from it: {restore_error_detail(exc)}") from exc

    def _use(self, module) -> None:
        self.module_ = module.to(self.device).eval()
        if self.first_guess is not None:
            self.module_.model.set_first_guess(**dict(self.first_guess))
        self._set_skeleton(module.hparams.skeleton)

    def fit(self, motions: Sequence[Motion] | None = None, y=None) -> LearnedRefiner:
        """Load the checkpoint trained on the groups of ``motions`` (or the only one), or train on ``motions``."""
        motions = list(motions or [])
        if self.checkpoint is not None:
            paths = [self.checkpoint] if isinstance(self.checkpoint, (str, Path)) else list(self.checkpoint)
            modules = [(p, self._load(p)) for p in paths]
            groups = sorted({str(m.metadata.get("group")) for m in motions if m.metadata.get("group") is not None})
            if len(modules) == 1 and not groups:
                self._use(modules[0][1])
                return self
            for path, module in modules:
                if sorted(module.hparams.skeleton.get("train_groups") or []) == groups:
                    self._use(module)
                    self.checkpoint_used_ = str(path)
                    return self
            trained = {str(p): m.hparams.skeleton.get("train_groups") for p, m in modules}
            raise RefinementError(
                f"LearnedRefiner.fit: no checkpoint was trained on exactly the groups {groups} of "
                f"the fit motions (checkpoints and their training groups: {trained})"
            )
        if not self.experiment:
            raise ValueError("LearnedRefiner: give checkpoint= (a trained run) or experiment= (a recipe to train)")
        if not motions:
            raise ValueError("LearnedRefiner.fit needs training motions (experiment= trains on them)")
        self._use(train_on_motions(self.experiment, motions, list(self.overrides)))
        return self

    def _predict(self, positions: np.ndarray, missing: np.ndarray) -> np.ndarray:
        import torch

        with torch.inference_mode():
            out = self.module_(torch.from_numpy(positions).to(self.device), torch.from_numpy(missing).to(self.device))
        return out.cpu().numpy()


def train_on_motions(experiment: str, motions: Sequence[Motion], overrides: Sequence[str] = ()):
    """Train ``configs/experiment/<experiment>`` on clean ``motions`` (validation: a seeded fraction of them); the
    LightningModule with the weights of the best validation epoch."""
    import tempfile

    import lightning as L
    from lightning.pytorch.callbacks import ModelCheckpoint

    from mocapkit.train.config import compose_config
    from mocapkit.train.training import build

    cfg = compose_config([f"experiment={experiment}", "logger=none", *overrides])
    L.seed_everything(int(cfg.seed), workers=True, verbose=False)
    # the motions are passed to the built partial, not to instantiate: Hydra merges instantiate's keyword arguments
    # into the config, which turns dataclasses (Motion) into plain dicts
    datamodule = build(cfg.data, _partial_=True, seed=cfg.seed)(motions=list(motions))
    module = build(cfg.module, **datamodule.label_spaces())
    with tempfile.TemporaryDirectory() as folder:
        best = ModelCheckpoint(dirpath=folder, filename="best", monitor="val/mje_cm", mode="min")
        trainer = L.Trainer(
            max_epochs=int(cfg.trainer.max_epochs),
            accelerator=cfg.trainer.accelerator,
            devices=1,
            logger=False,
            callbacks=[best],
            enable_progress_bar=False,
            enable_model_summary=False,
            gradient_clip_val=cfg.trainer.get("gradient_clip_val"),
        )
        trainer.fit(module, datamodule=datamodule)
        return LearnedRefiner._load(best.best_model_path)


class OnnxRefiner(_WindowedRefiner):
    """An exported refiner (``mocapkit export`` of a refiner run) run with onnxruntime and numpy only.

    Args:
        path: the ``.onnx`` file (its metadata holds the layout, frame rate, up axis and training window).
        window, overlap, repair_threshold, max_empty_frames, short_gap_frames, short_gap_points: as
            :class:`LearnedRefiner`.
        threads: onnxruntime intra-op threads (0: its default).
    """

    def __init__(
        self,
        path: str,
        window: int | None = None,
        overlap: int | None = None,
        repair_threshold: float = 0.02,
        max_empty_frames: int = 12,
        threads: int = 0,
        short_gap_frames: int = SHORT_GAP_FRAMES,
        short_gap_points: str = SHORT_GAP_POINTS,
    ):
        self.path = path
        self.window = window
        self.overlap = overlap
        self.repair_threshold = repair_threshold
        self.max_empty_frames = max_empty_frames
        self.threads = threads
        self.short_gap_frames = short_gap_frames
        self.short_gap_points = short_gap_points

    def fit(self, motions: Sequence[Motion] | None = None, y=None) -> OnnxRefiner:
        """Open the session and read the layout from the file's metadata (``motions`` are not needed)."""
        import json

        from mocapkit.deploy.runtime import cpu_session

        path = Path(self.path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such ONNX file")
        try:
            self.session_ = cpu_session(path, int(self.threads))
        except Exception as exc:
            raise RefinementError(f"{path}: onnxruntime cannot load it: {exc}") from exc
        meta = self.session_.get_modelmeta().custom_metadata_map
        if "mocapkit_skeleton" not in meta:
            raise RefinementError(
                f"{path}: not a mocapkit refiner export (no mocapkit_skeleton metadata); export "
                "one with `mocapkit export ckpt_path=RUN/best.ckpt`"
            )
        self._set_skeleton(json.loads(meta["mocapkit_skeleton"]))
        return self

    def _predict(self, positions: np.ndarray, missing: np.ndarray) -> np.ndarray:
        return self.session_.run(
            ["refined"], {"positions": positions.astype(np.float32), "missing": missing.astype(bool)}
        )[0]


__all__ = [
    "INFERENCE_WINDOW_FACTOR",
    "SHORT_GAP_FRAMES",
    "SHORT_GAP_POINTS",
    "LearnedRefiner",
    "OnnxRefiner",
    "empty_frames_kept",
    "short_gaps",
    "spline_fill",
    "train_on_motions",
]
