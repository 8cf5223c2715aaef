"""Metrics of motion refinement: how close a refined motion is to the clean one on the corrupted entries.

An **entry** is one joint (marker) in one frame. All metrics compare a refined motion with the clean
(ground-truth) motion on a bool ``[frames, joints]`` mask of the entries that were corrupted (removed or
perturbed; see :class:`~mocapkit.refinement.corruptions.Corruption`). Entries the clean motion itself lacks
(missing in the ground truth) are never scored. Entries the refiner left unfilled (NaN) are not scored either;
they are counted in ``unfilled`` so that a method cannot look good by skipping the hard gaps (compare
``coverage`` before comparing errors).

- :func:`per_frame_rmse`: the theses' per-frame RMSE, Wang 2017 eq. 3.18 (= eq. 4.16 with the ground truth in
  place of the printed "imperfect" pose): ``RMSE_i = sqrt(‖X_i − X̂_i‖² / n_i)`` where ``n_i`` is the number
  of corrupted markers in frame ``i`` (missing markers in eq. 3.18, missing + noisy entries n_p in eq. 4.16).
  ``‖X_i − X̂_i‖²`` sums squared coordinate differences over the frame (numerator ``"frame"``, the literal
  equation) or over the corrupted entries only (``"corrupted"``); the two agree for refiners that keep the
  observed entries, as every gap filler does. It is the RMS of the per-marker 3-D error, in **cm**; ``NaN``
  in frames with ``n_i = 0``.
- :func:`sequence_rmse`: the per-sequence value of the thesis figures ("average RMSE per sequence", Fig. 3.7):
  the mean of the per-frame RMSE over the frames that have corrupted entries, cm.
- :func:`matrix_rmse`: Wang 2017 §4.2.3, ``‖(X − X̃)|Ω^c‖_F / sqrt(|Ω^c|)`` over the coordinates of the
  corrupted entries (|Ω^c| counts matrix entries, 3 per marker, so this is the per-marker value / √3), cm.
- :func:`mean_joint_error`: the mean 3-D Euclidean error over the corrupted entries, **mm** (MPJPE-style).
- :func:`score_refinement`: all of the above for a refined motion given its :class:`Corruption`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from mocapkit.motion.container import Motion, all_coordinates


def _arrays(clean: Motion | np.ndarray, refined: Motion | np.ndarray):
    a = clean.positions if isinstance(clean, Motion) else np.asarray(clean)
    b = refined.positions if isinstance(refined, Motion) else np.asarray(refined)
    if a.shape != b.shape or a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(
            f"clean and refined positions must both be [frames, joints, 3], got {list(a.shape)} and {list(b.shape)}"
        )
    if isinstance(clean, Motion) and isinstance(refined, Motion) and clean.joint_names != refined.joint_names:
        raise ValueError("clean and refined motions have different joints")
    return a.astype(np.float64), b.astype(np.float64)


def _scored(clean: np.ndarray, refined: np.ndarray, mask: np.ndarray) -> np.ndarray:
    mask = np.asarray(mask, bool)
    if mask.shape != clean.shape[:2]:
        raise ValueError(f"mask must be [frames, joints] = {list(clean.shape[:2])}, got {list(mask.shape)}")
    return mask & all_coordinates(np.isfinite(clean)) & all_coordinates(np.isfinite(refined))


def joint_errors(clean: Motion | np.ndarray, refined: Motion | np.ndarray) -> np.ndarray:
    """Euclidean 3-D error per entry, metres, float64 ``[frames, joints]`` (NaN where either side is missing)."""
    a, b = _arrays(clean, refined)
    return np.linalg.norm(a - b, axis=2)


def per_frame_rmse(
    clean: Motion | np.ndarray, refined: Motion | np.ndarray, mask: np.ndarray, numerator: str = "frame"
) -> np.ndarray:
    """Per-frame RMSE of Wang 2017 eq. 3.18 / 4.16 (see the module docstring), cm.

    Args:
        clean, refined: Motions or positions ``[frames, joints, 3]`` in metres.
        mask: bool ``[frames, joints]``, the corrupted entries (n_i = their count in frame i, scored ones only).
        numerator: ``"frame"`` (literal equation: squared error summed over every entry of the frame that both
            sides have) or ``"corrupted"`` (only the masked entries).

    Returns:
        float64 ``[frames]`` in cm; NaN in frames without a scored corrupted entry.
    """
    a, b = _arrays(clean, refined)
    scored = _scored(a, b, mask)
    squared = np.where(
        all_coordinates(np.isfinite(a)) & all_coordinates(np.isfinite(b)), ((a - b) ** 2).sum(axis=2), 0.0
    )
    if numerator == "frame":
        total = squared.sum(axis=1)
    elif numerator == "corrupted":
        total = (squared * scored).sum(axis=1)
    else:
        raise ValueError(f"numerator must be 'frame' or 'corrupted', got {numerator!r}")
    count = scored.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(count > 0, np.sqrt(total / np.maximum(count, 1)) * 100.0, np.nan)


def sequence_rmse(
    clean: Motion | np.ndarray, refined: Motion | np.ndarray, mask: np.ndarray, numerator: str = "frame"
) -> float:
    """Mean of :func:`per_frame_rmse` over the frames with corrupted entries, cm (NaN if there are none)."""
    curve = per_frame_rmse(clean, refined, mask, numerator)
    return float(np.nanmean(curve)) if np.isfinite(curve).any() else float("nan")


def matrix_rmse(clean: Motion | np.ndarray, refined: Motion | np.ndarray, mask: np.ndarray) -> float:
    """Wang 2017 §4.2.3: RMS over the coordinates of the corrupted entries, cm (NaN if none is scored)."""
    a, b = _arrays(clean, refined)
    scored = _scored(a, b, mask)
    if not scored.any():
        return float("nan")
    return float(np.sqrt(((a - b)[scored] ** 2).mean()) * 100.0)


def mean_joint_error(clean: Motion | np.ndarray, refined: Motion | np.ndarray, mask: np.ndarray) -> float:
    """Mean Euclidean 3-D error over the corrupted (e.g. missing) entries, mm (NaN if none is scored)."""
    a, b = _arrays(clean, refined)
    scored = _scored(a, b, mask)
    if not scored.any():
        return float("nan")
    return float(np.linalg.norm((a - b)[scored], axis=1).mean() * 1000.0)


@dataclass
class RefinementScore:
    """The scores of one refined motion (see :func:`score_refinement`). Units in the field names."""

    rmse_cm: float  # Wang eq. 3.18/4.16, averaged over frames with corrupted entries
    matrix_rmse_cm: float  # Wang §4.2.3
    mean_error_mm: float  # mean 3-D error over the corrupted entries
    mean_error_removed_mm: float  # ... over the removed entries only
    mean_error_perturbed_mm: float  # ... over the perturbed entries only
    rmse_curve_cm: np.ndarray  # float64 [frames], NaN where a frame has no corrupted entry
    corrupted: int  # corrupted entries with ground truth
    unfilled: int  # of those, left missing by the refiner (not scored)
    coverage: float  # 1 − unfilled / corrupted
    changed_clean: int  # uncorrupted observed entries the refiner changed (0 for gap fillers)
    protocol: str = ""
    level: object = None

    def as_dict(self, curve: bool = False) -> dict:
        """Plain-Python numbers (the per-frame curve only with ``curve=True``)."""
        out = asdict(self)
        out["rmse_curve_cm"] = self.rmse_curve_cm.tolist() if curve else None
        if not curve:
            del out["rmse_curve_cm"]
        return out


def score_refinement(refined: Motion, clean: Motion, corruption, numerator: str = "frame") -> RefinementScore:
    """Score ``refined`` against ``clean`` on the entries ``corruption`` removed or perturbed.

    Args:
        refined: the refiner's output for ``corruption.motion``.
        clean: the motion ``corruption`` was made from (same frames and joints).
        corruption: a :class:`~mocapkit.refinement.corruptions.Corruption`.
        numerator: see :func:`per_frame_rmse`.
    """
    a, b = _arrays(clean, refined)
    if corruption.removed.shape != a.shape[:2]:
        raise ValueError(
            f"the corruption is for {list(corruption.removed.shape)} entries, the motions have {list(a.shape[:2])}"
        )
    truth = all_coordinates(np.isfinite(a))
    corrupted = corruption.corrupted & truth
    filled = all_coordinates(np.isfinite(b))
    untouched = ~corruption.motion.missing & ~corruption.corrupted
    given = corruption.motion.positions[untouched]
    changed = int((~(refined.positions[untouched] == given).all(axis=1)).sum())
    count, unfilled = int(corrupted.sum()), int((corrupted & ~filled).sum())
    return RefinementScore(
        rmse_cm=sequence_rmse(a, b, corrupted, numerator),
        matrix_rmse_cm=matrix_rmse(a, b, corrupted),
        mean_error_mm=mean_joint_error(a, b, corrupted),
        mean_error_removed_mm=mean_joint_error(a, b, corruption.removed & truth),
        mean_error_perturbed_mm=mean_joint_error(a, b, corruption.perturbed & truth),
        rmse_curve_cm=per_frame_rmse(a, b, corrupted, numerator),
        corrupted=count,
        unfilled=unfilled,
        coverage=1.0 - unfilled / count if count else float("nan"),
        changed_clean=changed,
        protocol=corruption.protocol,
        level=corruption.level,
    )
