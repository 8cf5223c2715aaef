"""The motion-retrieval benchmark of the comparison runner: retrieval methods × protocols × seeds on real data.

Samples are the clips of one data set, read once with :func:`~mocapkit.datasets.read_motion`:

=============  ==================================================================================================
``dataset``    protocols (``benchmark.protocols``)
=============  ==================================================================================================
``hdm05``      ``cross_performer``: each actor in turn gives the queries, the other actors' clips are the
               database (relevance = same class); ``zhou_tp20``: Zhou 2014's top-20 agreement (TP ratio), leave
               one out over every clip of the classes shared with the thesis's set (:data:`ZHOU_SHARED`), the
               whole folder as the mixed database (the thesis fits and queries on one set: label-free methods
               only, a supervised or trained method is marked n/a)
``bandai``     ``content``: queries of one style against the database of the other styles, relevance = same
               content; ``style``: queries of one content against the other contents, relevance = same style
``msr``        ``cross_subject``: queries from subjects 2 4 6 8 10, the database subjects 1 3 5 7 9 (groups named
               ``"1"`` ... ``"10"``, as the data modules name them)
=============  ==================================================================================================

A cell (method, protocol, seed) runs every fold: the method is fitted on the fold's database only (labels
passed only to supervised methods, ``label_free = False``), then ranks the fold's queries. The seed reaches
the method as its ``random_state`` (k-means, K-SVD, ...); the splits do not depend on it.

Metrics (:func:`~mocapkit.retrieval.metrics.retrieval_metrics`, pooled over every query of every fold): ``map``,
``p@1``, ``p@10``, ``nn_accuracy`` (= ``p@1`` with relevance = same class), and ``fit_seconds`` (per fold),
``query_ms`` (encoding and ranking one query against its database, mean). ``zhou_tp20`` reports ``tp_ratio``.
The report keeps label-free methods (no labels, no training run), self-supervised ones (a run trained without
labels) and supervised ones in separate tables.
"""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split

#: The HDM05 classes of ``hdm05_cuts11`` that Zhou 2014's 10-class retrieval set also holds (§2.8 of the digest):
#: elbow-to-knee, hopping, kicking, squatting, throwing.
ZHOU_SHARED = ("elbowToKnee1RepsLelbowStart", "hopBothLegs1hops", "kickLFront1Reps", "squat1Reps", "throwBasketball")
#: Protocols of each data set: protocol → (label field, group field whose values are the folds).
PROTOCOLS = {
    "hdm05": {"cross_performer": ("class", "group"), "zhou_tp20": ("class", None)},
    "bandai": {"content": ("content", "style"), "style": ("style", "content")},
    "msr": {"cross_subject": ("action", "subject")},
}
MSR_TRAIN_SUBJECTS = (1, 3, 5, 7, 9)
HEADLINE = ["map", "p@1", "p@10", "nn_accuracy"]


class RetrievalBenchmark(Benchmark):
    """Query-by-example retrieval on a folder of real clips (see the module docstring).

    Args:
        dataset: ``"hdm05"``, ``"bandai"`` or ``"msr"``.
        root: the folder (``../shared/data/hdm05_cuts11``, ``bandai_motion_1``, ``msr_action3d``).
        protocols: names from :data:`PROTOCOLS` for the data set.
        clips_per_group: read only this many clips of each group (a seeded subset; None: all), for quick runs.
        clip_seed: the seed of that subset.
        n_folds: hold out groups in this many folds (groups dealt round-robin in sorted order: fold ``i`` holds
            groups ``i, i + n_folds, ...``) instead of one group per fold; None: one fold per group. Bandai has 15
            styles and 16 contents: 3 folds keep the trained methods to 3 runs per protocol.
    """

    title = "Motion retrieval"
    percent_metrics = ()

    def __init__(
        self,
        dataset: str,
        root: str,
        protocols: list[str],
        clips_per_group: int | None = None,
        clip_seed: int = 0,
        n_folds: int | None = None,
    ):
        if dataset not in PROTOCOLS:
            raise ComparisonError(f"benchmark.dataset={dataset!r}: one of {sorted(PROTOCOLS)}")
        unknown = [p for p in protocols if p not in PROTOCOLS[dataset]]
        if unknown or not protocols:
            raise ComparisonError(
                f"benchmark.protocols: {unknown or protocols} not protocols of {dataset}; "
                f"known: {sorted(PROTOCOLS[dataset])}"
            )
        self.dataset, self.root = dataset, Path(root)
        self.protocols = tuple(protocols)
        self.clips_per_group, self.clip_seed = clips_per_group, int(clip_seed)
        self.n_folds = n_folds
        self.motions, self.fields = self._read()
        self.names = [m.name for m in self.motions]

    # -------------------------------------------------------------- data
    def _read(self):
        if self.dataset == "msr":
            from mocapkit.datasets.msr_action3d.dataset import MSRAction3D

            data = MSRAction3D(self.root)
            motions = list(data.motions)
            fields = {
                "action": np.array([f"a{a:02d}" for a in data.actions]),
                "subject": np.array([str(s) for s in data.subjects]),
            }  # as the data modules name them
            for motion, name in zip(motions, data.names):
                motion.name = name
        else:
            from mocapkit.datasets.mocap.folders import list_clips, read_clips

            clips = list_clips(self.dataset, self.root)
            if self.clips_per_group:
                rng = np.random.default_rng(self.clip_seed)
                keep = []
                for group in sorted({c["group"] for c in clips}):
                    members = [c for c in clips if c["group"] == group]
                    chosen = sorted(rng.permutation(len(members))[: int(self.clips_per_group)])
                    keep += [members[i] for i in chosen]
                clips = sorted(keep, key=lambda c: str(c["path"]))
            motions = read_clips(clips, progress=len(clips) > 100)
            if self.dataset == "hdm05":
                fields = {
                    "class": np.array([c["class"] for c in clips]),
                    "group": np.array([c["group"] for c in clips]),
                }
            else:  # bandai: list_clips' group is the style, class the content
                fields = {
                    "content": np.array([c["class"] for c in clips]),
                    "style": np.array([c["group"] for c in clips]),
                }
        return motions, fields

    def describe(self) -> dict:
        return {
            "dataset": self.dataset,
            "root": str(self.root),
            "n_clips": len(self.motions),
            "fields": {k: sorted(set(v.tolist())) for k, v in self.fields.items()},
            "clips_per_group": self.clips_per_group,
            "n_folds": self.n_folds,
        }

    def data(self, indices: np.ndarray):
        return [self.motions[int(i)] for i in indices], None

    # -------------------------------------------------------------- splits
    def folds(self, protocol: str) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """fold name → ``(database indices, query indices)`` of a protocol (sorted int64)."""
        _, group = PROTOCOLS[self.dataset][protocol]
        everything = np.arange(len(self.motions), dtype=np.int64)
        if protocol == "zhou_tp20":
            queries = everything[np.isin(self.fields["class"], ZHOU_SHARED)]
            return {"all": (everything, queries)}
        values = self.fields[group]
        if self.dataset == "msr":
            train = np.isin(values, [str(s) for s in MSR_TRAIN_SUBJECTS])
            return {"subjects 2-10 even": (everything[train], everything[~train])}
        groups = sorted(set(values.tolist()))
        if self.n_folds and len(groups) > int(self.n_folds):
            held = [groups[i :: int(self.n_folds)] for i in range(int(self.n_folds))]
        else:
            held = [[g] for g in groups]
        return {"+".join(h): (everything[~np.isin(values, h)], everything[np.isin(values, h)]) for h in held}

    def split(self, protocol: str, seed: int) -> Split:
        if protocol not in self.protocols:
            raise ComparisonError(f"protocol {protocol!r}: not among benchmark.protocols {list(self.protocols)}")
        folds = self.folds(protocol)
        train = np.unique(np.concatenate([db for db, _ in folds.values()]))
        test = np.unique(np.concatenate([q for _, q in folds.values()]))
        label = PROTOCOLS[self.dataset][protocol][0]
        return Split(
            protocol,
            seed,
            train,
            test,
            {
                "label": label,
                "folds": {name: {"n_database": len(db), "n_queries": len(q)} for name, (db, q) in folds.items()},
            },
        )

    # -------------------------------------------------------------- scoring
    def evaluate_estimator(self, estimator, split: Split) -> dict:
        from sklearn.base import clone

        from mocapkit.retrieval.metrics import retrieval_metrics, tp_ratio

        label = PROTOCOLS[self.dataset][split.protocol][0]
        labels = self.fields[label]
        label_free = bool(getattr(estimator, "label_free", True))
        kind = {"label_free": label_free, "needs_run": bool(getattr(estimator, "needs_run", False))}
        if split.protocol == "zhou_tp20":
            if not label_free or kind["needs_run"]:
                return {
                    "metrics": {"tp_ratio": float("nan")},
                    "detail": {
                        **kind,
                        "not_applicable": "the thesis's protocol fits and queries one set; a supervised or "
                        "trained method would have seen the queries",
                    },
                }
            fitted = clone(estimator)
            start = time.perf_counter()
            fitted.fit(self.motions)
            fit_s = time.perf_counter() - start
            d = fitted.distances(self.motions)
            scores = tp_ratio(d, labels, split.test, k=20)
            return {"metrics": {"tp_ratio": scores["tp_ratio"], "fit_seconds": fit_s}, "detail": {**kind, **scores}}
        q_labels, db_labels, fold_scores, folds = [], [], [], {}
        query_ms, fit_seconds = [], []
        group_field = PROTOCOLS[self.dataset][split.protocol][1]
        for fold, (db, queries) in self.folds(split.protocol).items():
            fitted = clone(estimator)
            start = time.perf_counter()
            # the protocol's group of every database clip (a trained method picks the run that held out the rest)
            database = [
                replace(
                    self.motions[i], metadata={**self.motions[i].metadata, "group": str(self.fields[group_field][i])}
                )
                for i in db
            ]
            fitted.fit(database, None if label_free else labels[db])
            fit_seconds.append(time.perf_counter() - start)
            start = time.perf_counter()
            d = fitted.distances([self.motions[i] for i in queries])
            query_ms.append(1000 * (time.perf_counter() - start) / len(queries))
            scores = retrieval_metrics(d, labels[queries], labels[db])
            folds[fold] = {
                **scores["metrics"],
                "fit_seconds": fit_seconds[-1],
                "query_ms": query_ms[-1],
                "nearest": [self.names[db[j]] for j in scores["per_query"]["nearest"]],
                "queries": [self.names[i] for i in queries],
            }
            q_labels.append(labels[queries])
            db_labels.append(labels[db])
            fold_scores.append(scores)
        kind["uses_labels"] = _uses_labels(fitted)
        pooled = _pooled(fold_scores)
        metrics = {**pooled, "fit_seconds": float(np.mean(fit_seconds)), "query_ms": float(np.mean(query_ms))}
        return {
            "metrics": metrics,
            "detail": {
                **kind,
                "label": label,
                "folds": folds,
                "confusion": _confusion(fold_scores, q_labels, db_labels),
            },
        }

    # -------------------------------------------------------------- presentation
    def headline(self, protocol: str) -> list[str]:
        return ["tp_ratio"] if protocol == "zhou_tp20" else HEADLINE

    def markdown(self, results: dict) -> str:
        lines = []
        cells = results.get("cells", [])
        protocols = results["protocols"]
        for title, wanted in (
            ("Label-free methods, no training run", "label_free"),
            ("Self-supervised methods (a training run without labels)", "self_supervised"),
            ("Supervised methods (labels of the database side)", "supervised"),
        ):
            keys = [k for k in dict.fromkeys(c["method"] for c in cells) if _kind(cells, k) == wanted]
            if not keys:
                continue
            lines += [
                f"## {title}",
                "",
                (
                    "mean ± sd over seeds; mAP / P@1 / P@10 pooled over every query of every "
                    "fold (the query is never in its own database)."
                ),
                "",
            ]
            header = (
                "| method | "
                + " | ".join(
                    f"{p} {'TP@20' if p == 'zhou_tp20' else 'mAP'} | {p} P@1" if p != "zhou_tp20" else f"{p} TP@20"
                    for p in protocols
                )
                + " | query ms |"
            )
            lines += [header, "|" + "---|" * (header.count("|") - 1)]
            for key in keys:
                row = [next(c["label"] for c in cells if c["method"] == key)]
                ms = []
                for p in protocols:
                    mine = [c for c in cells if c["method"] == key and c["protocol"] == p]
                    metrics = ["tp_ratio"] if p == "zhou_tp20" else ["map", "p@1"]
                    for m in metrics:
                        values = [c["metrics"].get(m) for c in mine]
                        row.append(_mean_sd(values))
                    ms += [c["metrics"].get("query_ms") for c in mine if c["metrics"].get("query_ms") is not None]
                row.append(f"{np.mean(ms):.1f}" if ms else "–")
                lines.append("| " + " | ".join(row) + " |")
            lines.append("")
        return "\n".join(lines)

    def plots(self, results: dict, out_dir) -> list[Path]:
        return _plot_confusions(results, Path(out_dir))


def _uses_labels(fitted) -> bool:
    """Whether labels shaped a fitted method: fitted with labels, or a trained encoder whose loss used them."""
    if not getattr(fitted, "label_free", True):
        return True
    return (getattr(fitted, "model_info_", None) or {}).get("loss") == "supcon"


def _kind(cells, key) -> str:
    """``"label_free"`` (no labels, no run), ``"self_supervised"`` (a run trained without labels) or
    ``"supervised"``, from the method's cells."""
    details = [c.get("detail") or {} for c in cells if c["method"] == key]
    if any(d.get("uses_labels") or not d.get("label_free", True) for d in details):
        return "supervised"
    return "self_supervised" if any(d.get("needs_run") for d in details) else "label_free"


def _mean_sd(values) -> str:
    finite = [float(v) for v in values if v is not None and np.isfinite(v)]
    if not finite:
        return "n/a"
    if len(finite) == 1:
        return f"{finite[0]:.3f}"
    return f"{np.mean(finite):.3f} ± {np.std(finite, ddof=1):.3f}"


def _pooled(fold_scores: list[dict]) -> dict:
    """Metrics over every query of every fold (each query ranked against its own fold's database), from the
    folds' :func:`~mocapkit.retrieval.metrics.retrieval_metrics`."""
    aps, p1, p10, nn = [], [], [], []
    for scores in fold_scores:
        n = scores["metrics"]["n_queries"]
        aps += [a for a in scores["per_query"]["ap"] if np.isfinite(a)]
        p1 += [scores["metrics"]["p@1"]] * n
        p10 += [scores["metrics"]["p@10"]] * n
        nn += [scores["metrics"]["nn_accuracy"]] * n
    return {
        "map": float(np.mean(aps)) if aps else float("nan"),
        "p@1": float(np.mean(p1)),
        "p@10": float(np.mean(p10)),
        "nn_accuracy": float(np.mean(nn)),
        "n_queries": len(p1),
    }


def _confusion(fold_scores, q_labels, db_labels) -> dict:
    """Query class × class of the nearest database clip (counts), pooled over folds (the folds'
    :func:`~mocapkit.retrieval.metrics.retrieval_metrics` ``per_query["nearest"]``)."""
    classes = sorted(set(np.concatenate(q_labels).tolist()) | set(np.concatenate(db_labels).tolist()))
    index = {c: i for i, c in enumerate(classes)}
    counts = np.zeros((len(classes), len(classes)), dtype=np.int64)
    for scores, q, db in zip(fold_scores, q_labels, db_labels):
        for a, b in zip(q, db[np.asarray(scores["per_query"]["nearest"], dtype=np.int64)]):
            counts[index[a], index[b]] += 1
    return {"classes": classes, "counts": counts.tolist()}


def _plot_confusions(results: dict, out_dir: Path) -> list[Path]:
    """One PNG per protocol: the 1-NN confusion matrix of the method with the highest mean mAP (seed 0 cell)."""
    from mocapkit.evaluation.classification import plot_confusion_matrix

    written = []
    for protocol in results["protocols"]:
        cells = [
            c
            for c in results.get("cells", [])
            if c["protocol"] == protocol and (c.get("detail") or {}).get("confusion")
        ]
        if not cells:
            continue
        best = max(cells, key=lambda c: c["metrics"].get("map") or -1.0)
        confusion = best["detail"]["confusion"]
        path = out_dir / f"confusion_{protocol}.png"
        plot_confusion_matrix(
            np.array(confusion["counts"]),
            confusion["classes"],
            path,
            title=f"{protocol}: 1-NN classes of {best['label']}",
        )
        written.append(path)
    return written
