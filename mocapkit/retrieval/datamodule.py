"""Training data of the learned motion embeddings: whole labelled clips as normalised landmarks, two views each.

:class:`RetrievalDataModule` reads HDM05 or Bandai clips (:mod:`mocapkit.datasets.mocap.folders`) or MSR Action3D
(:class:`~mocapkit.datasets.msr_action3d.dataset.MSRAction3D`), turns every clip into
:func:`~mocapkit.motion.geometry.normalised_landmarks` ``[T, 20, 3]`` once (``fps``, ``heading``), holds out
**groups** (performers) for testing and keeps a seeded, class-stratified fraction of the training groups' clips
for validation (checkpoint selection never sees a test performer):

==========  ===================================  =====================================================
dataset     label (``label``)                    group (held out by ``test_groups``)
==========  ===================================  =====================================================
``hdm05``   ``class`` (the motion class)         the actor (bd, bk, dg, mm)
``bandai``  ``content`` (= ``class``) or         no actor is known: the **style** when the label is the
            ``style``                            content, the **content** when the label is the style
``msr``     ``action`` (= ``class``)             the subject (``"1"`` ... ``"10"``)
``folder``  ``class``: the file's sub-folder     ``library``, one group: nothing is held out unless
            under ``root`` (``.`` at the top)    asked; a user's own library, any readable format, to
                                                 train a self-supervised embedding on what it will index
==========  ===================================  =====================================================

Every clip becomes ``frames`` frames by :func:`~mocapkit.retrieval.embedding.resample_frames` (what
:class:`~mocapkit.retrieval.embedding.EmbeddingRetrieval` does to a query). Training items are two views of a
clip, each augmented afresh at every access: a random temporal crop of ``crop`` (70–100 %) of the clip resampled
to ``frames``, a rotation about the vertical (±``rotation_deg``), a scale (``scale``) and Gaussian jitter of every
landmark (``jitter`` metres). There is no left/right mirroring: HDM05's classes have sides. Each training clip
appears ``repeats`` times per epoch.

What the second view shows (``positives``), without labels either way:

- ``same_clip``: the same clip (SimCLR's two views);
- ``dtw_neighbours``: the clip or one of its ``neighbours`` nearest training clips by DTW, drawn uniformly at each
  access (:func:`dtw_neighbours`). The embedding then learns DTW's neighbourhoods, not only the augmentations:
  a distillation of the label-free DTW search into an encoder that FAISS searches in milliseconds.

Validation and test items are the clips as they are (no augmentation), each flagged as a *query* or a *database*
clip, so that one loader gives a retrieval task:

- ``val``: queries = the validation clips; database = the training clips (of the training groups);
- ``test``: queries = the held-out groups' clips; database = every training-group clip (training and validation).

Batches are dicts::

    landmarks  float32 [B, frames, 20, 3]   the clip (training: the first augmented view)
    view2      float32 [B, frames, 20, 3]   training only: the second augmented view
    label      int64   [B]                  index into class_names
    group      int64   [B]                  index into groups["all"]
    query      bool    [B]                  validation / test: a query (True) or a database clip (False)
    index      int64   [B]                  the clip's index in its part
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import lightning as L
import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from mocapkit.datasets.datamodule import data_loader
from mocapkit.datasets.mocap.folders import MocapFolderError, held_out_groups
from mocapkit.motion.geometry import normalised_landmarks
from mocapkit.motion.layouts import LANDMARK_NAMES
from mocapkit.retrieval.embedding import resample_frames
from mocapkit.retrieval.frames import RaggedFrames, candidate_dtw

DATASETS = ("hdm05", "bandai", "msr", "folder")
#: Labels each data set offers (``class`` is the first one's alias).
LABELS = {"hdm05": ("class",), "bandai": ("content", "style"), "msr": ("action",), "folder": ("folder",)}
AUGMENT_KEYS = ("crop", "rotation_deg", "scale", "jitter")
#: ``data.positives``: what the second view of a training clip shows (module docstring).
POSITIVES = ("same_clip", "dtw_neighbours")


@dataclass
class Clip:
    """One clip: normalised landmarks ``[T, 20, 3]``, its label and group (strings) and its name."""

    landmarks: np.ndarray
    label: str
    group: str
    name: str


def read_labelled_clips(
    dataset: str, root: str, label: str = "class", fps: float = 30.0, heading: str = "frame"
) -> list[Clip]:
    """Every clip of ``dataset`` under ``root`` as a :class:`Clip` (see the module docstring for labels and groups)."""
    if dataset not in DATASETS:
        raise MocapFolderError(f"data.dataset={dataset!r}: one of {list(DATASETS)}")
    label = LABELS[dataset][0] if label == "class" else label
    if label not in LABELS[dataset]:
        raise ValueError(f"data.label={label!r}: {dataset} offers {['class', *LABELS[dataset]]}")
    if dataset == "msr":
        from mocapkit.datasets.msr_action3d.dataset import ACTION_NAMES, MSRAction3D

        data = MSRAction3D(root)
        return [
            Clip(normalised_landmarks(m, fps=fps, heading=heading), ACTION_NAMES[int(a) - 1], str(int(s)), name)
            for m, a, s, name in zip(data.motions, data.actions, data.subjects, data.names)
        ]
    if dataset == "folder":
        return read_folder_clips(root, fps, heading)
    from mocapkit.datasets.mocap.folders import list_clips, read_clips

    clips = list_clips(dataset, root)
    print(f"[mocapkit] reading {len(clips)} {dataset} clips under {root}", flush=True)
    motions = read_clips(clips, progress=True)
    out = []
    for clip, motion in zip(clips, motions):
        landmarks = normalised_landmarks(motion, fps=fps, heading=heading)
        if dataset == "bandai" and label == "style":  # Bandai: group = the other factor (no actor is known)
            out.append(Clip(landmarks, clip["group"], clip["class"], clip["name"]))
        else:
            out.append(Clip(landmarks, clip["class"], clip["group"], clip["name"]))
    return out


def read_folder_clips(root: str, fps: float = 30.0, heading: str = "frame") -> list[Clip]:
    """Every motion file under ``root`` (any format :func:`~mocapkit.datasets.formats.motion_io.read_motion` reads,
    skeletons mixed) as a :class:`Clip`: label = its sub-folder under ``root`` (``"."`` at the top), group
    ``"library"``.

    Raises:
        MocapFolderError: no such folder, no motion file in it, or a file that does not read (names the file).
    """
    from mocapkit.datasets.formats.motion_io import expand_motion_paths, read_motion

    folder = Path(root)
    if not folder.is_dir():
        raise MocapFolderError(f"data.root={str(root)!r} is not a folder")
    paths = expand_motion_paths(folder, "data.root", MocapFolderError)
    print(f"[mocapkit] reading {len(paths)} motion files under {root}", flush=True)
    out = []
    for n, path in enumerate(paths, 1):
        try:
            landmarks = normalised_landmarks(read_motion(path), fps=fps, heading=heading)
        except Exception as exc:
            raise MocapFolderError(f"cannot read {path}: {exc}") from exc
        out.append(Clip(landmarks, path.parent.relative_to(folder).as_posix(), "library", path.stem))
        if n % 50 == 0 or n == len(paths):
            print(f"[mocapkit] read {n}/{len(paths)} files", flush=True)
    return out


def augment(
    sequence: np.ndarray,
    frames: int,
    rng: np.random.Generator,
    crop=(0.7, 1.0),
    rotation_deg: float = 30.0,
    scale=(0.9, 1.1),
    jitter: float = 0.01,
) -> np.ndarray:
    """One augmented view ``[frames, 20, 3]`` float32 of ``sequence`` ``[T, 20, 3]`` (module docstring)."""
    total = len(sequence)
    length = min(total, max(2, round(rng.uniform(*crop) * total)))
    start = int(rng.integers(total - length + 1))
    x = resample_frames(sequence[start : start + length], frames).astype(np.float64)
    angle = np.deg2rad(rng.uniform(-rotation_deg, rotation_deg))
    c, s = np.cos(angle), np.sin(angle)
    rotation = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    x = rng.uniform(*scale) * (x @ rotation.T)
    if jitter > 0:
        x = x + rng.normal(0.0, jitter, x.shape)
    return x.astype(np.float32)


#: Training clips up to which :func:`dtw_neighbours` compares every pair; beyond, each clip only this many.
NEIGHBOUR_CANDIDATES = 1000
#: the validation queries' nearest clips by DTW that ``val/dtw_agreement`` looks for (mocapkit/retrieval/module.py)
TEACHER_NEIGHBOURS = 5


def dtw_nearest(queries: list[Clip], database: list[Clip], k: int, excluded=None) -> np.ndarray:
    """int64 ``[len(queries), k]``: each query's ``k`` nearest database clips (nearest first) by DTW on the
    normalised landmarks flattened to ``[T, 60]``, each distance divided by ``sqrt(T_a + T_b)``: ``dtw_positions``'
    distance. ``excluded(i)``: bool ``[len(database)]``, the clips query ``i`` may not have (itself, its own
    group); -1 pads a row with fewer candidates. Labels are never read.

    Up to :data:`NEIGHBOUR_CANDIDATES` database clips every pair is compared (0.8 s for HDM05's 153 training clips
    against themselves, 6.5 s for MSR's 454, one core); beyond, each query is compared with its
    :data:`NEIGHBOUR_CANDIDATES` nearest database clips by a fixed-length descriptor (16 evenly spaced frames,
    FAISS), as ``dtw_large`` searches: time linear in the clips."""
    from mocapkit.retrieval import ann

    flat = lambda clips: RaggedFrames.from_list([c.landmarks.reshape(len(c.landmarks), -1) for c in clips])
    q_frames, db_frames = flat(queries), flat(database)
    q_lengths, db_lengths = q_frames.lengths.astype(np.float64), db_frames.lengths.astype(np.float64)
    nearest = np.full((len(queries), int(k)), -1, dtype=np.int64)
    every = np.arange(len(database))
    large = len(database) > NEIGHBOUR_CANDIDATES
    if large:
        describe = lambda frames: np.stack([resample_frames(frames[i], 16).ravel() for i in range(len(frames))])
        index = ann.build(describe(db_frames), "flat", metric="l2")
        q_descriptors = describe(q_frames)
    for first in range(0, len(queries), 4096):  # the candidate lists a block of queries at a time
        block = range(first, min(first + 4096, len(queries)))
        if large:
            lists = ann.search(index, "flat", q_descriptors[block.start : block.stop], NEIGHBOUR_CANDIDATES + 1)
        for i in block:
            if not large:  # every database clip
                row, d = every, candidate_dtw(q_frames[i], db_frames) / np.sqrt(q_lengths[i] + db_lengths)
                if excluded is not None:
                    d[excluded(i)] = np.inf
            else:  # the query's candidates by descriptor
                row = lists[i - first]
                row = row[row >= 0]
                if excluded is not None:
                    row = row[~excluded(i)[row]]
                d = candidate_dtw(q_frames[i], db_frames.subset(row)) / np.sqrt(q_lengths[i] + db_lengths[row])
            order = np.argsort(d, kind="stable")[: int(k)]
            best = row[order[np.isfinite(d[order])]]
            nearest[i, : len(best)] = best
    return nearest


def dtw_neighbours(clips: list[Clip], k: int) -> np.ndarray:
    """int64 ``[n, k]``: each clip's ``k`` nearest other clips (nearest first), :func:`dtw_nearest` of the clips
    among themselves."""
    n = len(clips)
    if not 1 <= int(k) < min(n, NEIGHBOUR_CANDIDATES + 1):
        raise ValueError(
            f"data.neighbours={k}: between 1 and the training clips less one ({n - 1}), at most {NEIGHBOUR_CANDIDATES}"
        )
    return dtw_nearest(clips, clips, k, excluded=lambda i: np.arange(n) == i)


class TwoViews(Dataset):
    """Training clips, ``repeats`` times each, as two freshly augmented views: of the clip itself, or the second
    of the clip or one of its ``partners`` (``[n, k]`` clip indices, e.g. :func:`dtw_neighbours`), drawn
    uniformly."""

    def __init__(
        self,
        clips: list[Clip],
        labels: np.ndarray,
        groups: np.ndarray,
        frames: int,
        repeats: int = 1,
        seed: int = 0,
        augmentation: dict | None = None,
        partners: np.ndarray | None = None,
    ):
        self.clips, self.labels, self.groups = clips, labels, groups
        self.frames, self.repeats, self.seed, self.calls = frames, max(1, int(repeats)), seed, 0
        self.augmentation = dict(augmentation or {})
        self.partners = partners

    def __len__(self) -> int:
        return len(self.clips) * self.repeats

    def __getitem__(self, index: int) -> dict:
        self.calls += 1
        rng = np.random.default_rng([self.seed, self.calls, index])
        i = index % len(self.clips)
        first = augment(self.clips[i].landmarks, self.frames, rng, **self.augmentation)
        j = i if self.partners is None else int(rng.choice(np.append(self.partners[i], i)))
        return {
            "landmarks": torch.from_numpy(first),
            "view2": torch.from_numpy(augment(self.clips[j].landmarks, self.frames, rng, **self.augmentation)),
            "label": torch.tensor(self.labels[i]),
            "group": torch.tensor(self.groups[i]),
            "index": torch.tensor(i),
        }


class RetrievalClips(Dataset):
    """Clips as they are (resampled to ``frames``), each a query or a database clip; with ``teacher``
    (int64 ``[n, k]``, a query's nearest clips by DTW as indices of this data set, -1 elsewhere) each item also
    carries its row, which the module's label-free selection compares with the embedding's nearest clips."""

    def __init__(
        self,
        clips: list[Clip],
        labels: np.ndarray,
        groups: np.ndarray,
        query: np.ndarray,
        frames: int,
        teacher: np.ndarray | None = None,
    ):
        self.clips, self.labels, self.groups, self.query, self.frames = clips, labels, groups, query, frames
        self.teacher = teacher
        self._cache: dict[int, torch.Tensor] = {}

    def __len__(self) -> int:
        return len(self.clips)

    def __getitem__(self, index: int) -> dict:
        if index not in self._cache:
            self._cache[index] = torch.from_numpy(resample_frames(self.clips[index].landmarks, self.frames))
        return {
            "landmarks": self._cache[index],
            "label": torch.tensor(self.labels[index]),
            "group": torch.tensor(self.groups[index]),
            "query": torch.tensor(bool(self.query[index])),
            "index": torch.tensor(index),
            **({} if self.teacher is None else {"teacher": torch.from_numpy(self.teacher[index])}),
        }


def stratified_split(labels: list[str], fraction: float, seed: int) -> np.ndarray:
    """bool ``[n]``: a seeded ``fraction`` of each label's clips (rounded; at least one of a label with ≥ 2 clips)."""
    rng = np.random.default_rng(seed)
    labels = np.asarray(labels)
    chosen = np.zeros(len(labels), dtype=bool)
    for name in sorted(set(labels.tolist())):
        members = np.flatnonzero(labels == name)
        if len(members) < 2:
            continue
        n = min(len(members) - 1, max(1, round(fraction * len(members))))
        chosen[rng.permutation(members)[:n]] = True
    return chosen


class RetrievalDataModule(L.LightningDataModule):
    """Labelled clips for the motion embeddings; see the module docstring.

    Args:
        dataset: ``"hdm05"``, ``"bandai"``, ``"msr"`` or ``"folder"`` (any library). root: its folder.
        label: ``"class"`` (each data set's own class), Bandai ``"content"`` or ``"style"``, MSR ``"action"``.
        test_groups: groups (performers) held out for testing; None: the first group in sorted order; ``[]``: none.
        train_groups: groups to train on; None: every group not held out.
        val_fraction: fraction of each class's training-group clips kept for validation (seeded by ``split_seed``).
        frames: frames per item (every clip is resampled to it). fps, heading: of
            :func:`~mocapkit.motion.geometry.normalised_landmarks`.
        repeats: times each training clip is drawn per epoch (a fresh augmentation each time).
        positives: ``"same_clip"`` or ``"dtw_neighbours"`` (the second view's clip; module docstring).
        neighbours: with ``dtw_neighbours``, how many nearest training clips may give the second view.
        augmentation: ``crop`` [min, max] fraction, ``rotation_deg``, ``scale`` [min, max], ``jitter`` (metres).
        batch_size, eval_batch_size, num_workers: the loaders'.
        split_seed: seed of the validation draw. seed: the run's seed (``mocapkit train`` passes it): augmentations.
        clips: instead of ``dataset`` / ``root``: :class:`Clip` objects (tests, or motions read elsewhere).
    """

    def __init__(
        self,
        dataset: str = "hdm05",
        root: str | None = None,
        label: str = "class",
        test_groups: list | str | None = None,
        train_groups: list | None = None,
        val_fraction: float = 0.1,
        frames: int = 64,
        fps: float = 30.0,
        heading: str = "frame",
        repeats: int = 1,
        positives: str = "same_clip",
        neighbours: int = 5,
        augmentation: dict | None = None,
        batch_size: int = 64,
        eval_batch_size: int = 128,
        num_workers: int = 0,
        split_seed: int = 0,
        seed: int = 0,
        clips: list[Clip] | None = None,
    ):
        super().__init__()
        if int(frames) < 8:
            raise ValueError(f"data.frames={frames}: at least 8")
        if not 0.0 < float(val_fraction) < 1.0:
            raise ValueError(f"data.val_fraction={val_fraction}: a fraction in (0, 1)")
        if positives not in POSITIVES:
            raise ValueError(f"data.positives={positives!r}: one of {list(POSITIVES)}")
        self.positives, self.neighbours = positives, int(neighbours)
        self.augmentation = dict(augmentation or {})
        if set(self.augmentation) - set(AUGMENT_KEYS):
            raise ValueError(
                f"data.augmentation: unknown key(s) {sorted(set(self.augmentation) - set(AUGMENT_KEYS))};"
                f" it takes {list(AUGMENT_KEYS)}"
            )
        self.dataset_name, self.root, self.label = dataset, None if root is None else str(root), label
        self.frames, self.fps, self.heading = int(frames), float(fps), heading
        self.repeats, self.seed, self.split_seed = int(repeats), int(seed), int(split_seed)
        self.batch_size, self.eval_batch_size, self.num_workers = (
            int(batch_size),
            int(eval_batch_size),
            int(num_workers),
        )
        if clips is None:
            if root is None:
                raise ValueError(
                    f"data.root is not set: give the {dataset} folder (e.g. data.root=../shared/data/hdm05_cuts11)"
                )
            clips = read_labelled_clips(dataset, root, label, self.fps, heading)
        clips = list(clips)
        if not clips:
            raise ValueError("no clip")
        groups = sorted({c.group for c in clips})
        if dataset == "folder" and test_groups is None:  # a user's library: the embedding indexes what it trains on
            test_groups = []
        train, test = held_out_groups(groups, test_groups, train_groups, dataset, root)
        self.groups = {"train": train, "test": test, "all": groups}
        train_clips = [c for c in clips if c.group in train]
        self.test_clips = [c for c in clips if c.group in test]
        val = stratified_split([c.label for c in train_clips], float(val_fraction), self.split_seed)
        self.val_clips = [c for c, v in zip(train_clips, val) if v]
        self.train_clips = [c for c, v in zip(train_clips, val) if not v]
        self.class_names_ = sorted({c.label for c in clips})
        self._label_index = {name: i for i, name in enumerate(self.class_names_)}
        self._group_index = {name: i for i, name in enumerate(groups)}

    # ------------------------------------------------------------------ what the model needs
    def label_spaces(self) -> dict:
        """``{"class_names": [...], "source": {...}}``: the label space and how the training data was made (data set,
        label, groups, frames, fps, heading, landmark names), stored in the checkpoint and the ONNX metadata."""
        return {
            "class_names": list(self.class_names_),
            "source": {
                "dataset": self.dataset_name,
                "root": self.root,
                "label": self.label,
                "train_groups": list(self.groups["train"]),
                "test_groups": list(self.groups["test"]),
                "groups": list(self.groups["all"]),
                "frames": self.frames,
                "fps": self.fps,
                "heading": self.heading,
                "positives": self.positives,
                "neighbours": self.neighbours if self.positives == "dtw_neighbours" else None,
                "landmark_names": list(LANDMARK_NAMES),
            },
        }

    @property
    def class_names(self) -> list[str]:
        return list(self.class_names_)

    def sample_counts(self) -> dict[str, int]:
        return {"train": len(self.train_clips), "val": len(self.val_clips), "test": len(self.test_clips)}

    def describe(self) -> dict:
        return {
            "split": f"groups: train {self.groups['train']}, test {self.groups['test']}",
            "dataset": self.dataset_name,
            "root": self.root,
            "label": self.label,
            "frames": self.frames,
            "fps": self.fps,
            "heading": self.heading,
            "classes": len(self.class_names_),
            "sample_counts": self.sample_counts(),
        }

    # ------------------------------------------------------------------ loaders
    def _arrays(self, clips: list[Clip]) -> tuple[np.ndarray, np.ndarray]:
        return (
            np.array([self._label_index[c.label] for c in clips], dtype=np.int64),
            np.array([self._group_index[c.group] for c in clips], dtype=np.int64),
        )

    def _retrieval(self, queries: list[Clip], database: list[Clip], teacher: bool = False) -> RetrievalClips:
        """Queries then database clips; with ``teacher``, each query's :data:`TEACHER_NEIGHBOURS` nearest database
        clips by DTW among those the module ranks it against (the other groups' where the database has several,
        as ``val/map`` ranks)."""
        clips = [*queries, *database]
        labels, groups = self._arrays(clips)
        query = np.arange(len(clips)) < len(queries)
        rows = None
        if teacher:
            q_groups, db_groups = groups[: len(queries)], groups[len(queries) :]
            cross = len(np.unique(db_groups)) > 1
            excluded = (lambda i: db_groups == q_groups[i]) if cross else None
            print(f"[mocapkit] DTW neighbours of {len(queries)} validation clips", flush=True)
            nearest = dtw_nearest(queries, database, TEACHER_NEIGHBOURS, excluded)
            rows = np.full((len(clips), TEACHER_NEIGHBOURS), -1, dtype=np.int64)
            rows[: len(queries)] = np.where(nearest >= 0, nearest + len(queries), -1)
        return RetrievalClips(clips, labels, groups, query, self.frames, rows)

    def dataset(self, part: str) -> Dataset:
        if not hasattr(self, "_datasets"):
            labels, groups = self._arrays(self.train_clips)
            partners = None
            if self.positives == "dtw_neighbours":
                print(f"[mocapkit] DTW neighbours of {len(self.train_clips)} training clips", flush=True)
                partners = dtw_neighbours(self.train_clips, self.neighbours)
            self._datasets = {
                "train": TwoViews(
                    self.train_clips,
                    labels,
                    groups,
                    self.frames,
                    self.repeats,
                    self.seed,
                    self.augmentation,
                    partners,
                ),
                "val": self._retrieval(self.val_clips, self.train_clips, teacher=self.positives == "dtw_neighbours"),
                "test": self._retrieval(self.test_clips, [*self.train_clips, *self.val_clips]),
            }
        return self._datasets[part]

    def _loader(self, part: str) -> DataLoader:
        train = part == "train"
        return data_loader(
            self,
            self.dataset(part),
            batch_size=self.batch_size if train else self.eval_batch_size,
            shuffle=train,
            drop_last=train and len(self.dataset(part)) > self.batch_size,
        )

    def train_dataloader(self) -> DataLoader:
        return self._loader("train")

    def val_dataloader(self) -> DataLoader:
        return self._loader("val")

    def test_dataloader(self) -> DataLoader:
        return self._loader("test")


__all__ = [
    "Clip",
    "RetrievalClips",
    "RetrievalDataModule",
    "TwoViews",
    "augment",
    "dtw_neighbours",
    "read_folder_clips",
    "read_labelled_clips",
    "stratified_split",
]
