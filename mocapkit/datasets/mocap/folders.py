"""Folders of real motion capture: which files make up HDM05, CMU and Bandai, and how their clips are grouped.

=========  ==========================================================  ============================================
dataset    files under ``root``                                        group (the "performer" of a fold)
=========  ==========================================================  ============================================
``hdm05``  ``<actor>/HDM_<actor>_<class>_<nnn>_<fps>.amc`` (+ ASF)     the actor (bd, bk, dg, mm)
           or the generator's ``<class>_<actor>_<nnn>.amc``
``cmu``    ``NN_MM.amc`` + ``NN.asf``                                  the subject ``NN`` (01, 02, 03)
``bandai`` ``data/dataset-1_<content>_<style>_<nnn>.bvh``              the **style** (15): neither the file names nor
                                                                       the JSON labels say which actor performed a
                                                                       take, so a Bandai fold holds out a style
=========  ==========================================================  ============================================

The layout of ``../shared/data`` (and its SOURCES.md) is what these patterns follow; HDM05 and CMU share the
31-joint ASF skeleton (``cmu31``), Bandai has its own 22-joint BVH skeleton.
"""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

DATASETS = ("hdm05", "cmu", "bandai")
#: How each data set's files are found and grouped (see the module docstring).
FILE_PATTERNS = {
    "hdm05": "HDM_<actor>_<class>_<nnn>_<fps>.amc or <class>_<actor>_<nnn>.amc, with HDM_<actor>.asf",
    "cmu": "NN_MM.amc with NN.asf beside it",
    "bandai": "dataset-1_<content>_<style>_<nnn>.bvh",
}


class MocapFolderError(ValueError):
    """A folder that does not hold the data set it is said to hold (names the folder and the expected files)."""


def list_clips(dataset: str, root: str | Path) -> list[dict]:
    """``[{"path", "name", "group", "class"}]`` of the clips of ``dataset`` under ``root``, sorted by path.

    Raises:
        MocapFolderError: unknown data set, a missing folder, or no file of the data set's pattern (names the folder).
    """
    if dataset not in DATASETS:
        raise MocapFolderError(f"dataset={dataset!r}: one of {list(DATASETS)}")
    root = Path(root)
    if not root.is_dir():
        raise MocapFolderError(f"root={str(root)!r} is not a folder (dataset {dataset}: {FILE_PATTERNS[dataset]})")
    clips = []
    if dataset == "hdm05":
        from mocapkit.datasets.mocap.hdm05_classes import parse_clip_name

        for path in sorted(root.rglob("*.amc")):
            try:
                name = parse_clip_name(path, strict=False)
            except ValueError:
                continue
            clips.append({"path": path, "name": path.stem, "group": name.actor, "class": name.cls})
    elif dataset == "cmu":
        for path in sorted(root.rglob("*.amc")):
            match = re.fullmatch(r"(\d+)_(\d+)", path.stem)
            if match:
                clips.append({"path": path, "name": path.stem, "group": match.group(1), "class": path.stem})
    else:
        for path in sorted(root.rglob("*.bvh")):
            parts = path.stem.split("_")
            if len(parts) == 4 and parts[0].startswith("dataset"):
                clips.append({"path": path, "name": path.stem, "group": parts[2], "class": parts[1]})
    if not clips:
        raise MocapFolderError(f"root={str(root)!r}: no {dataset} clip found ({FILE_PATTERNS[dataset]})")
    return clips


def read_clips(clips: list[dict], fps: float | None = None, progress: bool = False) -> list:
    """The :class:`~mocapkit.motion.container.Motion` of every clip of :func:`list_clips` (positions in
    metres, rotations dropped), resampled to ``fps`` when given, ``metadata["group"]`` / ``["class"]`` set.

    Raises:
        MocapFolderError: a file that does not read (names it) or a clip whose joints differ from the first's.
    """
    from mocapkit.datasets.formats.motion_io import read_motion

    motions = []
    for n, clip in enumerate(clips, 1):
        try:
            motion = read_motion(clip["path"])
        except Exception as exc:
            raise MocapFolderError(f"cannot read {clip['path']}: {exc}") from exc
        if fps is not None:
            motion = motion.resample(float(fps))
        motion = replace(
            motion, rotations=None, metadata={**motion.metadata, "group": clip["group"], "class": clip["class"]}
        )
        if motions and motion.joint_names != motions[0].joint_names:
            raise MocapFolderError(
                f"{clip['path']} has joints {list(motion.joint_names)[:5]}..., not those of "
                f"{clips[0]['path']}; one skeleton layout per data set"
            )
        motions.append(motion)
        if progress and (n % 50 == 0 or n == len(clips)):
            print(f"[mocapkit] read {n}/{len(clips)} clips", flush=True)
    return motions


def held_out_groups(
    groups, test_groups=None, train_groups=None, dataset: str = "", root=None
) -> tuple[list[str], list[str]]:
    """``(train, test)`` groups of a fold: ``test_groups`` (one group or a list; None: the first of ``groups``) and
    ``train_groups`` (None: every other group), checked against ``groups`` (the data's groups, sorted).

    Raises:
        MocapFolderError: a named group the data does not have, or a group on both sides (names them).
    """
    groups = [str(g) for g in groups]
    if test_groups is None:
        test = groups[:1]
    else:
        test = [str(g) for g in ([test_groups] if isinstance(test_groups, (str, int)) else test_groups)]
    unknown = [g for g in [*test, *(train_groups or [])] if str(g) not in groups]
    if unknown:
        raise MocapFolderError(
            f"data.test_groups / data.train_groups: {unknown} are not groups of {dataset} under "
            f"{root} (groups: {groups})"
        )
    train = [str(g) for g in train_groups] if train_groups else [g for g in groups if g not in test]
    overlap = sorted(set(train) & set(test))
    if overlap:
        raise MocapFolderError(f"data.train_groups and data.test_groups share {overlap}")
    return train, test
