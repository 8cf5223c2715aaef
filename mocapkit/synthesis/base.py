"""The one contract of every motion-variation synthesiser (Zhou 2014 ch. 4 and its baselines).

A synthesiser is a scikit-learn estimator (parameters stored untouched in ``__init__``, learned state in
attributes ending in ``_``, ``NotFittedError`` before ``fit``) with two methods:

``fit(clips) -> self``
    about ten example clips of **one motion type**: a sequence of :class:`~mocapkit.motion.container.Motion`
    read from ASF/AMC (:func:`~mocapkit.datasets.formats.asf_amc.read_amc`), so that each carries its raw joint
    angles in ``metadata["amc_values"]`` and its skeleton in ``metadata["asf"]``; BVH clips go through
    :func:`as_amc_clips` first (an exact conversion to ASF/AMC on one T-pose rest). The clips may come from
    different performers (different bone lengths) but must share one bone hierarchy and the same dofs per bone.
``sample(n_variants, n_frames=None, seed=None) -> list[Motion]``
    ``n_variants`` new clips of ``n_frames`` frames each (default: the mean training length), drawn with
    ``seed``. Each is an AMC motion on the **reference skeleton** (the first training clip's ASF; override with
    the ``skeleton`` argument of :meth:`MotionSynthesizer.sample`), made with
    :func:`~mocapkit.datasets.formats.asf_amc.amc_motion`, so :func:`~mocapkit.datasets.formats.asf_amc.write_amc`
    writes it, ``read_amc`` reads it back and ``mocapkit render`` draws it.

Subclasses implement ``_fit_clips(clips)`` and ``_sample_values(n_variants, n_frames, rng)`` (one dict
bone → ``[n_frames, len(dof)]`` AMC values per variant, angles in degrees, root translation in ASF units).
The shared checks (AMC clips, one hierarchy, enough clips, long enough clips), the packing of AMC values into one
matrix (:func:`dof_matrix`, :func:`dof_values`) and its resampling in time (:func:`time_warp`,
:func:`resample_clip`, for methods that model a lower frame rate than the data's) live here.
"""

from __future__ import annotations

import sys
from collections.abc import Sequence

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

from mocapkit.datasets.formats.asf_amc import AsfSkeleton, amc_motion
from mocapkit.motion.container import Motion
from mocapkit.synthesis.clips import DofLayout, SynthesisInputError, check_clips, check_flag, on_skeleton, smooth_values


class MotionSynthesizer(BaseEstimator):
    """Base class of variation synthesisers (see the module docstring).

    **Footskate cleanup**, one for every synthesiser that has the parameters ``footskate_cleanup`` (bool) and
    ``footskate_root`` (one of :data:`~mocapkit.synthesis.footskate.ROOT_MOVES`, default
    :data:`~mocapkit.synthesis.footskate.DEFAULT_ROOT_MOVE`): :meth:`sample` passes each variant through
    :func:`~mocapkit.synthesis.footskate.cleanup_footskate` on the output skeleton, with the floor ``floor_``
    that :meth:`fit` measured on the training clips (the mean over the clips of their lowest ankle height,
    metres) and ``move_root=footskate_root``; ``footskate_reports_`` then holds one
    :class:`~mocapkit.synthesis.footskate.FootskateReport` per variant (empty without the cleanup). A
    synthesiser without those parameters (the training-clip reference) is never cleaned.

    **Smoothing**, one for every synthesiser that has the parameter ``smoothing_seconds`` (≥ 0): before the cleanup,
    :meth:`sample` low-passes each variant's AMC values in time (:func:`smooth_values`, a Gaussian of that standard
    deviation in seconds; 0 = off). Sampled frames carry frame-to-frame noise that no real clip has (jerk, and feet
    that tremble during a stance); the smoothing takes it out before the cleanup looks for stances. The default,
    :data:`SMOOTHING_SECONDS`, was chosen on training clips only (its docstring). With ``noise_scale="auto"`` the
    scale is chosen on smoothed variants, so the smoothing does not lower the variation asked for.

    **Noise scale**, one for every synthesiser that has the parameters ``noise_scale`` (a number ≥ 0, or
    ``"auto"``) and ``target_variation``: its random draws are multiplied by the scale. With ``"auto"``,
    :meth:`_set_noise_scale` (called at the end of ``_fit_clips``) tries the class's ``noise_scales``, smallest
    first, and keeps the first whose ``auto_variants`` variants vary at least ``target_variation`` times as much as
    the training clips (V of Zhou eq. 4.5, :func:`~mocapkit.synthesis.metrics.variation`, the training clips
    posed on the reference skeleton), the largest when none does. Only training clips are used.

    Class attributes: ``min_clips`` (fewest training clips), ``min_frames`` (shortest training clip, frames),
    ``noise_scales`` and ``auto_variants`` (what ``noise_scale="auto"`` tries).
    """

    min_clips = 2
    min_frames = 4
    noise_scales: tuple[float, ...] = ()
    auto_variants = 10

    def fit(self, clips: Sequence[Motion]) -> MotionSynthesizer:
        clips = list(clips)
        self.layout_ = check_clips(clips, self.min_clips, self.min_frames, what=f"{type(self).__name__}.fit")
        self.skeleton_ = clips[0].metadata["asf"]
        self.fps_ = float(clips[0].fps)
        self.mean_frames_ = round(float(np.mean([len(c.positions) for c in clips])))
        if hasattr(self, "footskate_cleanup"):
            from mocapkit.synthesis.footskate import planted_ankle_height

            self._cleans_feet()  # checks the parameters before a long fit
            self.floor_ = planted_ankle_height(clips)
        self._smoothing_seconds()
        self._fit_clips(clips)
        return self

    def _cleans_feet(self) -> bool:
        """Whether :meth:`sample` runs the footskate cleanup (class docstring); checks its parameters."""
        if not hasattr(self, "footskate_cleanup"):
            return False
        from mocapkit.synthesis.footskate import ROOT_MOVES

        cleans = check_flag(self, "footskate_cleanup")
        if self.footskate_root not in ROOT_MOVES:
            raise ValueError(
                f"{type(self).__name__}: footskate_root must be one of {list(ROOT_MOVES)}, got {self.footskate_root!r}"
            )
        return cleans

    def _smoothing_seconds(self) -> float:
        """The Gaussian smoothing's standard deviation in seconds (class docstring; 0 without the parameter);
        checks it."""
        seconds = getattr(self, "smoothing_seconds", 0.0)
        if isinstance(seconds, (str, bool)) or not float(seconds) >= 0:
            raise ValueError(
                f"{type(self).__name__}: smoothing_seconds must be a number >= 0 (seconds), got {seconds!r}"
            )
        return float(seconds)

    def sample(
        self, n_variants: int, n_frames: int | None = None, seed: int | None = None, skeleton: AsfSkeleton | None = None
    ) -> list[Motion]:
        """``n_variants`` new clips of ``n_frames`` frames (default: the mean training length) on ``skeleton``
        (default: the first training clip's)."""
        if not hasattr(self, "layout_"):
            raise NotFittedError(f"{type(self).__name__} is not fitted: call fit(clips) first")
        if n_variants < 1:
            raise ValueError(f"n_variants must be >= 1, got {n_variants}")
        n_frames = self.mean_frames_ if n_frames is None else int(n_frames)
        if n_frames < 1:
            raise ValueError(f"n_frames must be >= 1, got {n_frames}")
        skeleton = self.skeleton_ if skeleton is None else skeleton
        if DofLayout.of(skeleton) != self.layout_:
            raise SynthesisInputError(
                f"sample: skeleton {skeleton.source or skeleton.name} does not match the training clips' bones/dofs"
            )
        rng = np.random.default_rng(seed)
        cleans = self._cleans_feet()
        smoothing = self._smoothing_seconds()
        out, self.footskate_reports_ = [], []
        for k, values in enumerate(self._sample_values(n_variants, n_frames, rng)):
            if smoothing > 0:
                values = smooth_values(values, self.layout_, self.fps_, smoothing)
            if cleans:
                from mocapkit.synthesis.footskate import cleanup_footskate

                values, report = cleanup_footskate(
                    values, skeleton, self.fps_, floor=self.floor_, move_root=self.footskate_root
                )
                self.footskate_reports_.append(report)
            out.append(
                amc_motion(
                    skeleton, values, fps=self.fps_, angle_unit="deg", name=f"{type(self).__name__}_variant_{k:03d}"
                )
            )
        return out

    # ------------------------------------------------------------------ noise scale
    def _check_noise_scale(self) -> None:
        """A ValueError naming the class unless ``noise_scale`` is ``"auto"`` or a number ≥ 0."""
        scale = self.noise_scale
        if scale != "auto" and (isinstance(scale, str) or not float(scale) >= 0):
            raise ValueError(f"{type(self).__name__}: noise_scale must be 'auto' or a number >= 0, got {scale!r}")

    def _noise_scale(self) -> float:
        """The scale sampling uses: ``noise_scale`` when a number (so it can change after ``fit``), else the one
        ``fit`` chose."""
        if isinstance(self.noise_scale, str):
            return self.noise_scale_
        return float(self.noise_scale)

    def _set_noise_scale(self, clips: list[Motion]) -> None:
        """``noise_scale_``: the given scale, or with ``"auto"`` the one chosen on the training ``clips`` (class
        docstring); ``variation_by_noise_scale_`` keeps each tried scale's ``V / V_train``."""
        from mocapkit.synthesis.metrics import variation

        self.variation_by_noise_scale_ = {}
        if self.noise_scale != "auto":
            self.noise_scale_ = float(self.noise_scale)
            return
        reference = variation([on_skeleton(clip, self.skeleton_) for clip in clips]).v
        for scale in self.noise_scales:
            self.noise_scale_ = scale
            ratio = variation(self.sample(self.auto_variants, seed=self.random_state)).v / reference
            self.variation_by_noise_scale_[scale] = ratio
            if getattr(self, "verbose", False):
                print(
                    f"[{type(self).__name__}] noise_scale {scale}: V / V_train = {ratio:.2f} "
                    f"(target {self.target_variation})",
                    file=sys.stderr,
                    flush=True,
                )
            if ratio >= self.target_variation:
                break

    # ------------------------------------------------------------------ subclasses
    def _fit_clips(self, clips: list[Motion]) -> None:
        raise NotImplementedError

    def _sample_values(self, n_variants: int, n_frames: int, rng: np.random.Generator) -> list[dict[str, np.ndarray]]:
        raise NotImplementedError
