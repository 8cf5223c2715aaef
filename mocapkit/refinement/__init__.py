"""Motion refinement: the refiner contract (``base``) that classical (:mod:`mocapkit.classical`) and
learned refiners share, and the seeded corruption protocols (``corruptions``) they are tested on."""
from mocapkit.refinement.base import (
           MotionRefiner,
           RefinementError,
           check_motion,
           motion_matrix,
)
from mocapkit.refinement.corruptions import (
           PROTOCOLS,
           Corruption,
           CorruptionError,
           ProtocolInfo,
           corrupt,
)

__all__ = ["PROTOCOLS", "Corruption", "CorruptionError", "MotionRefiner", "ProtocolInfo", "RefinementError",
           "check_motion", "corrupt", "motion_matrix"]
