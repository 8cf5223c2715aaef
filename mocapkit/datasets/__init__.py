"""Datasets: file formats, synthetic generators, evaluation protocols and data modules."""
from mocapkit.datasets.layouts import NTU25, SkeletonLayout
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

__all__ = [
    "NTU25", "SkeletonLayout", "BodySelection", "NTUSampleName", "SkeletonFormatError", "SkeletonSequence",
    "parse_ntu_name", "read_missing_list", "read_skeleton", "select_main_bodies", "sequence_from_positions",
    "write_skeleton",
]
