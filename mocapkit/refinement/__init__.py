"""Motion refinement: the refiner contract (``base``) that classical (:mod:`mocapkit.classical`) and
learned refiners share."""
from mocapkit.refinement.base import MotionRefiner, RefinementError, check_motion, motion_matrix

__all__ = ["MotionRefiner", "RefinementError", "check_motion", "motion_matrix"]
