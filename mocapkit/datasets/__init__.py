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
from mocapkit.datasets.format_errors import MotionFormatError
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
    "Motion", "MotionFormatError", "read_motion", "write_motion", "C3DFormatError", "read_c3d", "write_c3d",
    "AmcFormatError", "AsfFormatError", "read_amc", "read_asf", "write_amc", "write_asf",
    "BvhFormatError", "read_bvh", "write_bvh",
    "CMU31", "LAYOUTS", "MSR20", "NTU25", "SkeletonLayout", "NTUCache", "PrepareReport", "prepare_ntu", "BodySelection", "NTUSampleName",
    "SkeletonFormatError", "SkeletonSequence", "parse_ntu_name", "read_missing_list", "read_skeleton",
    "select_main_bodies", "sequence_from_positions", "write_skeleton", "SPLITS", "split_indices", "split_summary",
    "validation_split",
]
