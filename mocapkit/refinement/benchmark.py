"""The motion-refinement benchmark of the comparison runner: refiners × corruption protocols × seeds, scored on
held-out performers of real motion capture (HDM05, CMU, Bandai).

Samples are the clips of one data set, read with :func:`~mocapkit.datasets.read_motion` (joint positions in
metres, ``[frames, joints, 3]``, forward kinematics for ASF/AMC and BVH). Every clip belongs to a **group**, the
"performer" of a fold: the HDM05 actor, the CMU subject, the Bandai style (which files make up each data set and
how they are grouped: :mod:`mocapkit.datasets.mocap.folders`).

**Folds, protocols, seeds.** A runner protocol is one corruption ``"<protocol>@<level>"`` of
:data:`~mocapkit.refinement.corruptions.PROTOCOLS` (``rdcrypt@0.3``, ``rgloss@10x60``, ``random_missing@0.3``,
``continuous_missing@40``, ``long_gaps@5x2s``, ...). The held-out groups are the **folds of every cell**: one
cell (method, protocol, seed) runs every fold in turn: a data-driven method (``requires_fit``) is fitted on the
clean clips of the *other* groups only, then every test clip of the held-out group is corrupted, refined and
scored. So the runner's table is method × protocol with folds pooled inside a cell (sd over seeds), and
:meth:`RefinementBenchmark.markdown` adds the table with mean ± sd over **seeds × folds** (one value per fold
and seed: the mean over that fold's test clips). The runner's seed is the **corruption seed**: test clip ``i``
(its sample index) of a cell with seed ``s`` is corrupted with ``numpy.random.default_rng`` seeded by
``SeedSequence([s, i])``, so every method of a cell sees exactly the same corrupted clips; the test clips
themselves do not depend on the seed (``clip_seed``).

**Test clips (CPU bounds, all seeded by ``clip_seed``).** ``clips_per_performer`` reads only that many files of
each group (a seeded subset: the pool for both sides); ``train_clips_per_performer`` fits on only that many clips
of each training group; ``clips_per_fold`` scores that many clips of each held-out group: the first clips of a
seeded permutation of the group's clips that every protocol of the benchmark can corrupt (gap protocols need
``L + 2`` frames; with ``same_clips: false`` eligibility is per protocol instead), so every column of the table
is on the same clips. ``max_frames`` crops each *test* clip to its central ``max_frames`` frames (training clips
are used whole); ``fps`` resamples every clip (:meth:`~mocapkit.motion.container.Motion.resample`).

**Metrics per cell** (means over the cell's test clips, every fold; :func:`~mocapkit.refinement.metrics.
score_refinement` against the clean clip on the corrupted = removed or perturbed entries):

- ``rmse_cm``: the theses' per-frame RMSE (Wang 2017 eq. 3.18 / 4.16), averaged over the frames with corrupted
  entries (the per-sequence value of the thesis's Fig. 3.7), cm;
- ``mje_mm``: mean 3-D joint-position error over the corrupted entries, mm; ``mje_removed_mm``: the same over the
  removed (missing) entries only (NaN for ``rdcrypt``, which removes nothing);
- ``coverage``: fraction of the corrupted entries the method filled (a method that leaves entries missing is
  scored on the rest only: compare coverage first); a clip whose ``refine`` (or the fold's ``fit``) raises
  counts as coverage 0 and is not scored for the errors (the message goes into the detail);
- ``seconds``: ``refine`` wall time per clip (s; ``cpu_seconds``: process CPU time); ``fit_seconds``: ``fit``
  wall time per fold (0 without ``requires_fit``; with ``cache_fits`` a fit is done once per fold and parameter
  set and reused by every later cell with the same parameters, and those cells report that fit's time: give
  data-driven methods ``reseed: false`` so that the runner's per-seed ``random_state`` does not force a refit);
- ``n_failed``: clips whose refine or fit raised.

Hyper-parameter ``select:`` of the runner does not apply (it cross-validates classifiers); tune a refiner's
parameters in its ``estimator`` / ``params`` entry.

The detail of a cell keeps, per clip, the numbers above with the clip, group, class, frames and corruption
seed; per fold, the means and the groups the method was fitted on (``fit_groups``: exactly the groups of the
motions passed to ``fit``); and the per-frame RMSE curve (cm, ``[frames]``, None where no entry is corrupted) of
one clip (``curve_clip``: a clip name, or the first test clip).

Presentation: :meth:`~RefinementBenchmark.markdown` (methods × protocols, RMSE mean ± sd over seeds × folds, the
winner in bold, refine and fit time; the same for the joint error; where each method is worse than the
``baselines`` (linear / PCHIP interpolation); the configured ``claims``; mean rank per motion class) and
:meth:`~RefinementBenchmark.plots` (RMSE against ``mr`` of ``random_missing`` and against ``ml`` of
``continuous_missing``, per-frame RMSE curves in the style of the thesis's Figs. 3.8–3.11, refine time against
frames when the test clips' lengths differ at least twofold).
"""

from __future__ import annotations

import math
import time
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from mocapkit.datasets.mocap.folders import DATASETS, FILE_PATTERNS, MocapFolderError  # noqa: F401
from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split

#: A method whose coverage is below this is not eligible for the bold winner (its RMSE is on fewer entries).
FULL_COVERAGE = 0.999
#: Two mean RMSEs within this relative difference are a tie (claims: ≈; the baseline table leaves them out).
TIE = 0.005


# ------------------------------------------------------------------------------------------ protocols
def _level(text: str):
    """``"40"`` → 40, ``"0.3"`` → 0.3, ``"10x60"`` / ``"5x2s"`` → the string."""
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def known_protocols() -> str:
    """``name@level`` for every protocol and its thesis levels, for error messages."""
    from mocapkit.refinement.corruptions import PROTOCOLS

    return ", ".join(f"{name}@{'|'.join(str(level) for level in info.levels)}" for name, info in PROTOCOLS.items())


def parse_protocol(text: str, fps: float = 120.0) -> tuple[str, object]:
    """``"continuous_missing@40"`` → ``("continuous_missing", 40)``; checks the level on a dummy motion.

    Raises:
        ComparisonError: not ``NAME@LEVEL`` with ``NAME`` a key of ``PROTOCOLS``, or a level the protocol rejects
            (the message lists the known protocols and their thesis levels).
    """
    from mocapkit.motion.container import Motion
    from mocapkit.refinement.corruptions import PROTOCOLS, CorruptionError, corrupt

    name, sep, level = str(text).partition("@")
    if not sep or name not in PROTOCOLS or not level:
        raise ComparisonError(
            f"benchmark.protocols: {text!r} is not NAME@LEVEL of a known corruption protocol; "
            f"known (with the theses' levels): {known_protocols()}"
        )
    value = _level(level)
    dummy = Motion(
        np.random.default_rng(0).normal(size=(4000, 31, 3)), [f"j{i}" for i in range(31)], fps, name="level-check"
    )
    try:
        corrupt(dummy, name, value, seed=0)
    except CorruptionError as exc:
        raise ComparisonError(
            f"benchmark.protocols: {text!r}: {str(exc).split(': ', 1)[-1]}; known: {known_protocols()}"
        ) from exc
    return name, value


def clip_seed_for(seed: int, index: int) -> int:
    """The corruption seed of sample ``index`` in a cell of seed ``seed``: ``SeedSequence([seed, index])``."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1)[0])


# ------------------------------------------------------------------------------------------ data
def list_clips(dataset: str, root: Path) -> list[dict]:
    """:func:`mocapkit.datasets.mocap.folders.list_clips`, its errors as :class:`ComparisonError` on ``benchmark.*``."""
    from mocapkit.datasets.mocap.folders import list_clips as folder_clips

    try:
        return folder_clips(dataset, root)
    except MocapFolderError as exc:
        raise ComparisonError(f"benchmark.{exc}") from exc


def central_crop(motion, max_frames: int | None):
    """The central ``max_frames`` frames of ``motion`` (itself when shorter or ``max_frames`` is None)."""
    if not max_frames or motion.num_frames <= max_frames:
        return motion
    start = (motion.num_frames - int(max_frames)) // 2
    stop = start + int(max_frames)
    return replace(
        motion,
        positions=motion.positions[start:stop],
        missing=motion.missing[start:stop],
        rotations=None,
        metadata={**motion.metadata, "crop": [start, stop]},
    )


def _nan_mean(values) -> float:
    values = [float(v) for v in values if v is not None and np.isfinite(v)]
    return float(np.mean(values)) if values else float("nan")


def _json_float(value):
    return None if value is None or not np.isfinite(value) else float(value)


class RefinementBenchmark(Benchmark):
    """Refiners on corrupted real motion, held-out groups (performers) as folds; see the module docstring.

    Args:
        dataset: ``"hdm05"``, ``"cmu"`` or ``"bandai"``.
        root: the data set's folder (``../shared/data/hdm05_cuts11``, ``.../cmu_amc``, ``.../bandai_motion_1``).
        protocols: ``["<protocol>@<level>", ...]`` (:data:`~mocapkit.refinement.corruptions.PROTOCOLS`); the
            compare config's top-level ``protocols`` must be among them.
        fps: resample every clip to this rate (frames per second); None keeps the data's (HDM05 / CMU 120,
            Bandai 30). Gap lengths in frames (``continuous_missing@40``, ``rgloss@10x60``) are frames at this rate.
        max_frames: crop every test clip to its central ``max_frames`` frames (None: whole clips).
        clips_per_fold: test clips per held-out group (None: every eligible clip), seeded by ``clip_seed``.
        held_out: the groups held out in turn (performers, CMU subjects as ``"01"``, Bandai styles); None: all.
        clips_per_performer: read only this many files per group (seeded subset; None: all).
        train_clips_per_performer: fit on only this many clips per training group (seeded subset; None: all).
        same_clips: True: test clips must suit every protocol (the same clips in every column); False: per protocol.
        clip_seed: seed of the clip subsets (not the corruption seed, which is the cell's).
        curve_clip: the clip (file stem) whose per-frame RMSE curve is kept and plotted; None: the first test clip.
        numerator: ``"frame"`` or ``"corrupted"``: the per-frame RMSE numerator (:func:`~mocapkit.evaluation.
            refinement.per_frame_rmse`).
        cache_fits: reuse a fold's fitted model across the protocols of a cell seed (same parameters).
        baselines: method keys every method is compared with in the "worse than" table (e.g. linear, pchip).
        claims: ``[{method, beats: [keys] | null (all others), protocols: [names] | null (all), text}]``, checked
            per protocol in ``results.md`` (mean RMSE lower than each beaten method's).
    """

    title = "Motion refinement on held-out performers"
    percent_metrics = ("coverage",)

    def __init__(
        self,
        dataset: str,
        root: str,
        protocols: list[str],
        fps: float | None = None,
        max_frames: int | None = None,
        clips_per_fold: int | None = None,
        held_out: list | None = None,
        clips_per_performer: int | None = None,
        train_clips_per_performer: int | None = None,
        same_clips: bool = True,
        clip_seed: int = 0,
        curve_clip: str | None = None,
        numerator: str = "frame",
        cache_fits: bool = True,
        baselines: list | None = None,
        claims: list | None = None,
    ):
        if root is None:
            raise ComparisonError("benchmark.root is not set: give the data set's folder")
        if not protocols:
            raise ComparisonError(f"benchmark.protocols: give at least one NAME@LEVEL; known: {known_protocols()}")
        if numerator not in ("frame", "corrupted"):
            raise ComparisonError(f"benchmark.numerator={numerator!r}: 'frame' or 'corrupted'")
        for key, value in (
            ("max_frames", max_frames),
            ("clips_per_fold", clips_per_fold),
            ("clips_per_performer", clips_per_performer),
            ("train_clips_per_performer", train_clips_per_performer),
        ):
            if value is not None and int(value) < 1:
                raise ComparisonError(f"benchmark.{key}={value!r}: a positive number or null")
        self.dataset, self.root = dataset, Path(root)
        self.fps = None if fps is None else float(fps)
        self.max_frames = None if max_frames is None else int(max_frames)
        self.clips_per_fold = None if clips_per_fold is None else int(clips_per_fold)
        self.clips_per_performer = None if clips_per_performer is None else int(clips_per_performer)
        self.train_clips_per_performer = None if train_clips_per_performer is None else int(train_clips_per_performer)
        self.same_clips, self.clip_seed, self.curve_clip = bool(same_clips), int(clip_seed), curve_clip
        self.numerator, self.cache_fits = numerator, bool(cache_fits)
        self.baselines = [str(b) for b in (baselines or [])]
        self.claims = [dict(c) for c in (claims or [])]
        for claim in self.claims:
            if not claim.get("method"):
                raise ComparisonError(f"benchmark.claims: every claim needs method: KEY, got {claim!r}")

        found = list_clips(dataset, self.root)
        self.all_groups = sorted({c["group"] for c in found})
        if self.clips_per_performer:
            rng = np.random.default_rng(self.clip_seed)
            keep = []
            for group in self.all_groups:
                mine = [c for c in found if c["group"] == group]
                order = rng.permutation(len(mine))[: self.clips_per_performer]
                keep += [mine[i] for i in sorted(order)]
            found = keep
        from mocapkit.datasets.mocap.folders import read_clips

        try:
            self.motions = read_clips(found, self.fps)
        except MocapFolderError as exc:
            raise ComparisonError(f"benchmark: {exc}") from exc
        self.clips = [
            {**clip, "path": str(clip["path"]), "frames": motion.num_frames}
            for clip, motion in zip(found, self.motions)
        ]
        self.groups = np.asarray([c["group"] for c in self.clips])
        self.names = [c["name"] for c in self.clips]
        present = sorted(set(self.groups.tolist()))
        if held_out is None:
            self.held_out = present
        else:
            self.held_out = [str(g) for g in ([held_out] if isinstance(held_out, (str, int)) else held_out)]
            unknown = [g for g in self.held_out if g not in present]
            if unknown:
                raise ComparisonError(
                    f"benchmark.held_out={unknown}: not groups of {dataset} under {self.root} (groups: {present})"
                )
        if len(present) < 2:
            raise ComparisonError(
                f"benchmark: {dataset} under {self.root} has one group ({present}); holding one out needs at least two"
            )
        data_fps = self.motions[0].fps
        self.parsed = {}
        for text in protocols:
            self.parsed[str(text)] = parse_protocol(str(text), data_fps)
        self.protocols = tuple(self.parsed)
        self._test_cache: dict[int, object] = {}
        self._eligible: dict[tuple[int, str], bool] = {}
        self._fits: dict[tuple, tuple] = {}

    # -------------------------------------------------------------- data
    def describe(self) -> dict:
        frames = [c["frames"] for c in self.clips]
        return {
            "dataset": self.dataset,
            "root": str(self.root),
            "n_clips": len(self.clips),
            "frames": int(sum(frames)),
            "fps": float(self.motions[0].fps),
            "joints": self.motions[0].num_joints,
            "groups": {g: int((self.groups == g).sum()) for g in sorted(set(self.groups.tolist()))},
            "group_kind": "style (no performer label in the files)" if self.dataset == "bandai" else "performer",
            "held_out": self.held_out,
            "max_frames": self.max_frames,
            "clips_per_fold": self.clips_per_fold,
            "clips_per_performer": self.clips_per_performer,
            "train_clips_per_performer": self.train_clips_per_performer,
            "same_clips": self.same_clips,
            "clip_seed": self.clip_seed,
            "numerator": self.numerator,
            "cache_fits": self.cache_fits,
            "resampled_to": self.fps,
        }

    def data(self, indices: np.ndarray):
        """Clean whole clips (a list of :class:`~mocapkit.motion.container.Motion`, positions ``[T_i, J, 3]``
        metres) and their groups (``[n]`` str) of ``indices``."""
        indices = np.asarray(indices, dtype=np.int64)
        return [self.motions[i] for i in indices], self.groups[indices]

    def test_motion(self, index: int):
        """The clean test clip ``index``: cropped to ``max_frames`` (central frames)."""
        if index not in self._test_cache:
            self._test_cache[index] = central_crop(self.motions[index], self.max_frames)
        return self._test_cache[index]

    def _suits(self, index: int, protocol: str) -> bool:
        """Whether ``protocol`` can corrupt test clip ``index`` (gap protocols need enough frames)."""
        from mocapkit.refinement.corruptions import CorruptionError, corrupt

        key = (index, protocol)
        if key not in self._eligible:
            name, level = self.parsed[protocol]
            try:
                corrupt(self.test_motion(index), name, level, seed=0)
                self._eligible[key] = True
            except CorruptionError:
                self._eligible[key] = False
        return self._eligible[key]

    def _train_indices(self, fold: str) -> np.ndarray:
        """Clips of every group but ``fold`` (``train_clips_per_performer`` of each, seeded), sorted."""
        rng = np.random.default_rng([self.clip_seed, 1])
        chosen = []
        for group in sorted(set(self.groups.tolist())):
            mine = np.flatnonzero(self.groups == group)
            if self.train_clips_per_performer and len(mine) > self.train_clips_per_performer:
                subset = np.sort(rng.permutation(mine)[: self.train_clips_per_performer])
            else:
                subset = mine
            if group != fold:
                chosen.append(subset)
        return np.sort(np.concatenate(chosen)).astype(np.int64)

    def _test_indices(self, fold: str, protocol: str) -> tuple[np.ndarray, int]:
        """``clips_per_fold`` clips of group ``fold`` that suit the protocol(s), in a seeded order; and how many
        of the group's clips were passed over as too short."""
        mine = np.flatnonzero(self.groups == fold)
        rng = np.random.default_rng([self.clip_seed, 2, zlib.crc32(fold.encode())])  # its own draw per group
        order = mine[rng.permutation(len(mine))]
        needed = list(self.protocols) if self.same_clips else [protocol]
        chosen, skipped = [], 0
        for index in order:
            if self.clips_per_fold and len(chosen) >= self.clips_per_fold:
                break
            if all(self._suits(int(index), p) for p in needed):
                chosen.append(int(index))
            else:
                skipped += 1
        return np.sort(np.asarray(chosen, dtype=np.int64)), skipped

    def split(self, protocol: str, seed: int) -> Split:
        """Every held-out group is a fold: ``test`` = the union of the folds' test clips, ``train`` = the union of
        the folds' training clips (each fold trains only on the *other* groups: ``info["folds"]``)."""
        if protocol not in self.parsed:
            raise ComparisonError(f"protocol {protocol!r}: not among benchmark.protocols {list(self.protocols)}")
        folds, tests, trains = {}, [], []
        for fold in self.held_out:
            test, skipped = self._test_indices(fold, protocol)
            if len(test) == 0:
                longest = max(self.test_motion(int(i)).num_frames for i in np.flatnonzero(self.groups == fold))
                wanted = list(self.protocols) if self.same_clips else protocol
                raise ComparisonError(
                    f"benchmark: no clip of {fold!r} suits {wanted} (longest test clip {longest} "
                    f"frames after max_frames={self.max_frames}); "
                    "raise max_frames, lower the gap lengths or set same_clips: false"
                )
            train = self._train_indices(fold)
            folds[fold] = {
                "test": test.tolist(),
                "test_clips": [self.names[i] for i in test],
                "n_train": len(train),
                "train_groups": sorted(set(self.groups[train].tolist())),
                "skipped_short": skipped,
            }
            tests.append(test)
            trains.append(train)
        test = np.unique(np.concatenate(tests))
        train = np.unique(np.concatenate(trains))
        if self.curve_clip is not None and self.curve_clip not in [self.names[i] for i in test]:
            raise ComparisonError(
                f"benchmark.curve_clip={self.curve_clip!r} is not a test clip of {protocol}: "
                f"{[self.names[i] for i in test]}"
            )
        name, level = self.parsed[protocol]
        return Split(
            protocol,
            seed,
            train,
            test,
            {
                "corruption": name,
                "level": level,
                "folds": folds,
                "corruption_seed": "SeedSequence([seed, sample index])",
            },
        )

    # -------------------------------------------------------------- scoring
    def _fitted(self, estimator, fold: str, train: np.ndarray) -> tuple[object, float, bool, list[str]]:
        """``(estimator fitted on train, fit seconds, from the cache?, groups it was fitted on)``."""
        from sklearn.base import clone

        key = (
            fold,
            type(estimator).__module__,
            type(estimator).__qualname__,
            repr(sorted((k, repr(v)) for k, v in estimator.get_params(deep=True).items())),
            tuple(train.tolist()),
        )
        if self.cache_fits and key in self._fits:
            fitted, seconds, groups = self._fits[key]
            return fitted, seconds, True, groups
        fitted = clone(estimator)
        motions, groups = self.data(train)
        start = time.perf_counter()
        fitted.fit(motions)
        seconds = time.perf_counter() - start
        fitted_groups = sorted({m.metadata["group"] for m in motions})
        if self.cache_fits:
            self._fits[key] = (fitted, seconds, fitted_groups)
        return fitted, seconds, False, fitted_groups

    def evaluate_estimator(self, estimator, split: Split) -> dict:
        """Per fold: fit on the training groups' clean clips (only when ``estimator.requires_fit``), then corrupt
        (seeded), refine and score every test clip. Returns the metrics (means over the clips) and the detail."""
        from mocapkit.refinement.corruptions import CorruptionError, corrupt
        from mocapkit.refinement.metrics import score_refinement

        name, level = self.parsed[split.protocol]
        clips, folds, curve = [], {}, None
        curve_name = self.curve_clip
        for fold, info in split.info["folds"].items():
            train = np.asarray(self._train_indices(fold), dtype=np.int64)
            fit_error = None
            if getattr(estimator, "requires_fit", False):
                try:
                    refiner, fit_seconds, cached, fit_groups = self._fitted(estimator, fold, train)
                except Exception as exc:  # noqa: BLE001 -- any fit error is recorded; the fold's clips count as failed
                    fit_error = f"fit failed: {type(exc).__name__}: {exc}"
                    refiner, fit_seconds, cached, fit_groups = None, float("nan"), False, []
                    print(f"[compare] {type(estimator).__name__} {fit_error} (fold {fold})", flush=True)
                if fold in fit_groups:  # never: the fold's clips are not in train
                    raise ComparisonError(f"benchmark: the fit of fold {fold!r} saw its own clips")
            else:
                refiner, fit_seconds, cached, fit_groups = estimator, 0.0, False, []
            mine = []
            for index in info["test"]:
                clean = self.test_motion(index)
                seed = clip_seed_for(split.seed, index)
                record = {
                    "clip": self.names[index],
                    "index": int(index),
                    "fold": fold,
                    "class": self.clips[index]["class"],
                    "frames": clean.num_frames,
                    "corruption_seed": seed,
                }
                try:
                    corruption = corrupt(clean, name, level, seed=seed)
                except CorruptionError as exc:  # the same for every method (deterministic): not scored
                    record["error"] = f"not corruptible: {exc}"
                    clips.append(record)
                    continue
                if fit_error:
                    record.update(error=fit_error, coverage=0.0, corrupted=int(corruption.corrupted.sum()))
                    clips.append(record)
                    mine.append(record)
                    continue
                start, cpu = time.perf_counter(), time.process_time()
                try:
                    refined = refiner.refine(corruption.motion)
                except Exception as exc:  # noqa: BLE001 -- any refine error is recorded (n_failed, coverage 0)
                    record.update(
                        seconds=time.perf_counter() - start,
                        cpu_seconds=time.process_time() - cpu,
                        error=f"{type(exc).__name__}: {exc}",
                        coverage=0.0,
                        corrupted=int(corruption.corrupted.sum()),
                    )
                    print(
                        f"[compare] {type(estimator).__name__} failed on {record['clip']} ({split.protocol}): "
                        f"{record['error']}",
                        flush=True,
                    )
                    clips.append(record)
                    mine.append(record)
                    continue
                seconds, cpu_seconds = time.perf_counter() - start, time.process_time() - cpu
                score = score_refinement(refined, clean, corruption, numerator=self.numerator)
                record.update(
                    rmse_cm=_json_float(score.rmse_cm),
                    mje_mm=_json_float(score.mean_error_mm),
                    mje_removed_mm=_json_float(score.mean_error_removed_mm),
                    matrix_rmse_cm=_json_float(score.matrix_rmse_cm),
                    coverage=float(score.coverage),
                    corrupted=score.corrupted,
                    unfilled=score.unfilled,
                    changed_clean=score.changed_clean,
                    seconds=seconds,
                    cpu_seconds=cpu_seconds,
                )
                if curve is None and (curve_name is None or curve_name == record["clip"]):
                    curve = {
                        "clip": record["clip"],
                        "fold": fold,
                        "frames": clean.num_frames,
                        "fps": float(clean.fps),
                        "description": corruption.description,
                        "rmse_cm": [_json_float(v) for v in score.rmse_curve_cm],
                    }
                clips.append(record)
                mine.append(record)
            folds[fold] = {
                "fit_seconds": _json_float(fit_seconds),
                "fit_cached": cached,
                "fit_groups": fit_groups,
                "fit_error": fit_error,
                "n_fit_clips": len(train) if fit_groups else 0,
                "n_test": len(mine),
                **{
                    k: _nan_mean(r.get(k) for r in mine)
                    for k in ("rmse_cm", "mje_mm", "mje_removed_mm", "coverage", "seconds")
                },
            }
        scored = [r for r in clips if "rmse_cm" in r or "coverage" in r]
        fitted = [f["fit_seconds"] for f in folds.values() if f["fit_seconds"] is not None]
        metrics = {
            k: _nan_mean(r.get(k) for r in scored)
            for k in ("rmse_cm", "mje_mm", "mje_removed_mm", "matrix_rmse_cm", "coverage", "seconds", "cpu_seconds")
        }
        metrics["fit_seconds"] = float(np.mean(fitted)) if fitted else 0.0
        metrics["n_failed"] = float(sum(1 for r in scored if "error" in r))
        return {
            "metrics": metrics,
            "detail": {"protocol": name, "level": level, "folds": folds, "clips": clips, "curve": curve},
        }

    # -------------------------------------------------------------- presentation
    def headline(self, protocol: str) -> list[str]:
        return ["rmse_cm", "mje_mm", "coverage", "seconds", "fit_seconds"]

    def format_metric(self, name, mean, sd=None) -> str:
        if mean is None or (isinstance(mean, float) and math.isnan(mean)):
            return "–"
        digits = {"mje_mm": 1, "mje_removed_mm": 1, "n_failed": 0}.get(name, 2 if name.endswith("_cm") else 3)
        if name in self.percent_metrics:
            return super().format_metric(name, mean, sd)
        return f"{mean:.{digits}f}" + (f" ± {sd:.{digits}f}" if sd is not None else "")

    def markdown(self, results: dict) -> str:
        table = fold_table(results)
        if not table["methods"]:
            return ""
        bench = results["benchmark"]
        protocols = results["protocols"]
        seeds = results["seeds"]
        held = bench.get("held_out") or []
        group_kind = bench.get("group_kind", "performer")
        lines = [
            "## Refinement: methods × protocols",
            "",
            (
                f"{bench.get('dataset', '')} under `{bench.get('root', '')}`: {bench.get('n_clips')} clips, "
                f"{bench.get('joints')} joints, {bench.get('fps', 0):g} fps; held out in turn ({group_kind}): "
                f"{', '.join(held)}; test clips per fold {bench.get('clips_per_fold') or 'all'}, cropped to "
                f"{bench.get('max_frames') or 'whole'} frames; seeds (corruption) {seeds}. Data-driven methods are "
                "fitted on the other groups' clean clips only (`fit_groups` in results.json)."
            ),
            "",
            (
                "RMSE = the theses' per-frame RMSE (Wang 2017 eq. 3.18 / 4.16) averaged over the frames with "
                "corrupted entries, cm; mean ± sd over seeds × folds (one value per fold and seed: the mean over "
                "the fold's test clips). **Bold**: the lowest mean among methods that filled ≥ "
                f"{100 * FULL_COVERAGE:.1f} % of the corrupted entries; † = coverage below that (scored on the "
                "filled entries only); ✗ = some refines raised. Time: `refine` wall seconds per clip (mean over "
                "every cell) and `fit` seconds per fold."
            ),
            "",
        ]
        lines += _metric_table(table, protocols, "rmse_cm", 2)
        lines += ["", "Mean joint-position error over the corrupted entries (mm), mean ± sd over seeds × folds:", ""]
        lines += _metric_table(table, protocols, "mje_mm", 1)
        lines += [""] + _baseline_lines(table, protocols, self.baselines)
        lines += [""] + _claim_lines(table, protocols, self.claims)
        lines += [""] + _class_rank_lines(results)
        lines += [""] + _clip_lines(results)
        return "\n".join(lines)

    def plots(self, results: dict, out_dir) -> list[Path]:
        out_dir = Path(out_dir)
        table = fold_table(results)
        written = []
        for protocol, symbol, stem in (
            ("random_missing", "missing ratio mr", "rmse_vs_mr"),
            ("continuous_missing", "gap length ml (frames)", "rmse_vs_ml"),
        ):
            path = _plot_levels(table, results["protocols"], protocol, symbol, out_dir / f"{stem}.png")
            written += [path] if path else []
        path = _plot_curves(results, out_dir / "rmse_curves.png")
        written += [path] if path else []
        path = _plot_time(results, out_dir / "seconds_vs_frames.png")
        written += [path] if path else []
        return written


# ------------------------------------------------------------------------------------------ tables
def fold_table(results: dict) -> dict:
    """``{"methods": {key: label}, "values": {(method, protocol): {metric: [per seed × fold]}}, "time": ...}``
    from the cells' details (a fold's value = the mean over its test clips)."""
    methods, values, times, fits, failed = {}, {}, {}, {}, {}
    for cell in results.get("cells", []):
        detail = cell.get("detail") or {}
        if "folds" not in detail:
            continue
        key = cell["method"]
        methods[key] = cell["label"]
        entry = values.setdefault((key, cell["protocol"]), {})
        for fold in detail["folds"].values():
            for metric in ("rmse_cm", "mje_mm", "coverage", "seconds"):
                entry.setdefault(metric, []).append(fold.get(metric))
            if fold.get("fit_groups"):
                fits.setdefault(key, []).append(fold.get("fit_seconds", 0.0))
        times.setdefault(key, []).append(cell["metrics"].get("seconds"))
        if cell["metrics"].get("n_failed"):
            failed[(key, cell["protocol"])] = True
    return {"methods": methods, "values": values, "time": times, "fit": fits, "failed": failed}


def _stats(values) -> tuple[float, float, int]:
    finite = [float(v) for v in values or [] if v is not None and np.isfinite(v)]
    if not finite:
        return float("nan"), float("nan"), 0
    return float(np.mean(finite)), float(np.std(finite, ddof=1)) if len(finite) > 1 else 0.0, len(finite)


def _winner(table: dict, protocol: str, metric: str) -> str | None:
    best, best_key = math.inf, None
    for key in table["methods"]:
        entry = table["values"].get((key, protocol))
        if not entry:
            continue
        mean = _stats(entry[metric])[0]
        coverage = _stats(entry["coverage"])[0]
        if np.isfinite(mean) and coverage >= FULL_COVERAGE and mean < best:
            best, best_key = mean, key
    return best_key


def _metric_table(table: dict, protocols: list[str], metric: str, digits: int) -> list[str]:
    header = ["method", *protocols, "refine s/clip", "fit s/fold"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    winners = {p: _winner(table, p, metric) for p in protocols}
    for key, label in table["methods"].items():
        row = [label]
        for protocol in protocols:
            entry = table["values"].get((key, protocol))
            if not entry:
                row.append("–")
                continue
            mean, sd, _ = _stats(entry[metric])
            text = "–" if not np.isfinite(mean) else f"{mean:.{digits}f} ± {sd:.{digits}f}"
            if winners[protocol] == key:
                text = f"**{text}**"
            if _stats(entry["coverage"])[0] < FULL_COVERAGE:
                text += " †"
            if table["failed"].get((key, protocol)):
                text += " ✗"
            row.append(text)
        seconds = _stats(table["time"].get(key))[0]
        fit = _stats(table["fit"].get(key))[0] if key in table["fit"] else 0.0
        row += [f"{seconds:.3f}" if np.isfinite(seconds) else "–", f"{fit:.1f}" if np.isfinite(fit) else "–"]
        lines.append("| " + " | ".join(row) + " |")
    return lines


def _baseline_lines(table: dict, protocols: list[str], baselines: list[str]) -> list[str]:
    present = [b for b in baselines if b in table["methods"]]
    if not present:
        return []
    lines = [
        "### Against the interpolation baselines",
        "",
        (
            f"Protocols where a method's mean RMSE is **above** the baseline's by more than {100 * TIE:g} % "
            "(ratio method / baseline; the protocol kind in brackets: missing, noise, mixed). A method not meant "
            "for a kind (interpolation on noise) is listed all the same."
        ),
        "",
        "| method | " + " | ".join(f"worse than {table['methods'][b]}" for b in present) + " |",
        "|---|" + "---|" * len(present),
    ]
    from mocapkit.refinement.corruptions import PROTOCOLS

    for key, label in table["methods"].items():
        cells = []
        for base in present:
            if base == key:
                cells.append("(baseline)")
                continue
            worse = []
            for protocol in protocols:
                mine, theirs = table["values"].get((key, protocol)), table["values"].get((base, protocol))
                if not mine or not theirs:
                    continue
                a, b = _stats(mine["rmse_cm"])[0], _stats(theirs["rmse_cm"])[0]
                if np.isfinite(a) and np.isfinite(b) and a > b * (1 + TIE):
                    kind = PROTOCOLS[protocol.split("@")[0]].kind
                    worse.append(f"{protocol} [{kind}] ×{a / b:.2f}" if b > 0 else f"{protocol} [{kind}]")
            cells.append(", ".join(worse) or "none")
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return lines


def _claim_lines(table: dict, protocols: list[str], claims: list[dict]) -> list[str]:
    if not claims:
        return []
    lines = [
        "### The theses' claims on these data",
        "",
        (
            "A claim holds on a protocol when the method's mean RMSE is below every beaten method's (those run) "
            f"by more than {100 * TIE:g} %; ≈ marks a tie (within {100 * TIE:g} %), which neither holds nor "
            "fails."
        ),
        "",
    ]
    for claim in claims:
        method = claim["method"]
        text = claim.get("text") or f"{method} beats {claim.get('beats') or 'every other method'}"
        lines.append(f"**{text}**")
        lines.append("")
        if method not in table["methods"]:
            lines += [f"- not run (method `{method}` absent from this comparison)", ""]
            continue
        beats = claim.get("beats") or [k for k in table["methods"] if k != method]
        beats = [b for b in beats if b in table["methods"]]
        chosen = [p for p in protocols if not claim.get("protocols") or p.split("@")[0] in claim["protocols"]]
        holds = 0
        for protocol in chosen:
            mine = table["values"].get((method, protocol))
            if not mine:
                continue
            a = _stats(mine["rmse_cm"])[0]
            parts, marks = [], []
            for other in beats:
                theirs = table["values"].get((other, protocol))
                if not theirs:
                    continue
                b = _stats(theirs["rmse_cm"])[0]
                if not (np.isfinite(a) and np.isfinite(b)) or a > b * (1 + TIE):
                    mark = "✗"
                elif a < b * (1 - TIE):
                    mark = "✓"
                else:
                    mark = "≈"
                marks.append(mark)
                parts.append(f"{table['methods'][other]} {b:.2f} {mark}")
            verdict = "does not hold" if "✗" in marks else "tie" if "≈" in marks else "holds"
            holds += verdict == "holds"
            lines.append(
                f"- {protocol}: {table['methods'][method]} {a:.2f} cm vs " + ", ".join(parts) + f" → {verdict}"
            )
        lines += [f"- holds on {holds} of {len(chosen)} protocols", ""]
    return lines


def _class_rank_lines(results: dict) -> list[str]:
    """Mean rank (1 = lowest RMSE) of each method per motion class, over every (protocol, seed, clip)."""
    per_instance: dict[tuple, dict[str, float]] = {}
    classes: dict[tuple, str] = {}
    labels = {}
    for cell in results.get("cells", []):
        for clip in (cell.get("detail") or {}).get("clips", []):
            value = clip.get("rmse_cm")
            if value is None or clip.get("coverage", 0) < FULL_COVERAGE:
                continue
            key = (cell["protocol"], cell["seed"], clip["clip"])
            per_instance.setdefault(key, {})[cell["method"]] = value
            classes[key] = clip["class"]
            labels[cell["method"]] = cell["label"]
    methods = list(labels)
    ranks: dict[str, dict[str, list[float]]] = {}
    for key, scores in per_instance.items():
        if len(scores) != len(methods) or len(methods) < 2:
            continue
        order = sorted(scores, key=scores.get)
        for r, method in enumerate(order, 1):
            ranks.setdefault(classes[key], {}).setdefault(method, []).append(r)
    if not ranks:
        return []
    names = sorted(ranks)
    lines = [
        "### Mean rank per motion class",
        "",
        (
            "Rank 1 = the lowest RMSE on a (protocol, seed, clip) instance that every method filled completely; "
            "mean over the class's instances (count in brackets). Bold: the best mean rank of the class."
        ),
        "",
        "| method | " + " | ".join(f"{n} ({len(next(iter(ranks[n].values())))})" for n in names) + " |",
        "|---|" + "---|" * len(names),
    ]
    best = {n: min(ranks[n], key=lambda m: np.mean(ranks[n][m])) for n in names}
    for method in methods:
        cells = []
        for n in names:
            text = f"{np.mean(ranks[n][method]):.1f}" if method in ranks[n] else "–"
            cells.append(f"**{text}**" if best[n] == method else text)
        lines.append(f"| {labels[method]} | " + " | ".join(cells) + " |")
    return lines


def _clip_lines(results: dict) -> list[str]:
    """The test clips of every fold; protocols with the same clips share a row (all of them with ``same_clips``)."""
    frames, by_clips = {}, {}
    for cell in results.get("cells", []):
        for clip in (cell.get("detail") or {}).get("clips", []):
            frames[clip["clip"]] = clip["frames"]
    for protocol in results.get("protocols", []):
        seeds = results.get("splits", {}).get(protocol) or {}
        split = next(iter(seeds.values()), {})
        if not split.get("folds"):
            continue
        key = tuple(
            (fold, tuple(info["test_clips"]), info.get("skipped_short", 0)) for fold, info in split["folds"].items()
        )
        by_clips.setdefault(key, []).append(protocol)
    if not by_clips:
        return []
    lines = [
        "### Test clips",
        "",
        "| protocols | fold | test clips (frames) | passed over as too short |",
        "|---|---|---|---|",
    ]
    for key, protocols in by_clips.items():
        shown = "every protocol" if len(by_clips) == 1 else ", ".join(protocols)
        for fold, names, skipped in key:
            clips = ", ".join(f"{c} ({frames.get(c, '?')})" for c in names)
            lines.append(f"| {shown} | {fold} | {clips} | {skipped} |")
    return lines


# ------------------------------------------------------------------------------------------ plots
def _styles(labels) -> dict[str, dict]:
    """One colour (tab10) and line style per method label, the same in every plot (more than 10 methods: dashes)."""
    from mocapkit.evaluation.plots import pyplot

    colours = pyplot().get_cmap("tab10").colors
    return {
        label: {"color": colours[i % 10], "linestyle": ("-", "--", ":")[(i // 10) % 3]}
        for i, label in enumerate(dict.fromkeys(labels))
    }


def _plot_levels(table: dict, protocols: list[str], name: str, xlabel: str, path: Path) -> Path | None:
    levels = [(float(p.split("@")[1]), p) for p in protocols if p.split("@")[0] == name]
    if len(levels) < 2:
        return None
    from mocapkit.evaluation.plots import pyplot, save_figure

    plt = pyplot()
    levels.sort()
    longest = max((len(label) for label in table["methods"].values()), default=0)
    fig, ax = plt.subplots(figsize=(max(7.5, 5.0 + 0.06 * longest), 4.4))  # room for the legend's labels
    styles = _styles(table["methods"].values())
    for key, label in table["methods"].items():
        xs, ys, es = [], [], []
        for x, protocol in levels:
            mean, sd, _ = _stats((table["values"].get((key, protocol)) or {}).get("rmse_cm"))
            if np.isfinite(mean):
                xs.append(x)
                ys.append(mean)
                es.append(sd)
        if xs:
            ax.errorbar(xs, ys, yerr=es, marker="o", ms=4, capsize=3, label=label, **styles[label])
    ax.set_xlabel(xlabel)
    ax.set_ylabel("RMSE (cm, Wang eq. 3.18)")
    ax.set_yscale("log", nonpositive="clip")
    ax.set_title(f"{name}: RMSE, mean ± sd over seeds × folds", loc="left")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, frameon=False, loc="center left", bbox_to_anchor=(1.0, 0.5))
    return save_figure(fig, path)


def _plot_curves(results: dict, path: Path) -> Path | None:
    """Per-frame RMSE of the curve clip, one panel per protocol, one line per method (first seed)."""
    seed = results["seeds"][0] if results.get("seeds") else None
    panels = {}
    for cell in results.get("cells", []):
        curve = (cell.get("detail") or {}).get("curve")
        if cell["seed"] != seed or not curve:
            continue
        panels.setdefault(cell["protocol"], []).append((cell["label"], curve))
    if not panels:
        return None
    from mocapkit.evaluation.plots import pyplot, save_figure

    plt = pyplot()
    names = [p for p in results["protocols"] if p in panels]
    cols = min(3, len(names) + 1)  # one more panel: the legend
    rows = math.ceil((len(names) + 1) / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(5.0 * cols, 3.2 * rows), squeeze=False)
    styles = _styles(label for p in names for label, _ in panels[p])
    for ax, protocol in zip(axes.flat, names):
        for label, curve in panels[protocol]:
            values = np.asarray([np.nan if v is None else v for v in curve["rmse_cm"]], dtype=float)
            frames = np.arange(len(values))
            ax.plot(
                frames,
                values,
                lw=0.9,
                marker="." if np.isfinite(values).sum() < 200 else None,
                ms=2,
                label=label,
                **styles[label],
            )
        clip = panels[protocol][0][1]
        ax.set_title(f"{protocol} — {clip['clip']}", fontsize=8)
        ax.set_xlabel(f"frame ({clip['fps']:g} fps)", fontsize=8)
        ax.set_ylabel("RMSE per frame (cm)", fontsize=8)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(names) :]:
        ax.axis("off")
    handles, labels = axes.flat[0].get_legend_handles_labels()
    axes.flat[len(names)].legend(handles, labels, fontsize=8, frameon=False, loc="center")
    fig.suptitle(f"Per-frame RMSE (Wang eq. 3.18) of one test clip, seed {seed}", fontsize=10)
    return save_figure(fig, path)


def _plot_time(results: dict, path: Path) -> Path | None:
    points = {}
    for cell in results.get("cells", []):
        for clip in (cell.get("detail") or {}).get("clips", []):
            if clip.get("seconds") is not None:
                points.setdefault(cell["label"], []).append((clip["frames"], clip["seconds"]))
    lengths = [f for pts in points.values() for f, _ in pts]
    if not points or max(lengths) < 2 * min(lengths):  # all clips about one length: nothing to show
        return None
    from mocapkit.evaluation.plots import pyplot, save_figure

    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.5, 4.4))
    styles = _styles(points)
    markers = "os^vD<>ph*X"
    for i, (label, pts) in enumerate(points.items()):
        x, y = np.asarray(pts, dtype=float).T
        ax.scatter(
            x,
            np.maximum(y, 1e-5),
            s=10,
            alpha=0.6,
            label=label,
            color=styles[label]["color"],
            marker=markers[i % len(markers)],
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("frames")
    ax.set_ylabel("refine wall time (s)")
    ax.set_title("refine time per clip (every protocol and seed)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7, frameon=False, loc="center left", bbox_to_anchor=(1.0, 0.5))
    return save_figure(fig, path)


__all__ = ["RefinementBenchmark", "central_crop", "clip_seed_for", "fold_table", "list_clips", "parse_protocol"]
