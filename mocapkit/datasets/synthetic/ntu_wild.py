"""NTU-format files "from the wild": rewrite clean ``.skeleton`` files the way an independent generator might.

Real NTU files and files written by other tools differ from ``mocapkit synth ntu``'s in ways the
body selection must survive. :func:`wild_sequence` rewrites one sample with

* **frames without bodies**: a random ``empty_frame_prob`` of the frames, plus, in some files, the
  first 1-3 frames, have a body count of 0;
* **a flickering spurious body**: present in a random 40-60 % of the frames (chosen frame by frame,
  so it comes and goes), either a non-human point cloud of random shape that jumps to a new place
  every frame (``"cloud"``) or a copy of the actor displaced by a new random offset every frame
  (``"ghost"``, a human shape, taller than wide, so spread denoising keeps it); listed first (slot 0,
  and the first body ID of the file) in about half of the files;
* **CRLF line ends** (:func:`~mocapkit.datasets.formats.ntu_skeleton.write_skeleton`'s default).

:func:`wild_copy` rewrites a whole folder and writes ``wild_manifest.json``: per sample the
body IDs of the real people (those the NTU authors' rules keep on the clean file:
length >= 12 frames and spread denoising, which remove ``synth ntu``'s own chair-like blobs and
passers-by), the flicker's body ID and kind. :func:`body0_correct` scores a prepared cache's
``report.json`` against it. ``scripts/results/ntu_wild_files.py`` is the command-line front end.
"""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import numpy as np

from mocapkit.datasets.formats.ntu_skeleton import (
    SkeletonSequence,
    read_skeleton,
    select_main_bodies,
    sequence_from_positions,
    write_skeleton,
)

MANIFEST = "wild_manifest.json"
FLICKER_KINDS = ("cloud", "ghost")
_FLICKER_ID = 72057594037927936 + 99999  # above synth ntu's IDs (base + 1000..59999)


def real_body_ids(seq: SkeletonSequence) -> list[int]:
    """Body IDs of the people in a clean file: the tracks the NTU authors' length and spread rules keep.

    Flicker denoising is off here, so the oracle does not depend on the rule it is used to test.
    """
    sel = select_main_bodies(
        seq, max_bodies=max(seq.num_bodies, 1), denoise_spread=True, min_frames=12, denoise_flicker=False
    )
    return [seq.body_ids[b] for b in sel.kept]


def wild_sequence(
    seq: SkeletonSequence,
    rng: np.random.Generator,
    empty_frame_prob: float = 0.05,
    flicker_prob: float = 1.0,
    presence: tuple[float, float] = (0.4, 0.6),
    first_prob: float = 0.5,
) -> tuple[SkeletonSequence, dict]:
    """Rewrite one clean sample as an independent generator might have written it.

    Args:
        seq: the clean sample (e.g. from ``mocapkit synth ntu``).
        rng: the random source.
        empty_frame_prob: fraction of frames emptied (body count 0); a third of the files also lose
            their first 1-3 frames.
        flicker_prob: probability that the file gets a flickering spurious body.
        presence: its fraction of frames is uniform in this range, the frames drawn independently.
        first_prob: probability that the flicker is listed first (slot 0, first body ID).

    Returns:
        ``(wild, info)``; ``info`` = ``{"real_body_ids", "flicker_body_id" (None without one),
        "flicker_kind", "flicker_first", "empty_frames"}`` (``empty_frames``: frames of ``wild`` without
        any body, the clean file's own included).
    """
    positions = seq.positions.astype(np.float64)  # [B, T, 25, 3]
    present = seq.present.copy()
    ids = list(seq.body_ids)
    real = real_body_ids(seq)
    T = seq.num_frames
    info = {"real_body_ids": real, "flicker_body_id": None, "flicker_kind": None, "flicker_first": False}
    if real and rng.random() < flicker_prob:
        actor = positions[ids.index(real[0])]  # [T, 25, 3]
        actor_present = present[ids.index(real[0])]
        anchor = actor[actor_present].reshape(-1, 3).mean(0)  # where the scene is, metres
        kind = FLICKER_KINDS[int(rng.integers(len(FLICKER_KINDS)))]
        on = rng.random(T) < rng.uniform(*presence)
        if kind == "cloud":  # 25 points in a box of random shape, somewhere new every frame
            size = rng.uniform(0.2, 1.0, (T, 1, 3))
            centre = anchor + rng.normal(0.0, [0.8, 0.3, 0.8], (T, 1, 3))
            flicker = centre + rng.uniform(-0.5, 0.5, (T, 25, 3)) * size
        else:  # the actor's pose of a random frame, displaced by a new offset every frame
            source = np.flatnonzero(actor_present)
            frames = source[rng.integers(len(source), size=T)]
            offset = rng.normal(0.0, [0.6, 0.05, 0.6], (T, 1, 3))
            flicker = actor[frames] + offset
        first = bool(rng.random() < first_prob)
        if first:  # slot 0 in every frame, and the file's first body ID (present in the first frame)
            on[0] = True
            positions = np.concatenate([flicker[None], positions])
            present = np.concatenate([on[None], present])
            ids = [_FLICKER_ID] + ids
        else:
            positions = np.concatenate([positions, flicker[None]])
            present = np.concatenate([present, on[None]])
            ids = ids + [_FLICKER_ID]
        info.update(flicker_body_id=_FLICKER_ID, flicker_kind=kind, flicker_first=first)
    empty = rng.random(T) < empty_frame_prob
    if rng.random() < 1 / 3:
        empty[: int(rng.integers(1, 4))] = True
    if empty.all():
        empty[int(rng.integers(T))] = False
    present &= ~empty[None]
    positions[~present] = 0.0
    keep = present.any(axis=1)  # a track emptied entirely is gone
    wild = sequence_from_positions(seq.name, positions[keep], [i for i, k in zip(ids, keep) if k], present[keep])
    info["empty_frames"] = int((~wild.present.any(axis=0)).sum())  # the clean file's own lost frames too
    info["real_body_ids"] = [i for i in real if i in wild.body_ids]
    return wild, info


def wild_copy(src: str | os.PathLike, out: str | os.PathLike, seed: int = 0, **options) -> dict[str, dict]:
    """Rewrite every ``*.skeleton`` under ``src`` into ``out`` with :func:`wild_sequence`.

    ``classes.txt`` is copied; ``out/wild_manifest.json`` gets ``{sample name: info}``. Each file's
    randomness comes from ``seed`` and its name, so the output does not depend on the file order.
    ``options`` go to :func:`wild_sequence`. Returns the manifest.
    """
    src, out = Path(src), Path(out)
    files = sorted(src.rglob("*.skeleton"))
    if not files:
        raise FileNotFoundError(f"no .skeleton files under {src}")
    out.mkdir(parents=True, exist_ok=True)
    if (src / "classes.txt").is_file():
        shutil.copy(src / "classes.txt", out / "classes.txt")
    manifest = {}
    for path in files:
        key = [ord(c) for c in path.stem]
        rng = np.random.default_rng([int(seed), *key])
        wild, info = wild_sequence(read_skeleton(path), rng, **options)
        write_skeleton(out / path.name, wild, newline="\r\n")
        manifest[path.stem] = info
    (out / MANIFEST).write_text(json.dumps(manifest, indent=1) + "\n", encoding="utf-8")
    return manifest


def body0_correct(report: dict | str | os.PathLike, manifest: dict | str | os.PathLike) -> dict:
    """How often body 0 of a prepared cache is a real person.

    Args:
        report: a cache's ``report.json`` (path or loaded), whose ``bodies`` list gives the kept body IDs.
        manifest: :func:`wild_copy`'s manifest (path or loaded).

    Returns:
        ``{"samples", "body0_real", "body0_flicker", "rate", "wrong": [names]}`` over the samples of the
        report that are in the manifest and have a real person.
    """
    if not isinstance(report, dict):
        report = json.loads(Path(report).read_text(encoding="utf-8"))
    if not isinstance(manifest, dict):
        manifest = json.loads(Path(manifest).read_text(encoding="utf-8"))
    samples = real = flicker = 0
    wrong = []
    for entry in report["bodies"]:
        info = manifest.get(entry["name"])
        if info is None or not info["real_body_ids"]:
            continue
        samples += 1
        body0 = entry["kept"][0]["body_id"] if entry["kept"] else None
        if body0 in info["real_body_ids"]:
            real += 1
        else:
            wrong.append(entry["name"])
            flicker += body0 is not None and body0 == info["flicker_body_id"]
    return {
        "samples": samples,
        "body0_real": real,
        "body0_flicker": flicker,
        "rate": real / samples if samples else float("nan"),
        "wrong": wrong,
    }
