"""Motion refinement: the refiner contract (``base``) that classical (:mod:`mocapkit.classical`) and
learned refiners (``learned``: trained networks, from a checkpoint or an ONNX file) share, the running-median
outlier screen any of them can stand behind (``screening``), and the seeded
corruption protocols (``corruptions``) they are tested and trained on."""
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
           training_corruption,
)
from mocapkit.refinement.learned import LearnedRefiner, OnnxRefiner
from mocapkit.refinement.screening import MedianScreen, median_outliers

__all__ = ["PROTOCOLS", "Corruption", "CorruptionError", "LearnedRefiner", "MedianScreen", "MotionRefiner",
           "OnnxRefiner", "ProtocolInfo", "RefinementError", "check_motion", "corrupt", "median_outliers",
           "motion_matrix", "training_corruption"]
