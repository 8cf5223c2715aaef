"""The Kinect posture-reconstruction benchmark of the comparison runner (Zhou 2014 ch. 5 on simulated pairs).

No paired Kinect + mocap recording exists here, so every clip of a mocap folder (HDM05 cuts by default) is turned
into a (Kinect, mocap) pair by the calibrated Kinect v1 noise simulator
(:func:`~mocapkit.datasets.synthetic.kinect_noise.simulate_pairs`, 30 fps, Kinect-20 joints). **The cell's seed is
the simulation seed** (and the estimators' ``random_state``): seeds draw new noise on the same clips.

Protocols are held-out performers: protocol ``mm`` trains on the other performers' pairs and scores every clip of
``mm``. Samples are the clips; ``group`` is the performer folder's name. With ``transfer_root`` another data set
(Bandai's BVH takes, another studio, other actors and another skeleton mapped to the same 20 joints) is one more
protocol, ``transfer_name``: trained on **every** performer of ``root`` and scored on all of its clips; it is never
part of the training side of the other protocols.

Estimators follow :class:`~mocapkit.kinect.reconstruction.KinectPostureReconstructor`'s contract:
``fit(kinect_clips, mocap_clips, states)`` and ``predict(kinect_clips, state=states)`` on lists of ``[T, 20, 3]``
metres. Metrics (per cell, pooled over every test frame): ``error_cm`` (eqs 5.7–5.9, per-frame mean joint error,
:func:`~mocapkit.kinect.metrics.joint_error_cm`), ``raw_cm`` (the simulated Kinect's own error on the same
frames), ``reduction`` (1 − error / raw), ``frames_per_s`` (``predict`` on the whole test set as one batch of
clips, one process) and ``fit_seconds``.

Hyper-parameter selection (``select:`` of a method) never sees the held-out performer:
:meth:`KinectReconstructionBenchmark.cross_validate` holds out each training performer in turn (leave one group
out; ``cv`` caps how many) and scores ``−error_cm``. Fits are cached per (estimator class, fit-relevant
parameters, training clips, seed): parameters an estimator lists in ``predict_params`` (the energy weights of
Zhou's method) change without a refit, so a whole ablation shares one GP fit per fold.
"""

from __future__ import annotations

import copy
import time
from pathlib import Path

import numpy as np

from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split, mean_sd
from mocapkit.kinect.metrics import joint_error_cm

HEADLINE = ["error_cm", "reduction", "frames_per_s"]


class KinectReconstructionBenchmark(Benchmark):
    """Held-out-performer Kinect reconstruction on simulated pairs of a mocap folder (see the module docstring).

    Args:
        root: a folder of motion files, one sub-folder per performer (``../shared/data/hdm05_cuts11``).
        protocols: the held-out performers (sub-folder names), and ``transfer_name``; default: all of them.
        fps: the simulated Kinect's frame rate.
        clips_per_group: read only this many clips of each performer (a seeded subset; None: all), for quick runs.
        clip_seed: the seed of that subset.
        cache_fits: reuse a fit across methods and cells that differ only in prediction parameters.
        noise: the simulator's calibration, a :data:`~mocapkit.datasets.synthetic.kinect_noise.NOISE_PRESETS` name
            (``mean_error``: the default config; ``msr_steadiness``: as steady as MSR Action3D's real skeletons).
        transfer_root: a folder of motion files of another data set (searched recursively), scored as the
            protocol ``transfer_name`` by models trained on all of ``root`` (module docstring); None: none.
        transfer_name: that protocol's (and group's) name.
        real_inputs: folders or files of real Kinect skeletons (MSR Action3D, NTU ``.skeleton``; no ground truth):
            every fitted model also corrects them, and the cell reports the real-data proxies before and after
            (:func:`~mocapkit.kinect.metrics.steadiness_summary`: ``real_bone_sd_not_worse``, ``real_jitter_not_worse``
            (shares of files), ``real_bone_sd_after`` / ``_before``, ``real_jitter_after`` / ``_before`` (cm, means),
            ``real_new_swap_events``); None: none.
        real_max_files: read only this many of them (every k-th in name order, evenly spread); None: all.
    """

    title = "Kinect posture reconstruction (simulated Kinect v1 from real mocap, held-out performers)"
    percent_metrics = ("reduction",)
    selection_cv = (
        "validation on training performers held out in turn (the first `cv` in name order; error in cm, negated)"
    )

    def __init__(
        self,
        root: str,
        protocols: list[str] | None = None,
        fps: float = 30.0,
        clips_per_group: int | None = None,
        clip_seed: int = 0,
        cache_fits: bool = True,
        noise: str = "mean_error",
        transfer_root: str | None = None,
        transfer_name: str = "transfer",
        real_inputs: list[str] | None = None,
        real_max_files: int | None = None,
    ):
        from mocapkit.datasets.formats.motion_io import find_motion_files
        from mocapkit.datasets.synthetic.kinect_noise import KinectNoiseConfig

        try:
            self._noise_config = KinectNoiseConfig.preset(noise)
        except ValueError as exc:
            raise ComparisonError(f"benchmark.noise={noise!r}: {exc}") from None
        self.noise = noise

        self.root = Path(root)
        if not self.root.is_dir():
            raise ComparisonError(f"benchmark.root={root}: not a folder")
        files = [f for f in find_motion_files(self.root) if f.parent != self.root]
        if not files:
            raise ComparisonError(f"benchmark.root={root}: no motion files in per-performer sub-folders")
        group_of = {f: f.parent.name for f in files}
        groups = sorted(set(group_of.values()))
        self.transfer_root, self.transfer_name = (None if transfer_root is None else Path(transfer_root)), None
        if transfer_root is not None:
            transfer_name = str(transfer_name)
            if transfer_name in groups:
                raise ComparisonError(f"benchmark.transfer_name={transfer_name!r} is a performer folder of {root}")
            if not self.transfer_root.is_dir():
                raise ComparisonError(f"benchmark.transfer_root={transfer_root}: not a folder")
            extra = find_motion_files(self.transfer_root)
            if not extra:
                raise ComparisonError(f"benchmark.transfer_root={transfer_root}: no motion files")
            group_of.update({f: transfer_name for f in extra})
            files = files + extra
            self.transfer_name = transfer_name
        if clips_per_group is not None:
            rng = np.random.default_rng(clip_seed)
            kept = []
            for g in groups + ([self.transfer_name] if self.transfer_name else []):
                mine = [f for f in files if group_of[f] == g]
                kept += [mine[i] for i in sorted(rng.choice(len(mine), min(clips_per_group, len(mine)), replace=False))]
            files = kept
        self.files = sorted(files)
        self.groups = np.array([group_of[f] for f in self.files])
        self.protocols = (
            tuple(protocols) if protocols else tuple(groups) + ((self.transfer_name,) if self.transfer_name else ())
        )
        unknown = [p for p in self.protocols if p not in groups and p != self.transfer_name]
        if unknown:
            raise ComparisonError(f"benchmark.protocols: {unknown} are not performer folders of {root} ({groups})")
        self.fps, self.clips_per_group, self.clip_seed = float(fps), clips_per_group, clip_seed
        self.cache_fits = bool(cache_fits)
        self.real_inputs = [str(p) for p in (real_inputs or [])]
        self.real_max_files = real_max_files
        self._real: list | None = None
        self._pairs: dict[int, list] = {}
        self._fits: dict[tuple, tuple[object, float]] = {}

    # ------------------------------------------------------------------ data
    def pairs(self, seed: int) -> list:
        """The simulated :class:`~mocapkit.datasets.synthetic.kinect_noise.KinectPair` of every clip for ``seed``."""
        if seed not in self._pairs:
            from mocapkit.datasets.synthetic.kinect_noise import simulate_pairs

            pairs, _ = simulate_pairs(self.files, self._noise_config, seed=seed, fps=self.fps)
            self._pairs[seed] = pairs
        return self._pairs[seed]

    def data(self, indices: np.ndarray, seed: int = 0):
        """``(kinect clips, mocap clips)`` of samples ``indices`` simulated with ``seed``: lists of ``[T, 20, 3]``."""
        pairs = self.pairs(seed)
        return [pairs[i].noisy for i in indices], [pairs[i].clean for i in indices]

    def states(self, indices: np.ndarray, seed: int = 0) -> list[np.ndarray]:
        """The simulated tracking states ``[T, 20]`` of samples ``indices``."""
        pairs = self.pairs(seed)
        return [pairs[i].state for i in indices]

    def split(self, protocol: str, seed: int) -> Split:
        if protocol not in self.protocols:
            raise ComparisonError(f"unknown protocol {protocol!r}: this benchmark has {list(self.protocols)}")
        test = np.flatnonzero(self.groups == protocol)
        train = np.flatnonzero((self.groups != protocol) & (self.groups != self.transfer_name))
        return Split(
            protocol,
            seed,
            train,
            test,
            {"held_out": protocol, "train_groups": sorted(set(self.groups[train].tolist())), "simulation_seed": seed},
        )

    def describe(self) -> dict:
        return {
            "root": str(self.root),
            "n_clips": len(self.files),
            "fps": self.fps,
            "groups": {g: int((self.groups == g).sum()) for g in sorted(set(self.groups.tolist()))},
            "clips_per_group": self.clips_per_group,
            "clip_seed": self.clip_seed,
            "noise": self.noise,
            "transfer_root": None if self.transfer_root is None else str(self.transfer_root),
            "transfer_name": self.transfer_name,
            "real_inputs": self.real_inputs,
            "real_max_files": self.real_max_files,
        }

    def real_clips(self) -> list[tuple[str, np.ndarray, np.ndarray, int]]:
        """``(file, positions [T, 20, 3], state [T, 20], swap lag)`` of every file of ``real_inputs`` (read once;
        :func:`~mocapkit.kinect.kinect_fix.read_kinect_file`; unreadable or all-zero files are left out)."""
        if self._real is None:
            from mocapkit.datasets.formats.motion_io import expand_motion_paths
            from mocapkit.kinect.kinect_fix import read_kinect_file, swap_lag

            self._real = []
            for root in self.real_inputs:
                files = expand_motion_paths([root], "benchmark.real_inputs", empty_error=ComparisonError)
                if self.real_max_files is not None and len(files) > self.real_max_files:
                    files = [files[i] for i in np.linspace(0, len(files) - 1, int(self.real_max_files)).astype(int)]
                for path in files:
                    try:
                        raw, state, _, fps = read_kinect_file(path)
                    except (OSError, ValueError):
                        continue
                    self._real.append((str(path), raw, state, swap_lag(fps)))
        return self._real

    def real_scores(self, fitted) -> dict:
        """The real-data proxies of ``fitted`` on :meth:`real_clips`, per source folder and pooled: ``{"all":
        summary, folder: summary}`` (:func:`~mocapkit.kinect.metrics.steadiness_summary`); {} without real inputs."""
        from mocapkit.kinect.metrics import steadiness, steadiness_summary

        clips = self.real_clips()
        if not clips:
            return {}
        fixed = fitted.predict([c[1] for c in clips], state=[c[2] for c in clips])
        before = [steadiness(c[1], c[3]) for c in clips]
        after = [steadiness(f, c[3]) for f, c in zip(fixed, clips)]
        out = {"all": steadiness_summary(before, after)}
        for root in self.real_inputs:
            mine = [k for k, c in enumerate(clips) if c[0].startswith(str(Path(root)))]
            if mine:
                out[root] = steadiness_summary([before[k] for k in mine], [after[k] for k in mine])
        return out

    # ------------------------------------------------------------------ scoring
    def _fitted(self, estimator, train: np.ndarray, seed: int) -> tuple[object, float, bool]:
        """``(estimator fitted on the pairs of train, fit seconds, from the cache?)``."""
        from sklearn.base import clone

        late = set(getattr(estimator, "predict_params", ()))
        params = estimator.get_params(deep=False)
        key = (
            type(estimator).__module__,
            type(estimator).__qualname__,
            repr(sorted((k, repr(v)) for k, v in params.items() if k not in late)),
            tuple(train.tolist()),
            seed,
        )
        if self.cache_fits and key in self._fits:
            fitted, seconds = self._fits[key]
            fitted = copy.deepcopy(fitted)
            fitted.set_params(**{k: v for k, v in params.items() if k in late})
            return fitted, seconds, True
        fitted = clone(estimator)
        kinect, mocap = self.data(train, seed)
        start = time.perf_counter()
        fitted.fit(kinect, mocap, self.states(train, seed))
        seconds = time.perf_counter() - start
        if self.cache_fits:
            self._fits[key] = (fitted, seconds)
        return fitted, seconds, False

    def _score(self, fitted, test: np.ndarray, seed: int) -> dict:
        kinect, mocap = self.data(test, seed)
        start = time.perf_counter()
        predicted = fitted.predict(kinect, state=self.states(test, seed))
        seconds = time.perf_counter() - start
        frames = np.array([len(k) for k in kinect], dtype=np.float64)
        total = frames.sum()
        # frame-weighted per-joint means; the overall error is their mean (every frame has all 20 joints)
        per_joint = sum(joint_error_cm(p, m, per_joint=True) * len(m) for p, m in zip(predicted, mocap)) / total
        per_joint_raw = sum(joint_error_cm(k, m, per_joint=True) * len(m) for k, m in zip(kinect, mocap)) / total
        return {
            "error_cm": float(per_joint.mean()),
            "raw_cm": float(per_joint_raw.mean()),
            "frames_per_s": float(total / max(seconds, 1e-9)),
            "n_frames": int(total),
            "per_joint_cm": per_joint.round(3).tolist(),
            "per_joint_raw_cm": per_joint_raw.round(3).tolist(),
        }

    def evaluate_estimator(self, estimator, split: Split) -> dict:
        fitted, fit_seconds, cached = self._fitted(estimator, split.train, split.seed)
        scores = self._score(fitted, split.test, split.seed)
        metrics = {
            "error_cm": scores["error_cm"],
            "raw_cm": scores["raw_cm"],
            "reduction": 1.0 - scores["error_cm"] / scores["raw_cm"],
            "frames_per_s": scores["frames_per_s"],
            "fit_seconds": fit_seconds,
        }
        real = self.real_scores(fitted)
        if real:
            pooled = real["all"]
            for key in ("bone_sd_cm", "jitter_cm"):
                short = key.removesuffix("_cm")
                metrics[f"real_{short}_not_worse"] = pooled[f"{key}_not_worse"]
                metrics[f"real_{short}_before"] = pooled[f"{key}_before"]
                metrics[f"real_{short}_after"] = pooled[f"{key}_after"]
            metrics["real_new_swap_events"] = pooled["new_swap_events"]
        detail = {
            "real": real,
            "n_test_frames": scores["n_frames"],
            "fit_cached": cached,
            "per_joint_cm": scores["per_joint_cm"],
            "per_joint_raw_cm": scores["per_joint_raw_cm"],
        }
        return {"metrics": metrics, "detail": detail}

    def cross_validate(self, estimator, train: np.ndarray, folds: int, seed: int) -> float:
        """``−error_cm`` pooled over the frames of each training performer held out in turn (the first ``folds``
        performers in name order when there are more), each scored by a fit on the other training performers."""
        groups = sorted(set(self.groups[train].tolist()))
        if len(groups) < 2:
            raise ComparisonError(f"selection needs at least 2 training performers, got {groups}")
        weighted, frames = 0.0, 0
        for group in groups[: max(1, int(folds))]:
            inner_train = train[self.groups[train] != group]
            inner_test = train[self.groups[train] == group]
            fitted, _, _ = self._fitted(estimator, inner_train, seed)
            scores = self._score(fitted, inner_test, seed)
            weighted += scores["error_cm"] * scores["n_frames"]
            frames += scores["n_frames"]
        return -weighted / frames

    # ------------------------------------------------------------------ presentation
    def headline(self, protocol: str) -> list[str]:
        return HEADLINE

    def markdown(self, results: dict) -> str:
        cells = results.get("cells", [])
        if not cells:
            return ""
        keys = list(dict.fromkeys(c["method"] for c in cells))
        lines = []
        transfer = self.transfer_name
        for title, chosen in (
            ("Over all held-out performers", lambda c: c["protocol"] != transfer),
            (
                f"Another data set: `{transfer}`, by models trained on every performer",
                lambda c: c["protocol"] == transfer,
            ),
        ):
            table = self._pooled_table(title, [c for c in cells if chosen(c)], keys)
            lines += table
        return "\n".join(lines) + "\n" if lines else ""

    def _pooled_table(self, title: str, cells: list, keys: list) -> list[str]:
        """Markdown lines of one pooled table (frame-weighted over the cells' protocols, mean ± sd over seeds)."""
        if not cells:
            return []
        lines = [
            f"## {title}",
            "",
            (
                "Frame-weighted mean joint error (cm) over every test frame of every protocol, per seed; mean ± sd "
                "over seeds. `raw` is the simulated Kinect input on the same frames."
            ),
            "",
            "| method | error (cm) | raw (cm) | reduction | frames/s |",
            "|---|---|---|---|---|",
        ]
        for key in keys:
            mine = [c for c in cells if c["method"] == key and "metrics" in c]
            by_seed: dict[int, list] = {}
            for c in mine:
                by_seed.setdefault(c["seed"], []).append(c)
            errors, raws, speeds = [], [], []
            for seed_cells in by_seed.values():
                n = np.array([c["detail"]["n_test_frames"] for c in seed_cells], dtype=np.float64)
                errors.append(np.array([c["metrics"]["error_cm"] for c in seed_cells]) @ n / n.sum())
                raws.append(np.array([c["metrics"]["raw_cm"] for c in seed_cells]) @ n / n.sum())
                speeds += [c["metrics"]["frames_per_s"] for c in seed_cells]
            if not errors:
                continue
            reduction = [1.0 - e / r for e, r in zip(errors, raws)]
            label = mine[0]["label"]
            lines.append(
                f"| {label} | {mean_sd(errors, 2)} | {mean_sd(raws, 2)} | "
                f"{mean_sd([100 * r for r in reduction], 1)} % | {np.median(speeds):,.0f} |"
            )
        return lines + [""]

    def plots(self, results: dict, out_dir: Path) -> list[Path]:
        """``per_joint_error.png``: each method's error per joint (pooled over the held-out performers, first seed)
        beside raw; ``per_joint_error_<transfer>.png`` the same on the other data set."""
        cells = [c for c in results.get("cells", []) if "detail" in c and "per_joint_cm" in (c["detail"] or {})]
        if not cells:
            return []
        seed = min(c["seed"] for c in cells)
        cells = [c for c in cells if c["seed"] == seed]
        out = []
        performers = [c for c in cells if c["protocol"] != self.transfer_name]
        if performers:
            out.append(
                _per_joint_plot(
                    performers,
                    f"Per-joint error over all held-out performers (seed {seed})",
                    Path(out_dir) / "per_joint_error.png",
                )
            )
        transfer = [c for c in cells if c["protocol"] == self.transfer_name]
        if transfer:
            out.append(
                _per_joint_plot(
                    transfer,
                    f"Per-joint error on {self.transfer_name}, trained on every performer (seed {seed})",
                    Path(out_dir) / f"per_joint_error_{self.transfer_name}.png",
                )
            )
        return out


def _per_joint_plot(cells: list, title: str, path: Path) -> Path:
    """One figure: each method's frame-weighted per-joint error over ``cells`` beside the raw input's."""
    from mocapkit.evaluation.plots import pyplot, save_figure
    from mocapkit.motion.layouts import LANDMARK_NAMES

    plt = pyplot()
    keys = list(dict.fromkeys(c["method"] for c in cells))
    fig, ax = plt.subplots(figsize=(11, 4.2))
    x = np.arange(len(LANDMARK_NAMES))

    def pooled(mine, field):
        n = np.array([c["detail"]["n_test_frames"] for c in mine], dtype=np.float64)
        return np.array([c["detail"][field] for c in mine]).T @ n / n.sum()

    ax.plot(x, pooled([c for c in cells if c["method"] == keys[0]], "per_joint_raw_cm"), "k--", label="raw Kinect")
    for key in keys:
        mine = [c for c in cells if c["method"] == key]
        ax.plot(x, pooled(mine, "per_joint_cm"), marker="o", ms=3, label=mine[0]["label"])
    ax.set_xticks(x, LANDMARK_NAMES, rotation=60, ha="right", fontsize=8)
    ax.set_ylabel("mean joint error (cm)")
    ax.set_title(title)
    ax.legend(fontsize=7, ncol=2)
    ax.grid(alpha=0.3)
    return save_figure(fig, path)
