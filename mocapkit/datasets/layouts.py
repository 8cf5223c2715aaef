"""Skeleton layouts: joint names and the kinematic tree (parent of each joint).

A layout is all a method needs to know about a skeleton's topology: the graph
model builds its adjacency from ``parents``, the energy image rasterises the
bones ``(joint, parent)``, and readers attach a layout to every sequence.
Joint indices are 0-based everywhere in mocapkit.
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SkeletonLayout:
    """A named skeleton topology.

    Attributes:
        name: short identifier, e.g. ``"ntu25"``.
        joint_names: one name per joint, in storage order.
        parents: parent index of each joint, ``-1`` for the root.
    """

    name: str
    joint_names: tuple[str, ...]
    parents: tuple[int, ...]

    def __post_init__(self) -> None:
        if len(self.joint_names) != len(self.parents):
            raise ValueError(f"layout {self.name!r}: {len(self.joint_names)} names but {len(self.parents)} parents")
        roots = [j for j, p in enumerate(self.parents) if p < 0]
        if len(roots) != 1:
            raise ValueError(f"layout {self.name!r} must have exactly one root, found {roots}")

    @property
    def num_joints(self) -> int:
        return len(self.joint_names)

    @property
    def bones(self) -> tuple[tuple[int, int], ...]:
        """``(child, parent)`` pairs, one per non-root joint."""
        return tuple((j, p) for j, p in enumerate(self.parents) if p >= 0)

    def index(self, name: str) -> int:
        """Index of the joint called ``name`` (``KeyError`` naming it if absent)."""
        try:
            return self.joint_names.index(name)
        except ValueError:
            raise KeyError(f"layout {self.name!r} has no joint {name!r}") from None


#: Kinect v2 / NTU RGB+D 25-joint layout (field-anchors §1.2). The parents follow
#: the CTR-GCN bone list, rooted at SpineBase.
NTU25 = SkeletonLayout(
    name="ntu25",
    joint_names=(
        "SpineBase", "SpineMid", "Neck", "Head",
        "ShoulderLeft", "ElbowLeft", "WristLeft", "HandLeft",
        "ShoulderRight", "ElbowRight", "WristRight", "HandRight",
        "HipLeft", "KneeLeft", "AnkleLeft", "FootLeft",
        "HipRight", "KneeRight", "AnkleRight", "FootRight",
        "SpineShoulder", "HandTipLeft", "ThumbLeft", "HandTipRight", "ThumbRight",
    ),
    parents=(
        -1, 0, 20, 2,
        20, 4, 5, 6,
        20, 8, 9, 10,
        0, 12, 13, 14,
        0, 16, 17, 18,
        1, 7, 7, 11, 11,
    ),
)
