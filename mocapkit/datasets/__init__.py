"""Datasets, by concern. Nothing imported here needs torch; the data modules are imported from
their packages (e.g. ``from mocapkit.datasets.ntu.datamodule import NTUDataModule``).

==================  =====================================================================
package / module    what it holds
==================  =====================================================================
``formats``         the :class:`Motion` container, ``read_motion`` / ``write_motion``, one
                    reader/writer per file format, skeleton layouts, the format errors
``synthetic``       stand-in generators written in the real formats (NTU, HDM05, CASIA-B)
``ntu``             NTU RGB+D preparation, cache, X-Sub/X-View/X-Set splits, data module
``msr_action3d``    MSR Action3D data set, its protocols, data module
``hdm05``           HDM05 class labellings and cross-actor splits
``casia_b``         Gait Energy Images, GEI cache, the two gait protocols, data module
``splits``          subject lists and validation hold-outs shared by every protocol
``datamodule``      the Lightning data-module bases (split + loaders; padded skeleton batches)
``augment``         skeleton training augmentation
==================  =====================================================================

This module re-exports the public API: the readers and writers, the caches and the preparation
functions.
"""

from mocapkit.datasets.casia_b.cache import GEICache
from mocapkit.datasets.casia_b.gei import (
    GaitSequenceError,
    gait_energy_images,
    gait_period,
    normalize_silhouettes,
)
from mocapkit.datasets.casia_b.prepare import prepare_casia_b
from mocapkit.datasets.formats.asf_amc import (
    AmcFormatError,
    AsfFormatError,
    read_amc,
    read_asf,
    write_amc,
    write_asf,
)
from mocapkit.datasets.formats.bvh import BvhFormatError, read_bvh, write_bvh
from mocapkit.datasets.formats.c3d import C3DFormatError, read_c3d, write_c3d
from mocapkit.datasets.formats.casia_b import (
    CONDITIONS,
    VIEWS,
    GaitSequence,
    GaitSequenceKey,
    SilhouetteFormatError,
    list_casia_b,
    read_sequence,
    read_silhouette,
)
from mocapkit.datasets.formats.errors import MotionFormatError
from mocapkit.datasets.formats.motion_io import read_motion, write_motion
from mocapkit.datasets.formats.ntu_skeleton import (
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
from mocapkit.datasets.ntu.cache import NTUCache
from mocapkit.datasets.ntu.prepare import PrepareReport, prepare_ntu
from mocapkit.datasets.ntu.splits import SPLITS, split_indices, split_summary
from mocapkit.datasets.splits import validation_split
from mocapkit.motion.container import Motion
from mocapkit.motion.layouts import CMU31, LAYOUTS, MSR20, NTU25, SkeletonLayout

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
