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


#: Kinect v2 / NTU RGB+D 25-joint layout (Shahroudy et al. 2016). The parents follow
#: the CTR-GCN bone list, rooted at SpineBase.
NTU25 = SkeletonLayout(
    name="ntu25",
    joint_names=(
        "SpineBase",
        "SpineMid",
        "Neck",
        "Head",
        "ShoulderLeft",
        "ElbowLeft",
        "WristLeft",
        "HandLeft",
        "ShoulderRight",
        "ElbowRight",
        "WristRight",
        "HandRight",
        "HipLeft",
        "KneeLeft",
        "AnkleLeft",
        "FootLeft",
        "HipRight",
        "KneeRight",
        "AnkleRight",
        "FootRight",
        "SpineShoulder",
        "HandTipLeft",
        "ThumbLeft",
        "HandTipRight",
        "ThumbRight",
    ),
    parents=(
        -1,
        0,
        20,
        2,
        20,
        4,
        5,
        6,
        20,
        8,
        9,
        10,
        0,
        12,
        13,
        14,
        0,
        16,
        17,
        18,
        1,
        7,
        7,
        11,
        11,
    ),
)


#: MSR Action3D's own 20-joint order (shared/samples/SOURCES.md, section msr3d), rooted at HipCenter.
#: Left/right within each pair follow the usual reading of the dataset (Vemulapalli et al.'s
#: skeleton code); the MSR reader's tests check the sides against the data.
MSR20 = SkeletonLayout(
    name="msr20",
    joint_names=(
        "ShoulderLeft",
        "ShoulderRight",
        "ShoulderCenter",
        "Spine",
        "HipLeft",
        "HipRight",
        "HipCenter",
        "ElbowLeft",
        "ElbowRight",
        "WristLeft",
        "WristRight",
        "HandLeft",
        "HandRight",
        "KneeLeft",
        "KneeRight",
        "AnkleLeft",
        "AnkleRight",
        "FootLeft",
        "FootRight",
        "Head",
    ),
    parents=(2, 2, 3, 6, 6, 6, -1, 0, 1, 7, 8, 9, 10, 4, 5, 13, 14, 15, 16, 2),
)

#: The CMU / HDM05 ASF skeleton with 31 joints (root plus 30 bones), in the usual ASF order.
CMU31 = SkeletonLayout(
    name="cmu31",
    joint_names=(
        "root",
        "lhipjoint",
        "lfemur",
        "ltibia",
        "lfoot",
        "ltoes",
        "rhipjoint",
        "rfemur",
        "rtibia",
        "rfoot",
        "rtoes",
        "lowerback",
        "upperback",
        "thorax",
        "lowerneck",
        "upperneck",
        "head",
        "lclavicle",
        "lhumerus",
        "lradius",
        "lwrist",
        "lhand",
        "lfingers",
        "lthumb",
        "rclavicle",
        "rhumerus",
        "rradius",
        "rwrist",
        "rhand",
        "rfingers",
        "rthumb",
    ),
    parents=(
        -1,
        0,
        1,
        2,
        3,
        4,
        0,
        6,
        7,
        8,
        9,
        0,
        11,
        12,
        13,
        14,
        15,
        13,
        17,
        18,
        19,
        20,
        21,
        20,
        13,
        24,
        25,
        26,
        27,
        28,
        27,
    ),
)

#: Limb landmarks of both Kinect layouts (v2 ``ntu25`` and v1 ``msr20`` name the limb joints alike).
_KINECT_LIMBS = {
    "l_shoulder": "ShoulderLeft",
    "l_elbow": "ElbowLeft",
    "l_wrist": "WristLeft",
    "l_hand": "HandLeft",
    "r_shoulder": "ShoulderRight",
    "r_elbow": "ElbowRight",
    "r_wrist": "WristRight",
    "r_hand": "HandRight",
    "l_hip": "HipLeft",
    "l_knee": "KneeLeft",
    "l_ankle": "AnkleLeft",
    "l_foot": "FootLeft",
    "r_hip": "HipRight",
    "r_knee": "KneeRight",
    "r_ankle": "AnkleRight",
    "r_foot": "FootRight",
}

#: Body landmarks shared across layouts: landmark -> joint name in each layout. A joint's
#: position in an ASF skeleton is the *end* of the bone of that name (e.g. CMU ``lfemur`` ends
#: at the left knee), which is what forward kinematics returns for that joint.
LANDMARKS: dict[str, dict[str, str]] = {
    "ntu25": {"pelvis": "SpineBase", "spine": "SpineMid", "neck": "SpineShoulder", "head": "Head", **_KINECT_LIMBS},
    "msr20": {"pelvis": "HipCenter", "spine": "Spine", "neck": "ShoulderCenter", "head": "Head", **_KINECT_LIMBS},
    "cmu31": {
        "pelvis": "root",
        "spine": "upperback",
        "neck": "lowerneck",
        "head": "head",
        "l_shoulder": "lclavicle",
        "l_elbow": "lhumerus",
        "l_wrist": "lradius",
        "l_hand": "lhand",
        "r_shoulder": "rclavicle",
        "r_elbow": "rhumerus",
        "r_wrist": "rradius",
        "r_hand": "rhand",
        "l_hip": "lhipjoint",
        "l_knee": "lfemur",
        "l_ankle": "ltibia",
        "l_foot": "lfoot",
        "r_hip": "rhipjoint",
        "r_knee": "rfemur",
        "r_ankle": "rtibia",
        "r_foot": "rfoot",
    },
}

LAYOUTS = {layout.name: layout for layout in (NTU25, MSR20, CMU31)}


def get_layout(layout: SkeletonLayout | str) -> SkeletonLayout:
    """``layout`` itself, or the layout of that name in :data:`LAYOUTS` (``"ntu25"``, ``"msr20"``, ``"cmu31"``)."""
    if isinstance(layout, SkeletonLayout):
        return layout
    if layout not in LAYOUTS:
        raise ValueError(f"unknown skeleton layout {layout!r}; known: {sorted(LAYOUTS)}")
    return LAYOUTS[layout]


def hip_joints(joint_names, layout_name: str | None = None) -> tuple[int, int] | None:
    """``(left, right)`` hip joint indices of a skeleton, for heading alignment; None when they cannot be told.

    Known layouts use :data:`LANDMARKS` (``l_hip`` / ``r_hip``); other skeletons (BVH rigs) are matched by name:
    a joint whose lower-case name contains ``upleg``, ``upperleg``, ``thigh`` or ``hip`` and a left / right mark
    (``left`` / ``right``, a ``_l`` / ``_r`` suffix or an ``l`` / ``r`` prefix).
    """
    names = list(joint_names)
    table = LANDMARKS.get(layout_name or "")
    if table and table["l_hip"] in names and table["r_hip"] in names:
        return names.index(table["l_hip"]), names.index(table["r_hip"])
    found = {}
    for i, name in enumerate(names):
        low = name.lower()
        if not any(k in low for k in ("upleg", "upperleg", "thigh", "hip")) or low in ("hips", "hip"):
            continue
        if (
            "left" in low
            or low.endswith(("_l", ".l"))
            or low.startswith(("l_", "left"))
            or low[:1] == "l"
            and "hip" in low[1:4]
        ):
            found.setdefault("l", i)
        elif (
            "right" in low
            or low.endswith(("_r", ".r"))
            or low.startswith(("r_", "right"))
            or low[:1] == "r"
            and "hip" in low[1:4]
        ):
            found.setdefault("r", i)
    return (found["l"], found["r"]) if "l" in found and "r" in found else None


#: The 20 body landmarks of :data:`LANDMARKS`, in one order, with their tree (parent landmark index, -1 for the
#: pelvis): the skeleton on which layout-independent features (retrieval) are computed.
LANDMARK_NAMES: tuple[str, ...] = (
    "pelvis",
    "spine",
    "neck",
    "head",
    "l_shoulder",
    "l_elbow",
    "l_wrist",
    "l_hand",
    "r_shoulder",
    "r_elbow",
    "r_wrist",
    "r_hand",
    "l_hip",
    "l_knee",
    "l_ankle",
    "l_foot",
    "r_hip",
    "r_knee",
    "r_ankle",
    "r_foot",
)
LANDMARK_PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 2, 4, 5, 6, 2, 8, 9, 10, 0, 12, 13, 14, 0, 16, 17, 18)

#: Landmark → lower-case joint-name stems of common BVH rigs (Bandai Namco ``UpperArm_L``, Mixamo and CMU-BVH
#: ``LeftArm`` / ``LeftForeArm`` / ``LeftUpLeg``, the CMU BVH rig's ``LeftHip`` / ``LeftKnee`` / ``LeftShoulder``
#: / ``LeftElbow``, ...), first match wins. A BVH joint sits at the *start* of its
#: bone, so the "upper arm" joint is the shoulder, the "forearm" joint the elbow, the "hand" joint the wrist.
_RIG_STEMS: dict[str, tuple[str, ...]] = {
    "pelvis": ("hips", "hip", "pelvis", "root", "jointroot"),
    "spine": ("spine", "spine1", "chest", "torso"),
    "neck": ("neck", "neck1"),
    "head": ("head",),
    "shoulder": ("upperarm", "arm", "shoulder"),
    "elbow": ("lowerarm", "forearm", "elbow"),
    "wrist": ("hand", "wrist"),
    "hand": ("handend", "hand", "wrist"),
    "hip": ("upperleg", "upleg", "thigh", "hip"),  # "hip": CMU BVH's LeftHip (after LHipJoint, the pelvis bone)
    "knee": ("lowerleg", "leg", "shin", "calf", "knee"),
    "ankle": ("foot", "ankle"),
    "foot": ("toes", "toe", "toebase", "toesend", "foot"),
}


def _rig_side(name: str) -> tuple[str | None, str]:
    """``("l" | "r" | None, stem)``: the side mark of a rig joint name and the name without it (lower case); a
    namespace before a colon (Mixamo's ``mixamorig:LeftUpLeg``) is dropped."""
    low = name.lower().replace(" ", "")
    if ":" in low and low.rsplit(":", 1)[1] not in ("l", "r"):
        low = low.rsplit(":", 1)[1]
    for side, words in (("l", ("left",)), ("r", ("right",))):
        for word in words:
            if word in low:
                return side, low.replace(word, "").strip("_.:")
        for suffix in (f"_{side}", f".{side}", f":{side}"):
            if low.endswith(suffix):
                return side, low[: -len(suffix)]
        for prefix in (f"{side}_", f"{side}."):
            if low.startswith(prefix):
                return side, low[len(prefix) :]
    return None, low.replace("_", "")


def mirror_joints(joint_names) -> list[int]:
    """The left-right counterpart of every joint: ``result[j]`` is the index of joint ``j``'s mirror image (``j``
    itself for a joint on the mid-line), an involution.

    A counterpart shares the name's stem and has the other side mark: ``Left`` / ``Right``, ``_L`` / ``_R``,
    ``L_`` / ``R_`` (BVH rigs, :func:`_rig_side`), or a one-letter ``l`` / ``r`` prefix as in ASF skeletons
    (``lhumerus`` / ``rhumerus``: the name with its first letter swapped must be a joint too, so ``lowerback`` and
    ``root`` stay themselves). A side-marked joint without a counterpart raises ``ValueError`` naming it.
    """
    names = list(joint_names)
    parsed = [_rig_side(name) for name in names]
    index = {name.lower(): i for i, name in enumerate(names)}
    result = list(range(len(names)))
    for j, (side, stem) in enumerate(parsed):
        if side is not None:
            other = "r" if side == "l" else "l"
            match = [i for i, (s, st) in enumerate(parsed) if s == other and st == stem]
            if not match:
                raise ValueError(
                    f"joint {names[j]!r} is marked {'left' if side == 'l' else 'right'} but no joint "
                    f"is its counterpart (stem {stem!r}); cannot mirror this skeleton"
                )
            result[j] = match[0]
        elif names[j][:1].lower() in ("l", "r"):
            swapped = ("r" if names[j][:1].lower() == "l" else "l") + names[j][1:].lower()
            result[j] = index.get(swapped, j)
    if any(result[result[j]] != j for j in range(len(names))):
        raise ValueError(f"joints {names}: the left-right counterparts are not one-to-one; cannot mirror this skeleton")
    return result


def find_landmarks(joint_names, layout_name: str | None = None) -> dict[str, int]:
    """Landmark name → joint index of a skeleton, for every landmark of :data:`LANDMARK_NAMES` it has.

    Known layouts (``ntu25``, ``msr20``, ``cmu31``: Kinect, HDM05 and CMU) use :data:`LANDMARKS`; other skeletons
    (BVH rigs) are matched by joint name (:data:`_RIG_STEMS`, with ``Left``/``Right``, ``_L``/``_R`` or
    ``L_``/``R_`` side marks). A landmark the skeleton lacks is absent from the result.
    """
    names = list(joint_names)
    table = LANDMARKS.get(layout_name or "")
    if table:
        return {lm: names.index(joint) for lm, joint in table.items() if joint in names}
    parsed = [_rig_side(name) for name in names]
    found: dict[str, int] = {}
    for landmark in LANDMARK_NAMES:
        side, _, part = landmark.partition("_") if "_" in landmark else (None, "", landmark)
        for stem in _RIG_STEMS[part]:
            match = [i for i, (s, st) in enumerate(parsed) if s == side and st.replace("_", "") == stem]
            if match:
                found[landmark] = match[0]
                break
    return found
