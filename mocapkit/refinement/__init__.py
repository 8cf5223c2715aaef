"""Motion refinement (gap filling and denoising of mocap): the refiner contract (``base``), the classical refiners
(``gap_filling``, ``svt``, ``lrmf``, ``trnn``, ``psc``, ``filter_bases``, ``dynammo``, ``pose_prior``), the learned
ones behind the same contract (``learned``: trained networks from a checkpoint or an ONNX file), the running-median
outlier screen any of them can stand behind (``screening``), the seeded corruption protocols they are tested and
trained on (``corruptions``), ``mocapkit refine`` (``apply``), the training windows (``datamodule``), metrics,
``mocapkit eval`` of a refiner run (``evaluate``) and the benchmark (``benchmark``)."""

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

__all__ = [
    "PROTOCOLS",
    "Corruption",
    "CorruptionError",
    "LearnedRefiner",
    "MedianScreen",
    "MotionRefiner",
    "OnnxRefiner",
    "ProtocolInfo",
    "RefinementError",
    "check_motion",
    "corrupt",
    "median_outliers",
    "motion_matrix",
    "training_corruption",
]
