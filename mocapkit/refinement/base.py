"""The one contract of every motion refiner, classical or learned.

A refiner is a scikit-learn estimator (parameters stored untouched in ``__init__``, learned state
in attributes ending in ``_``) with two methods:

``fit(motions)``
    learn from clean training motions (a sequence of :class:`~mocapkit.motion.container.Motion`
    of one skeleton layout); a no-op for methods that need no training data. Returns ``self``.
``refine(motion) -> Motion``
    a new Motion in which every entry that ``motion.missing`` marks is filled and, for the robust
    methods, every outlier the method detects is repaired. Observed entries that the method does
    not flag come back **bit-identical**; frames or joints it cannot fill (a marker missing in every
    frame, gaps beyond what the method can do) stay missing and are listed in
    ``out.metadata["refinement"]["unfilled"]``, never invented silently.

A refiner whose learned model depends on the frame rate (``fixed_sampling``: the windowed networks, PSC, filter
bases) refines a take at another rate at its own: the take is resampled to the fitted rate
(:meth:`~mocapkit.motion.container.Motion.resample`, linear), refined there, and the result interpolated
linearly back to the take's own frames, where it fills the missing entries; observed entries come back
bit-identical (outliers are not repaired on that path) and ``metadata["refinement"]["resampled"]`` records both
rates. A take with another up axis is turned to the fitted one (:func:`~mocapkit.motion.geometry.turn_up_axis`: the right-handed turns of
:func:`~mocapkit.motion.geometry.to_y_up`, exact because they only permute and negate coordinates), refined there
(resampled too if its rate differs) and turned back, so observed entries stay bit-identical and repairs are kept;
``metadata["refinement"]["turned"]`` records both axes. Units need no conversion: a
:class:`~mocapkit.motion.container.Motion` is in metres whatever its file used (``source_units``).

Subclasses implement :meth:`MotionRefiner._refine_matrix` on the frames × (3·joints) matrix, in
float64 metres, and set ``requires_fit = True`` when ``fit`` must come first. The shared checks
(finite observed values, at least one observed entry, fitted layout) live here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from sklearn.base import BaseEstimator
from sklearn.exceptions import NotFittedError

from mocapkit.motion.container import Motion, all_coordinates
from mocapkit.motion.geometry import turn_up_axis


class RefinementError(ValueError):
    """A motion a refiner cannot work on; the message names the motion (file), markers and frames."""


def motion_matrix(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """``motion`` as the matrix of the theses' low-rank methods.

    Returns:
        ``(X, observed)``: float64 ``[frames, 3·joints]`` metres (joint-major: columns ``3j, 3j+1, 3j+2``
        are x, y, z of joint ``j``; 0 where missing) and bool ``[frames, 3·joints]``, True where observed.
    """
    frames, joints = motion.positions.shape[:2]
    observed = np.repeat(~motion.missing, 3, axis=1)
    X = np.where(observed, motion.positions.reshape(frames, 3 * joints), 0.0).astype(np.float64)
    return X, observed


def check_motion(motion: Motion, min_frames: int = 1, what: str = "refine") -> None:
    """Reject what no refiner can work on, naming the file, markers and frames.

    Raises:
        RefinementError: fewer than ``min_frames`` frames, no observed entry at all, or NaN / Inf
            in an entry that is not marked missing (a Motion marks both missing when it is built; this
            catches values written into ``positions`` afterwards).
    """
    label = motion.source or motion.name or "motion"
    if not isinstance(motion, Motion):
        raise TypeError(f"{what}: expected a Motion, got {type(motion).__name__}")
    if motion.num_frames < min_frames:
        raise RefinementError(f"{label}: {motion.num_frames} frames, {what} needs at least {min_frames}")
    if motion.missing.all():
        raise RefinementError(f"{label}: every entry is missing, nothing to refine from")
    bad = ~all_coordinates(np.isfinite(motion.positions)) & ~motion.missing
    if bad.any():
        frame, joint = np.argwhere(bad)[0]
        raise RefinementError(
            f"{label}: non-finite value at frame {frame} of marker {motion.joint_names[joint]!r} "
            f"({int(bad.sum())} such entries); mark them missing (NaN) or remove them"
        )


class MotionRefiner(BaseEstimator):
    """Base class of the refiners: input checks, the matrix view and the merge of observed entries."""

    #: True when :meth:`fit` must be called before :meth:`refine` (data-driven methods).
    requires_fit: bool = False
    #: Fewest frames the method can work on.
    min_frames: int = 2
    #: True when the learned model depends on the frame rate and up axis (window-based data-driven methods):
    #: ``fit`` then requires one of each (recorded as ``fps_``, ``up_axis_``) and ``refine`` brings a take to them.
    fixed_sampling: bool = False

    def fit(self, motions: Sequence[Motion] | None = None, y=None) -> MotionRefiner:
        """Learn from clean ``motions`` (all of one layout); records ``joint_names_``. A no-op otherwise."""
        motions = list(motions or [])
        if self.requires_fit and not motions:
            raise ValueError(f"{type(self).__name__}.fit needs at least one training motion")
        if motions:
            names = motions[0].joint_names
            for m in motions[1:]:
                if m.joint_names != names:
                    raise RefinementError(
                        f"{m.source or m.name}: joints {list(m.joint_names)[:4]}... differ from the "
                        f"first training motion's; fit one refiner per skeleton layout"
                    )
            self.joint_names_ = names
            if self.fixed_sampling:
                fps, up = {float(m.fps) for m in motions}, {m.up_axis for m in motions}
                if len(fps) > 1 or len(up) > 1:
                    raise RefinementError(
                        f"{type(self).__name__}.fit: training motions mix frame rates {sorted(fps)} "
                        f"or up axes {sorted(up)}; resample them to one rate first"
                    )
                self.fps_, self.up_axis_ = fps.pop(), up.pop()
        self._fit_matrices([motion_matrix(m) for m in motions]) if motions else None
        return self

    def _fit_matrices(self, data: list[tuple[np.ndarray, np.ndarray]]) -> None:
        """Learn from ``[(X, observed), ...]`` (see :func:`motion_matrix`); data-driven methods override."""

    def refine(self, motion: Motion) -> Motion:
        """``motion`` with its missing entries filled (and detected outliers repaired); see the module docstring."""
        check_motion(motion, self.min_frames, what=type(self).__name__)
        if self.requires_fit:
            if not hasattr(self, "joint_names_"):
                raise NotFittedError(f"{type(self).__name__} is not fitted: call fit(training_motions) first")
            if tuple(motion.joint_names) != tuple(self.joint_names_):
                absent = [n for n in self.joint_names_ if n not in motion.joint_names]
                raise RefinementError(
                    f"{motion.source or motion.name}: {type(self).__name__} was fitted on another "
                    f"skeleton layout (missing joints: {absent[:8]}{'...' if len(absent) > 8 else ''})"
                )
        if self.fixed_sampling and hasattr(self, "fps_"):
            if motion.up_axis != self.up_axis_:
                return self._refine_turned(motion)
            if float(motion.fps) != self.fps_:
                return self._refine_resampled(motion)
        X, observed = motion_matrix(motion)
        filled, repaired = self._refine_matrix(X, observed)
        frames, joints = motion.positions.shape[:2]
        filled = np.asarray(filled, dtype=np.float64).reshape(frames, joints, 3)
        repaired = np.zeros((frames, joints), bool) if repaired is None else np.asarray(repaired, bool)
        still_missing = motion.missing & ~all_coordinates(np.isfinite(filled))
        replace_mask = (motion.missing | repaired) & ~still_missing
        positions = motion.positions.copy()
        positions[replace_mask] = filled[replace_mask].astype(np.float32)
        positions[still_missing] = np.nan
        unfilled = {motion.joint_names[j]: int(still_missing[:, j].sum()) for j in np.flatnonzero(still_missing.any(0))}
        report = {
            "method": type(self).__name__,
            "filled": int((motion.missing & ~still_missing).sum()),
            "repaired": int((repaired & ~motion.missing).sum()),
            "unfilled": unfilled,
        }
        return replace(
            motion, positions=positions, missing=still_missing, metadata={**motion.metadata, "refinement": report}
        )

    def _refine_turned(self, motion: Motion) -> Motion:
        """Refine ``motion`` turned to the fitted up axis ``up_axis_`` and turn the result back (the module
        docstring)."""
        turned = replace(
            motion,
            positions=turn_up_axis(motion.positions, motion.up_axis, self.up_axis_),
            up_axis=self.up_axis_,
            rotations=None,  # local rotations are not turned; no refiner reads them
        )
        done = self.refine(turned)
        report = {
            **done.metadata["refinement"],
            "turned": {"up_axis": motion.up_axis, "refined_at_up_axis": self.up_axis_},
        }
        return replace(
            motion,
            positions=turn_up_axis(done.positions, self.up_axis_, motion.up_axis),
            missing=done.missing,
            metadata={**motion.metadata, "refinement": report},
        )

    def _refine_resampled(self, motion: Motion) -> Motion:
        """Refine ``motion`` at the fitted rate ``fps_`` and bring the filled entries back to its own frames (the
        module docstring)."""
        label = motion.source or motion.name or "motion"
        at_rate = motion.resample(self.fps_)
        if at_rate.num_frames < self.min_frames:
            raise RefinementError(
                f"{label}: {motion.num_frames} frames at {motion.fps:g} fps are "
                f"{at_rate.num_frames} at the {self.fps_:g} fps {type(self).__name__} was fitted "
                f"at; it needs at least {self.min_frames}"
            )
        done = self.refine(at_rate)
        # back at the take's own frames (their times in the refined take's frame units)
        back = done.sample_at(np.arange(motion.num_frames) * (self.fps_ / float(motion.fps)), motion.fps)
        fill = motion.missing & ~back.missing
        positions = motion.positions.copy()
        positions[fill] = back.positions[fill]
        still_missing = motion.missing & ~fill
        positions[still_missing] = np.nan
        unfilled = {motion.joint_names[j]: int(still_missing[:, j].sum()) for j in np.flatnonzero(still_missing.any(0))}
        report = {
            **done.metadata["refinement"],
            "filled": int(fill.sum()),
            "repaired": 0,
            "unfilled": unfilled,
            "resampled": {
                "fps": float(motion.fps),
                "refined_at_fps": float(self.fps_),
                "note": "refined at the fitted rate, interpolated back; observed samples kept",
            },
        }
        return replace(
            motion, positions=positions, missing=still_missing, metadata={**motion.metadata, "refinement": report}
        )

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """Fill ``X`` (float64 ``[frames, 3·joints]``, 0 where not ``observed``).

        Returns:
            ``(filled, repaired)``: the completed matrix (NaN where the method cannot fill) and a bool
            ``[frames, joints]`` mask of observed entries the method flags as outliers and replaces
            (None for methods that only fill gaps).
        """
        raise NotImplementedError
