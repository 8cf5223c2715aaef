"""The motion-variation synthesis benchmark of the comparison runner (Zhou 2014 ch. 4,
``../shared/spec/thesis-zhou-2014-retrieval-synthesis.md`` §3.7 and §7 gaps 20 and 22): synthesisers ×
motion types × seeds on real HDM05, CMU and Bandai clips.

**Protocols** are motion types: on HDM05 (``dataset="hdm05"``) the class part of
``HDM_<actor>_<class>_<nnn>_120.amc`` (``hopBothLegs1hops``, ``squat1Reps``, ...); on Bandai the content of
``dataset-1_<content>_<style>_<nnn>.bvh`` (``walk``, ``bow``, ...; BVH clips converted to ASF/AMC); on CMU, whose
file names carry no motion type, a name that ``types`` maps to a list of takes (``walk_uneven: [03_01, ...]``). With
``window_seconds`` every take is cut into consecutive windows of that length
(:func:`~mocapkit.synthesis.clips.clip_windows`; CMU's walks are minute-long takes of one motion) and the
windows are the clips. **Split** of a type for a seed: ``n_train`` clips (10, as the thesis) drawn with
``numpy.random.default_rng(seed)`` from the type's clips of every performer are the training side; all the other
clips of the type are held out, as the real references of the naturalness measures (the synthesisers never see
them). With ``heldout_takes``, the draw is from the other takes and only those takes' clips are the references (so
no reference window is the neighbour of a training window in the same take).

**A cell** (:meth:`SynthesisBenchmark.evaluate_estimator`): ``fit`` on the training clips, then
``sample(n_variants, seed=seed)`` (20 variants, as the thesis's Fig. 4.6) of the mean training length on the
reference skeleton (the first training clip's ASF). Metrics (:mod:`mocapkit.synthesis.metrics` for their
definitions and units):

- ``v_variants`` (eq. 4.5 on the variants, metres × path steps), ``v_variants_per_step`` (path-length
  normalised, metres); ``v_train``: the training clips' own V; ``v_ratio = v_variants / v_train``;
  ``v_heldout``: the held-out clips' V. Real clips are **posed on the reference skeleton** by their own AMC
  angles for every V and for the feature distance (so that the performers' body sizes do not count as
  variation: the variants all have the reference body);
- ``foot_skating_cms`` (cm/s), ``bone_drift_mm`` (mm), ``jerk`` (m/s³): means over the variants; the same on
  the held-out real clips, as recorded (their own skeletons): ``real_foot_skating_cms``, ``real_bone_drift_mm``,
  ``real_jerk``;
- ``feature_distance``: mean over the variants of the standardised mean/sd distance of their per-frame pose and
  velocity features to the held-out clips pooled; ``feature_distance_real`` ± ``feature_distance_real_sd``: the
  same distance of each held-out clip to the other held-out clips (the reference spread); ``within_real``: the
  fraction of variants no farther than the farthest held-out clip;
- **within the spread of the real clips, proxy by proxy** (:func:`~mocapkit.synthesis.metrics.within_spread`:
  no larger than the largest held-out clip's value): ``within_real_skating``, ``within_real_jerk``, and
  ``within_real_all``, the fraction of variants within on *every* proxy at once (foot skating, jerk, bone drift
  and the feature distance) — the issue's naturalness goal asks for that one;
- ``fit_seconds`` (wall time of ``fit``), ``sample_seconds_per_second`` (wall time of ``sample`` per second of
  generated motion; the thesis: 0.17 s per 1 s on HDM05).

The real-clip numbers depend only on the split and are computed once per (protocol, seed). ``select:`` of the
runner (classifier cross-validation) does not apply. :meth:`~SynthesisBenchmark.markdown` adds one table per
protocol with the variants' numbers beside the real references; :meth:`~SynthesisBenchmark.plots` draws V per
method with the training set's and the held-out set's V as lines (``variation.png``).
"""

from __future__ import annotations

import math
import time
import zlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split

#: Metric name → digits in the tables.
DIGITS = {
    "v_variants": 1,
    "v_train": 1,
    "v_heldout": 1,
    "v_ratio": 3,
    "v_variants_per_step": 3,
    "foot_skating_cms": 1,
    "real_foot_skating_cms": 1,
    "real_foot_skating_cms_max": 1,
    "bone_drift_mm": 4,
    "real_bone_drift_mm": 4,
    "jerk": 0,
    "real_jerk": 0,
    "real_jerk_max": 0,
    "feature_distance": 3,
    "feature_distance_real": 3,
    "feature_distance_real_sd": 3,
    "fit_seconds": 2,
    "sample_seconds_per_second": 3,
}


class SynthesisBenchmark(Benchmark):
    """Variation synthesisers on real motion types (module docstring).

    Args:
        root: the folder of ``dataset`` (:func:`~mocapkit.datasets.mocap.folders.list_clips`;
            ``../shared/data/hdm05_cuts11``: ``<actor>/HDM_<actor>_<class>_<nnn>_120.amc``; ``../shared/data/cmu_amc``).
        protocols: the motion types to run; each needs ``n_train`` clips to draw from and two more held out.
        n_train: training clips per split.
        n_variants: variants sampled per cell.
        dataset: ``"hdm05"``, ``"cmu"`` (ASF/AMC: the synthesisers learn joint angles) or ``"bandai"`` (BVH, the
            protocols are contents such as ``walk``; every clip is converted exactly to ASF/AMC on one T-pose rest
            made from the first clip's frame 0 by path, :func:`~mocapkit.synthesis.clips.as_amc_clips`).
        types: motion type → take names (file stems, e.g. ``03_01``), for data sets whose names carry no type.
        window_seconds: cut every take into windows of this many seconds; ``None``: a file is a clip.
        heldout_takes: takes whose clips are only ever held out (references), never drawn for training.
    """

    title = "Motion variation synthesis on real motion types"
    percent_metrics = ("within_real", "within_real_skating", "within_real_jerk", "within_real_all")

    def __init__(
        self,
        root: str,
        protocols: list[str],
        n_train: int = 10,
        n_variants: int = 20,
        dataset: str = "hdm05",
        types: dict | None = None,
        window_seconds: float | None = None,
        heldout_takes: list[str] | None = None,
    ):
        if dataset not in ("hdm05", "cmu", "bandai"):
            raise ComparisonError(
                f"benchmark.dataset={dataset!r}: one of 'hdm05', 'cmu' (ASF/AMC) or 'bandai' (BVH, "
                "converted to ASF/AMC)"
            )
        if root is None:
            raise ComparisonError(f"benchmark.root is not set: give the {dataset} folder")
        if not protocols:
            raise ComparisonError("benchmark.protocols: give at least one motion type, e.g. hopBothLegs1hops")
        if int(n_train) < 2 or int(n_variants) < 2:
            raise ComparisonError(
                f"benchmark.n_train={n_train}, n_variants={n_variants}: both must be >= 2 (V averages pairs)"
            )
        from mocapkit.datasets.formats.errors import MotionFormatError
        from mocapkit.datasets.mocap.folders import (
            MocapFolderError,
            list_clips,
            read_clips,
        )
        from mocapkit.synthesis.clips import as_amc_clips, clip_windows

        self.root, self.n_train, self.n_variants = Path(root), int(n_train), int(n_variants)
        self.dataset, self.window_seconds = dataset, window_seconds
        self.heldout_takes = tuple(str(t) for t in heldout_takes or ())
        try:
            found = list_clips(dataset, self.root)
        except MocapFolderError as exc:
            raise ComparisonError(f"benchmark.{exc}") from exc
        wanted = [str(p) for p in protocols]
        if types is not None:  # file names carry no motion type (CMU): the type is a list of takes
            types = {str(k): [str(t) for t in v] for k, v in dict(types).items()}
            unknown = sorted(set(wanted) - set(types))
            if unknown:
                raise ComparisonError(f"benchmark.protocols: {unknown} not among benchmark.types {sorted(types)}")
            take_type = {take: name for name, takes in types.items() for take in takes}
            names = {c["name"] for c in found}
            missing = sorted(set(take_type) - names)
            if missing:
                raise ComparisonError(f"benchmark.types: takes {missing} not found under {self.root}")
            found = [{**c, "class": take_type[c["name"]]} for c in found if c["name"] in take_type]
        missing = sorted(set(self.heldout_takes) - {c["name"] for c in found})
        if missing:
            raise ComparisonError(f"benchmark.heldout_takes: {missing} are not takes of benchmark.protocols")
        found = [c for c in found if c["class"] in wanted]
        try:
            motions = as_amc_clips(read_clips(found))  # BVH (Bandai): one T-pose rest, the first clip's
        except (MocapFolderError, MotionFormatError) as exc:
            raise ComparisonError(f"benchmark: {exc}") from exc
        self.motions, self.clips, self.frames_left_out = [], [], {}
        for clip, motion in zip(found, motions):
            if window_seconds is None:
                pieces = [motion]
            else:
                try:  # named after the take, so the windows are <take>[start:stop] (clip_segment's names)
                    pieces = clip_windows(replace(motion, name=clip["name"]), window_seconds)
                except ValueError as exc:
                    raise ComparisonError(f"benchmark.window_seconds: {exc}") from exc
                self.frames_left_out[clip["name"]] = motion.num_frames - sum(p.num_frames for p in pieces)
            for piece in pieces:
                self.motions.append(piece)
                self.clips.append(
                    {
                        "name": clip["name"] if window_seconds is None else piece.name,
                        "take": clip["name"],
                        "class": clip["class"],
                        "group": clip["group"],
                    }
                )
        self.classes = np.asarray([c["class"] for c in self.clips])
        short = {}
        for p in wanted:
            mine = [c for c in self.clips if c["class"] == p]
            drawable = sum(1 for c in mine if c["take"] not in self.heldout_takes)
            references = len(mine) - drawable if self.heldout_takes else len(mine) - self.n_train
            if drawable < self.n_train or references < 2:
                short[p] = {"to draw from": drawable, "held out": references}
        if short:
            raise ComparisonError(
                f"benchmark.protocols: {short} clips under {self.root}; each motion type needs "
                f"n_train = {self.n_train} clips to draw from and at least two held out"
            )
        self.protocols = tuple(wanted)
        self._references: dict[tuple[str, int], dict] = {}

    # -------------------------------------------------------------- data
    def describe(self) -> dict:
        out = {
            "dataset": self.dataset,
            "root": str(self.root),
            "n_train": self.n_train,
            "n_variants": self.n_variants,
            "clips": {p: int((self.classes == p).sum()) for p in self.protocols},
            "fps": float(self.motions[0].fps),
        }
        if self.window_seconds is not None:
            out.update(window_seconds=float(self.window_seconds), frames_left_out=self.frames_left_out)
        if self.heldout_takes:
            out["heldout_takes"] = list(self.heldout_takes)
        return out

    def data(self, indices: np.ndarray):
        """The clips (AMC :class:`~mocapkit.motion.container.Motion`, positions ``[T_i, 31, 3]`` metres) and
        their motion types (``[n]`` str) of ``indices``."""
        indices = np.asarray(indices, dtype=np.int64)
        return [self.motions[i] for i in indices], self.classes[indices]

    def split(self, protocol: str, seed: int) -> Split:
        """``n_train`` clips of the type drawn with ``default_rng([seed, crc32(type)])``; the rest held out (with
        ``heldout_takes``: drawn from the other takes' clips, and only the held-out takes' clips are the
        references)."""
        if protocol not in self.protocols:
            raise ComparisonError(f"protocol {protocol!r}: not among benchmark.protocols {list(self.protocols)}")
        mine = np.flatnonzero(self.classes == protocol)
        held = np.asarray([self.clips[i]["take"] in self.heldout_takes for i in mine], dtype=bool)
        rng = np.random.default_rng([int(seed), zlib.crc32(protocol.encode())])
        train = np.sort(rng.choice(mine[~held], size=self.n_train, replace=False)).astype(np.int64)
        test = (mine[held] if held.any() else np.setdiff1d(mine, train)).astype(np.int64)
        groups = lambda idx: sorted({self.clips[i]["group"] for i in idx})
        return Split(
            protocol,
            seed,
            train,
            test,
            {
                "train_clips": [self.clips[i]["name"] for i in train],
                "train_performers": groups(train),
                "heldout_performers": groups(test),
                "train_frames": [self.motions[i].num_frames for i in train],
            },
        )

    # -------------------------------------------------------------- scoring
    def references(self, split: Split) -> dict:
        """The split's real-clip numbers (computed once per protocol and seed): ``{"metrics", "heldout"}`` with
        ``heldout`` the held-out clips posed on the reference skeleton."""
        from mocapkit.synthesis.clips import on_skeleton
        from mocapkit.synthesis.metrics import clip_naturalness, proxy_means, variation

        key = (split.protocol, split.seed)
        if key not in self._references:
            train, _ = self.data(split.train)
            heldout, _ = self.data(split.test)
            skeleton = train[0].metadata["asf"]
            posed_train = [on_skeleton(m, skeleton) for m in train]
            posed_heldout = [on_skeleton(m, skeleton) for m in heldout]
            proxies = clip_naturalness(heldout)
            real = proxy_means(proxies)
            metrics = {
                "v_train": variation(posed_train).v,
                "v_heldout": variation(posed_heldout).v,
                **{f"real_{k}": v for k, v in real.items()},
                **{
                    f"real_{k}_max": float(np.nanmax(v)) if np.isfinite(v).any() else float("nan")
                    for k, v in proxies.items()
                    if k != "bone_drift_mm"
                },
            }
            self._references[key] = {"metrics": metrics, "heldout": posed_heldout, "proxies": proxies}
        return self._references[key]

    def evaluate_estimator(self, estimator, split: Split) -> dict:
        """Fit on the training clips, sample ``n_variants`` of the mean training length with the cell's seed,
        score them against the references (module docstring)."""
        from mocapkit.synthesis.metrics import (
            clip_naturalness,
            feature_distances,
            proxies_within,
            proxy_means,
            variation,
        )

        train, _ = self.data(split.train)
        start = time.perf_counter()
        estimator.fit(train)
        fit_seconds = time.perf_counter() - start
        start = time.perf_counter()
        variants = estimator.sample(self.n_variants, seed=split.seed)
        sample_seconds = time.perf_counter() - start
        reference = self.references(split)
        v = variation(variants)
        distances = feature_distances(variants, reference["heldout"])
        proxies = clip_naturalness(variants)
        within = proxies_within(proxies, reference["proxies"], distances)
        frames = variants[0].num_frames
        metrics = {
            "v_variants": v.v,
            "v_variants_per_step": v.v_per_step,
            **reference["metrics"],
            "v_ratio": v.v / reference["metrics"]["v_train"],
            **proxy_means(proxies),
            **distances.summary(),
            "within_real_skating": float(within["foot_skating_cms"].mean()),
            "within_real_jerk": float(within["jerk"].mean()),
            "within_real_all": float(within["every_proxy"].mean()),
            "fit_seconds": fit_seconds,
            "sample_seconds_per_second": sample_seconds / (len(variants) * frames / variants[0].fps),
        }
        detail = {
            "n_frames": frames,
            "fps": float(variants[0].fps),
            "n_variants": len(variants),
            "train_clips": split.info["train_clips"],
            "n_heldout": len(split.test),
            "variant_feature_distances": distances.variants.tolist(),
            "real_feature_distances": distances.real.tolist(),
            "variant_proxies": {k: v.tolist() for k, v in proxies.items()},
            "real_proxies": {k: v.tolist() for k, v in reference["proxies"].items()},
            "fitted": {
                k: _json(getattr(estimator, k))
                for k in (
                    "width_",
                    "cv_log_likelihood_",
                    "sigma_",
                    "train_seconds_",
                    "noise_scale_",
                    "variation_by_noise_scale_",
                )
                if hasattr(estimator, k)
            },
            "angle_flips": [list(flip) for flip in getattr(estimator, "angle_flips_", [])],
        }
        return {"metrics": metrics, "detail": detail}

    # -------------------------------------------------------------- presentation
    def headline(self, protocol: str) -> list[str]:
        return [
            "v_variants",
            "v_ratio",
            "foot_skating_cms",
            "jerk",
            "feature_distance",
            "within_real",
            "within_real_all",
            "fit_seconds",
            "sample_seconds_per_second",
        ]

    def format_metric(self, name, mean, sd=None) -> str:
        if mean is None or (isinstance(mean, float) and math.isnan(mean)):
            return "–"
        if name in self.percent_metrics:
            return super().format_metric(name, mean, sd)
        digits = DIGITS.get(name, 3)
        return f"{mean:.{digits}f}" + (f" ± {sd:.{digits}f}" if sd is not None else "")

    def markdown(self, results: dict) -> str:
        rows = results.get("summary") or []
        if not rows:
            return ""
        lines = [
            "## Variation and naturalness per motion type",
            "",
            (
                "V: Zhou eq. 4.5, mean pairwise DTW cost of root-normalised joint positions (Euclidean local cost, "
                "unnormalised path sum; metres × steps) of the variants, all on the reference skeleton; ratio: "
                "V / V of the training clips. Naturalness proxies: foot skating (cm/s during contacts), jerk "
                "(m/s³), bone-length drift (mm); feature distance: standardised mean/sd distance of per-frame pose "
                "and velocity features to the held-out real clips (dimensionless), beside the real clips' own "
                "leave-one-out distance (mean ± sd over held-out clips). Mean over seeds."
            ),
            "",
        ]
        for protocol in results["protocols"]:
            mine = [r for r in rows if r["protocol"] == protocol]
            if not mine:
                continue
            get = lambda r, k: (r["metrics"].get(k) or {}).get("mean")
            first = mine[0]
            fmt = self.format_metric
            lines += [
                f"### {protocol}",
                "",
                (
                    f"Training set V = {fmt('v_train', get(first, 'v_train'))}, held-out set V = "
                    f"{fmt('v_heldout', get(first, 'v_heldout'))}; held-out real clips: foot skating "
                    f"{fmt('real_foot_skating_cms', get(first, 'real_foot_skating_cms'))} cm/s (at most "
                    f"{fmt('real_foot_skating_cms_max', get(first, 'real_foot_skating_cms_max'))}), jerk "
                    f"{fmt('real_jerk', get(first, 'real_jerk'))} m/s³ (at most "
                    f"{fmt('real_jerk_max', get(first, 'real_jerk_max'))}), bone drift "
                    f"{fmt('real_bone_drift_mm', get(first, 'real_bone_drift_mm'))} mm, feature distance "
                    f"{fmt('feature_distance_real', get(first, 'feature_distance_real'))} ± "
                    f"{fmt('feature_distance_real_sd', get(first, 'feature_distance_real_sd'))}."
                ),
                "",
                (
                    "| method | V | V / V_train | V per step (m) | foot skating (cm/s) | jerk (m/s³) | "
                    "bone drift (mm) | feature distance | within real: distance | skating | jerk | "
                    "every proxy | fit (s) | sample (s per s) |"
                ),
                "|---|" + "---|" * 13,
            ]
            for r in mine:
                cells = [
                    fmt(k, get(r, k))
                    for k in (
                        "v_variants",
                        "v_ratio",
                        "v_variants_per_step",
                        "foot_skating_cms",
                        "jerk",
                        "bone_drift_mm",
                        "feature_distance",
                        "within_real",
                        "within_real_skating",
                        "within_real_jerk",
                        "within_real_all",
                        "fit_seconds",
                        "sample_seconds_per_second",
                    )
                ]
                lines.append(f"| {r['label']} | " + " | ".join(cells) + " |")
            lines.append("")
        return "\n".join(lines)

    def plots(self, results: dict, out_dir: Path) -> list[Path]:
        rows = results.get("summary") or []
        protocols = [p for p in results["protocols"] if any(r["protocol"] == p for r in rows)]
        if not protocols:
            return []
        from mocapkit.evaluation.plots import pyplot, save_figure

        plt = pyplot()
        fig, axes = plt.subplots(1, len(protocols), figsize=(4.8 * len(protocols), 4.0), squeeze=False)
        for ax, protocol in zip(axes[0], protocols):
            mine = [r for r in rows if r["protocol"] == protocol]
            labels = [r["label"] for r in mine]
            means = [r["metrics"]["v_variants"]["mean"] for r in mine]
            sds = [r["metrics"]["v_variants"]["sd"] for r in mine]
            ax.bar(range(len(mine)), means, yerr=sds, capsize=3, color="tab:blue", alpha=0.8)
            for key, style, name in (("v_train", "-", "training set"), ("v_heldout", "--", "held-out set")):
                value = (mine[0]["metrics"].get(key) or {}).get("mean")
                if value is not None:
                    ax.axhline(value, color="k", linestyle=style, lw=1, label=f"{name} V")
            ax.set_xticks(range(len(mine)), labels, rotation=25, ha="right", fontsize=8)
            ax.set_title(protocol, fontsize=9)
            ax.set_ylabel("V (Zhou eq. 4.5; m × DTW steps)")
            ax.grid(axis="y", alpha=0.3)
            ax.legend(fontsize=7, frameon=False)
        fig.suptitle(
            f"Variation of {results['benchmark'].get('n_variants', '')} variants per method "
            f"(mean ± sd over seeds {results['seeds']})",
            fontsize=10,
        )
        return [save_figure(fig, Path(out_dir) / "variation.png")]


def _json(value):
    """A fitted attribute as JSON (floats, lists, dicts with string keys)."""
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict):
        return {str(k): _json(v) for k, v in value.items()}
    return float(value) if isinstance(value, (int, float, np.floating, np.integer)) else repr(value)


__all__ = ["SynthesisBenchmark"]
