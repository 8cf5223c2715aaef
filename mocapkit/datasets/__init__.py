"""Datasets: file formats, synthetic generators, evaluation protocols and data modules.

The data modules (Lightning) live in their own modules and are imported from there,
e.g. ``from mocapkit.datasets.ntu_datamodule import NTUDataModule``, so that the
format readers stay importable without torch.
"""
from mocapkit.datasets.asf_amc import (
    AmcFormatError,
    AsfFormatError,
    read_amc,
    read_asf,
    write_amc,
    write_asf,
)
from mocapkit.datasets.bvh import BvhFormatError, read_bvh, write_bvh
from mocapkit.datasets.c3d import C3DFormatError, read_c3d, write_c3d
from mocapkit.datasets.casia_b import (
    CONDITIONS,
    VIEWS,
    GaitSequence,
    GaitSequenceKey,
    SilhouetteFormatError,
    list_casia_b,
    read_sequence,
    read_silhouette,
)
from mocapkit.datasets.casia_b_prepare import prepare_casia_b
from mocapkit.datasets.format_errors import MotionFormatError
from mocapkit.datasets.gei import (
    GaitSequenceError,
    gait_energy_images,
    gait_period,
    normalize_silhouettes,
)
from mocapkit.datasets.gei_cache import GEICache
from mocapkit.datasets.layouts import CMU31, LAYOUTS, MSR20, NTU25, SkeletonLayout
from mocapkit.datasets.motion import Motion
from mocapkit.datasets.motion_io import read_motion, write_motion
from mocapkit.datasets.ntu_cache import NTUCache
from mocapkit.datasets.ntu_prepare import PrepareReport, prepare_ntu
from mocapkit.datasets.ntu_skeleton import (
    BodySelection,
    NTUSampleName,
    SkeletonFormatError,
    SkeletonSequence,
    parse_ntu_name,
    read_missing_list,
    read_skeleton,
    select_main_bodies,
    sequence_from_positions,
    write_skeleton,
)
from mocapkit.datasets.protocols import (
    SPLITS,
    split_indices,
    split_summary,
    validation_split,
)

__all__ = [
    "CMU31",
    "CONDITIONS",
    "LAYOUTS",
    "MSR20",
    "NTU25",
    "SPLITS",
    "VIEWS",
    "AmcFormatError",
    "AsfFormatError",
    "BodySelection",
    "BvhFormatError",
    "C3DFormatError",
    "GEICache",
    "GaitSequence",
    "GaitSequenceError",
    "GaitSequenceKey",
    "Motion",
    "MotionFormatError",
    "NTUCache",
    "NTUSampleName",
    "PrepareReport",
    "SilhouetteFormatError",
    "SkeletonFormatError",
    "SkeletonLayout",
    "SkeletonSequence",
    "gait_energy_images",
    "gait_period",
    "list_casia_b",
    "normalize_silhouettes",
    "parse_ntu_name",
    "prepare_casia_b",
    "prepare_ntu",
    "read_amc",
    "read_asf",
    "read_bvh",
    "read_c3d",
    "read_missing_list",
    "read_motion",
    "read_sequence",
    "read_silhouette",
    "read_skeleton",
    "select_main_bodies",
    "sequence_from_positions",
    "split_indices",
    "split_summary",
    "validation_split",
    "write_amc",
    "write_asf",
    "write_bvh",
    "write_c3d",
    "write_motion",
    "write_skeleton",
]
