"""The MSR Action3D sequence-recognition benchmark of the comparison runner (thesis §6.3.4's bag of clip words).

Samples are the sequences of an :class:`~mocapkit.datasets.msr_action3d.dataset.MSRAction3D` folder: an estimator
gets ``X`` = a list of skeleton sequences ``[T_i, 20, 3]`` (metres, float32) and ``y`` = 0-based action labels
``[n]`` (so a ``Pipeline([("clips", SequenceClips(window=M)), ("bow", BagOfWordsClassifier(...))])`` is one method,
window included). Protocols (:func:`~mocapkit.datasets.msr_action3d.splits.msr_split_indices`):
``random_half`` (per action, a random half trains, drawn with the **cell seed**, the thesis's protocol),
``cross_subject`` (odd subjects train; the seed then only moves the methods' initialisation) and ``AS1`` /
``AS2`` / ``AS3`` (Li et al. 2010's 8-action subsets, cross-subject; labels stay the 20-action indices for
estimators, learned runs train the subset's 8 classes).

Metrics per cell: ``accuracy`` (sequence recognition on the test side, a fraction) and, when the method exposes
its training clips' words (a :class:`~mocapkit.clustering.bag_of_words.BagOfWordsClassifier` as the last step, or
the end-to-end NMF layer's arg-max soft words), their clustering quality against the sequences' actions:
``clip_acc`` (Hungarian), ``clip_nmi`` (arithmetic normalisation), ``clip_ari`` and ``n_words_used``.

Learned runs (``experiment=msr3d_nmf_layer``) get ``data.root``, ``data.split`` and ``data.split_seed=<seed>``;
they train on 90 % of the training sequences (10 % select the checkpoint) and see sequences longer than
``data.max_frames`` subsampled, as every run of the data module does.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from mocapkit.datasets.msr_action3d.dataset import ACTION_SUBSETS, MSRAction3D
from mocapkit.datasets.msr_action3d.splits import MSR_SPLITS, msr_split_indices
from mocapkit.evaluation.clustering import NMI_NORMALISATION, clustering_report
from mocapkit.evaluation.compare.base import Benchmark, ComparisonError, Split

#: Thesis §6.3.4: NMC on a random half (its features, k, λ and classifier are not stated).
THESIS_ACCURACY = 0.9333


def subset_copy(root: Path, target: Path, actions=None, subjects=None, takes=None) -> Path:
    """Copy the ``*_skeleton3D.txt`` files of ``root`` whose action / subject / take are listed into ``target``.

    A learned run reads its data from a folder, so a file subset must be a folder for learned and classical
    methods to see the same sequences. ``target`` is emptied first.
    """
    from mocapkit.datasets.formats.msr_action3d import parse_msr_name

    if target.exists():
        shutil.rmtree(target)
    target.mkdir(parents=True)
    copied = 0
    for source in sorted(Path(root).rglob("*_skeleton3D.txt")):
        name = parse_msr_name(source)
        if (
            (actions is None or name.action in actions)
            and (subjects is None or name.subject in subjects)
            and (takes is None or name.take in takes)
        ):
            shutil.copyfile(source, target / source.name)
            copied += 1
    if copied == 0:
        raise ComparisonError(
            f"benchmark: no MSR Action3D file of {root} matches actions={actions}, subjects={subjects}, takes={takes}"
        )
    return target


class MSRActionBenchmark(Benchmark):
    """MSR Action3D skeleton sequences, protocols ``random_half`` and ``cross_subject``, recognition accuracy.

    Args:
        root: the folder of ``*_skeleton3D.txt`` files.
        actions, subjects, takes: optional 1-based lists: use only those files (copied into ``subset_dir``,
            which learned runs then read as ``data.root``); None: every file.
        subset_dir: where the subset goes (required with a subset).
    """

    title = "MSR Action3D action recognition (sequences)"
    protocols = (*MSR_SPLITS, *sorted(ACTION_SUBSETS))
    percent_metrics = ("accuracy",)

    def __init__(self, root: str, actions=None, subjects=None, takes=None, subset_dir: str | None = None):
        if root is None:
            raise ComparisonError("benchmark.root is not set: give the MSR Action3D skeleton folder")
        self.source = Path(root)
        self.subset = {
            k: list(v) for k, v in (("actions", actions), ("subjects", subjects), ("takes", takes)) if v is not None
        }
        if self.subset:
            if not subset_dir:
                raise ComparisonError("benchmark.subset_dir: needed with benchmark.actions / subjects / takes")
            self.root = subset_copy(self.source, Path(subset_dir), actions, subjects, takes)
        else:
            self.root = self.source
        self.dataset = MSRAction3D(self.root)
        self.labels = np.asarray(self.dataset.actions, dtype=np.int64) - 1
        self.sequences = [self.dataset.positions(i) for i in range(len(self.dataset))]

    def describe(self) -> dict:
        return {
            "root": str(self.root),
            "source": str(self.source),
            "subset": self.subset,
            "n_sequences": len(self.dataset),
            "excluded": dict(self.dataset.excluded),
            "nmi_normalisation": NMI_NORMALISATION,
            "thesis_accuracy_random_half": THESIS_ACCURACY,
        }

    @staticmethod
    def _protocol(protocol: str) -> tuple[str, str | None]:
        """``(split, subset)`` of a protocol name: an ``AS*`` subset is its cross-subject split."""
        return ("cross_subject", protocol) if protocol in ACTION_SUBSETS else (protocol, None)

    def split(self, protocol: str, seed: int) -> Split:
        split, subset = self._protocol(protocol)
        train, test = msr_split_indices(self.dataset, split, subset=subset, seed=seed)
        subjects = np.asarray(self.dataset.subjects)
        return Split(
            protocol,
            seed,
            train,
            test,
            {
                "train_subjects": np.unique(subjects[train]).tolist(),
                "test_subjects": np.unique(subjects[test]).tolist(),
            },
        )

    def data(self, indices: np.ndarray):
        """Skeleton sequences (a list of ``[T_i, 20, 3]`` float32 arrays) and action labels ``[n]`` of ``indices``."""
        indices = np.asarray(indices, dtype=np.int64)
        return [self.sequences[i] for i in indices], self.labels[indices]

    # -------------------------------------------------------------- scoring
    def evaluate_estimator(self, estimator, split: Split) -> dict:
        X, y = self.data(split.train)
        estimator.fit(X, y)
        X_test, y_test = self.data(split.test)
        predicted = np.asarray(estimator.predict(X_test))
        metrics = {"accuracy": float((predicted == y_test).mean())}
        detail = {}
        final = estimator.steps[-1][1] if hasattr(estimator, "steps") else estimator
        words = getattr(final, "train_words_", None)
        if words is not None:
            metrics.update(clip_metrics(y[final.train_clip_sequence_], words))
            detail = {
                "n_train_clips": len(words),
                "best_C": getattr(final, "best_C_", None),
                "cluster_time_s": getattr(final, "cluster_time_", None),
                "classifier_time_s": getattr(final, "classifier_time_", None),
            }
        return {"metrics": metrics, "detail": detail}

    def learned_overrides(self, protocol: str, seed: int) -> list[str]:
        split, subset = self._protocol(protocol)
        return [
            f"data.root={self.root}",
            f"data.split={split}",
            f"data.split_seed={seed}",
            f"data.subset={subset or 'null'}",
        ]

    def evaluate_learned(self, report: dict, run_dir: Path, split: Split) -> dict:
        """Top-1 of ``mocapkit eval``; clip metrics of the model's arg-max soft words on the training sequences."""
        metrics = {"accuracy": float(report["top1"])}
        words = learned_clip_words(Path(report["checkpoint"]), [self.sequences[i] for i in split.train])
        if words is not None:
            owners, assigned = words
            metrics.update(clip_metrics(self.labels[split.train][owners], assigned))
        return {
            "metrics": metrics,
            "detail": {
                k: report[k] for k in ("top1", "top5", "mean_class_accuracy", "split", "sample_counts") if k in report
            },
        }

    # -------------------------------------------------------------- presentation
    def headline(self, protocol: str) -> list[str]:
        return ["accuracy", "clip_acc", "clip_nmi", "clip_ari", "n_words_used"]

    def format_metric(self, name, mean, sd=None) -> str:
        if name == "n_words_used" and mean is not None:
            return f"{mean:.0f}" + (f" ± {sd:.0f}" if sd is not None else "")
        return super().format_metric(name, mean, sd)

    def markdown(self, results: dict) -> str:
        return "\n".join(
            [
                "## Reading the table",
                "",
                (
                    f"Accuracy = sequence recognition on the test side. clip ACC / NMI / ARI = the training clips' words "
                    f"against their sequence's action (NMI normalisation: {NMI_NORMALISATION}); n_words_used = distinct "
                    "words among the training clips. The thesis (§6.3.4) reports "
                    f"{100 * THESIS_ACCURACY:.2f} % with NMC on a random half (features, k, λ, graph and classifier not "
                    "stated); only random_half rows compare with it. Hard bag of words (arg-max word per clip) is the "
                    "thesis's protocol; `soft` rows read the same clusterer as the mean ℓ1-normalised code per sequence."
                ),
            ]
        )


def clip_metrics(clip_labels: np.ndarray, words: np.ndarray) -> dict:
    """``clip_acc``, ``clip_nmi``, ``clip_ari``, ``n_words_used`` of clip ``words`` against their ``clip_labels``."""
    report = clustering_report(np.asarray(clip_labels), np.asarray(words))
    return {
        "clip_acc": report["acc"],
        "clip_nmi": report["nmi"],
        "clip_ari": report["ari"],
        "n_words_used": report["n_clusters"],
    }


def learned_clip_words(checkpoint: Path, sequences: list[np.ndarray]):
    """``(sequence index per clip, arg-max soft word per clip)`` of a checkpoint whose network has ``soft_words``
    (the end-to-end NMF layer), over ``sequences`` one at a time; None for other networks."""
    import torch

    from mocapkit.train.checkpoints import checkpoint_config, load_module

    checkpoint = Path(checkpoint)
    module = load_module(checkpoint_config(checkpoint), checkpoint).eval()  # vetted, weights_only
    network = getattr(module, "model", None)
    if not hasattr(network, "soft_words"):
        return None
    owners, words = [], []
    with torch.no_grad():
        for i, positions in enumerate(sequences):
            soft, valid = network.soft_words(torch.from_numpy(np.ascontiguousarray(positions))[None, None])
            chosen = soft[0][valid[0]].argmax(-1).numpy()
            words.append(chosen)
            owners.append(np.full(len(chosen), i))
    return np.concatenate(owners), np.concatenate(words)
