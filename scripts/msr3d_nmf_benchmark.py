"""MSR Action3D bag-of-clip-words benchmark: k-means, NMF, ONMF, GNMF, NMC and the end-to-end NMF layer.

The thesis's recognition protocol (§6.3.4, spec §5.3, §8 items 35-37), once per protocol and seed:

1. split the sequences (:func:`~mocapkit.datasets.msr_action3d.dataset.msr_split_indices`): ``random_half`` = a seeded
   random half of each action trains (the thesis's protocol; seed = the run seed), ``cross_subject`` = odd
   subjects train (fixed; the seed then only moves the clusterers' and classifiers' initialisation);
2. cut every sequence into clips of each ``--windows`` length M, stride M/2, and encode each clip as non-negative
   sign-split normalised coordinates of ``--frames-per-clip`` frames (:mod:`mocapkit.features.clips`); for the NMF
   family, centre the clips on the mean **training** clip and sign-split again
   (:class:`~mocapkit.classical.bag_of_words.ClipConditioner`, ``--conditioning centre``): without it one
   "mean pose" component wins the arg-max of most clips and GNMF / NMC used 7-25 of 100 words;
3. fit each clusterer on the **training clips only**: ``kmeans`` = ``sklearn.cluster.KMeans``;
   ``nmf`` / ``onmf`` / ``gnmf`` / ``nmc`` = :mod:`mocapkit.classical` (word = arg-max of a clip's code row).
   Test clips get ``KMeans.predict`` or the arg-max of ``transform`` with the components fixed; for GNMF and NMC
   the kNN graph couples the training clips only (test clips are coded without it). With ``--select`` the vocabulary
   size k and the graph weight (GNMF lam, NMC lambda2) are chosen per (window, protocol) by 3-fold stratified CV on
   the training sequences of the first seed's split (:func:`select_parameters`; no test sequence of that split is
   used; for ``random_half`` the other seeds' test halves overlap that training half, see results.md);
4. ℓ1-normalised word histogram per sequence (hard, the thesis) → ``LogisticRegression`` whose ``C`` is chosen by
   3-fold stratified cross-validation on the training sequences → recognition accuracy on the test; the same fitted
   NMF clusterer is also read as a soft bag of words (``<method> + soft`` rows: mean ℓ1-normalised code per
   sequence, an extra, not the thesis's protocol);
5. clip clustering quality of the training clips' words against their sequence's action: ACC (Hungarian),
   NMI (**arithmetic** normalisation, scikit-learn's default) and ARI;
6. ``layer``: the end-to-end model of :mod:`mocapkit.models.clip_bow`, trained with
   ``compose_config(["experiment=msr3d_nmf_layer", "data.split=<protocol>", "data.split_seed=<seed>", ...])``
   and :func:`~mocapkit.train.training.train`, scored with :func:`~mocapkit.evaluation.evaluate.evaluate` (top-1 of
   ``best.ckpt`` on the same test sequences). It trains on 90 % of the training sequences (10 % select the
   checkpoint) and, like every run of the data module, sees sequences longer than 128 frames subsampled to 128
   (one of 566); its clip words are the arg-max of its soft assignments.

Writes ``<out>/results.json`` (every run, the configuration, timings, the machine), ``<out>/results.md`` (table)
and ``<out>/accuracy.png``. Run it with ``OMP_NUM_THREADS=1``: the tensors are small, and two threads on a
busy 2-core machine made the layer's training 4x slower in our runs. ``--quick`` (tests): one seed, a subset
of ≤ 40 files, few words and iterations.

    OMP_NUM_THREADS=1 python scripts/msr3d_nmf_benchmark.py --root ../shared/data/msr_action3d \
        --out checkpoints/msr3d_nmf_benchmark --seeds 0 1 2 --windows 30 10 --select \
        [--protocols random_half cross_subject] [--methods kmeans nmf onmf gnmf nmc layer] [--conditioning none]
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from mocapkit.classical.bag_of_words import BagOfWordsClassifier  # noqa: E402
from mocapkit.features.clips import sequence_clip_features  # noqa: E402
from mocapkit.datasets.msr_action3d.dataset import MSRAction3D  # noqa: E402
from mocapkit.datasets.msr_action3d.splits import msr_split_indices  # noqa: E402
from mocapkit.evaluation.clustering import NMI_NORMALISATION, clustering_report  # noqa: E402

METHODS = ("kmeans", "nmf", "onmf", "gnmf", "nmc", "layer")
PROTOCOLS = ("random_half", "cross_subject")
THESIS_ACCURACY = 0.9333  # random half, NMC; the thesis's features, k, λ and classifier are not stated

#: --quick: the first take of actions a08-a11 by every subject (40 sequences in the release; all 10 subjects
#: recorded them, so the cross-subject protocol has its training and test subjects)
QUICK_ACTIONS, QUICK_SUBJECTS, QUICK_TAKES = range(8, 12), range(1, 11), (1,)


#: hyper-parameters used without ``--select`` (and the starting point of the selection): words ``k``; GNMF ``lam``,
#: NMC ``lambda1`` / ``lambda2`` (kNN graph with 5 neighbours, NMC ``eta = 0.5``)
DEFAULT_PARAMS = {"kmeans": {"k": 100}, "nmf": {"k": 100}, "onmf": {"k": 100}, "gnmf": {"k": 100, "lam": 0.1},
                  "nmc": {"k": 100, "lambda1": 1e-3, "lambda2": 0.1}}
#: ``--select``: 3-fold CV on the training sequences, first over k (other parameters at their default), then over
#: the graph weight at the chosen k
SELECT_K = (100, 200)
SELECT_GRAPH_WEIGHTS = (0.01, 0.1, 1.0)
GRAPH_WEIGHT = {"gnmf": "lam", "nmc": "lambda2"}
CONDITIONINGS = ("centre", "none")


def make_clusterer(method: str, params: dict, seed: int, max_iter: int):
    """The unfitted clusterer of ``method`` with hyper-parameters ``params`` (keys of :data:`DEFAULT_PARAMS`).

    NMF and GNMF start from NNDSVDa, ONMF and NMC from k-means (the thesis's NMC initialisation).
    """
    from sklearn.cluster import KMeans

    from mocapkit.classical import GNMF, NMC, NMF, OrthogonalNMF

    params = {**DEFAULT_PARAMS.get(method, {}), **params}
    k = int(params["k"])
    if method == "kmeans":
        return KMeans(n_clusters=k, n_init=10, max_iter=max_iter, random_state=seed)
    if method == "nmf":
        return NMF(k, init="nndsvda", max_iter=max_iter, tol=1e-4, random_state=seed)
    if method == "onmf":
        return OrthogonalNMF(k, init="kmeans", max_iter=max_iter, tol=1e-4, random_state=seed)
    if method == "gnmf":
        return GNMF(k, lam=params["lam"], graph="knn", n_neighbors=5, init="nndsvda", max_iter=max_iter, tol=1e-4,
                    random_state=seed)
    if method == "nmc":
        return NMC(k, lambda1=params["lambda1"], lambda2=params["lambda2"], graph="knn", n_neighbors=5, eta=0.5,
                   init="kmeans", max_iter=max_iter, tol=1e-4, random_state=seed)
    raise ValueError(f"unknown method {method!r}; choose from {METHODS}")


def make_conditioner(method: str, conditioning: str):
    """The clip conditioner of ``method``: the NMF family centres the clips on the mean training clip
    (``conditioning="centre"``; ``"none"``: raw sign-split features, the previous pipeline); k-means always reads
    the raw features (centring does not move its Euclidean clusters much and lowered its training-CV accuracy)."""
    from mocapkit.classical.bag_of_words import ClipConditioner

    if conditioning not in CONDITIONINGS:
        raise ValueError(f"conditioning must be one of {CONDITIONINGS}, got {conditioning!r}")
    return None if method == "kmeans" or conditioning == "none" else ClipConditioner(centre=True)


def _split_clips(owner: np.ndarray, n_sequences: int, train: np.ndarray, test: np.ndarray):
    """Clip masks of both sides and each clip's owner renumbered 0..n_side-1 in split order."""
    train_clip, test_clip = np.isin(owner, train), np.isin(owner, test)
    position = np.full(n_sequences, -1)
    position[train] = np.arange(len(train))
    position[test] = np.arange(len(test))
    return train_clip, test_clip, position[owner]


def cv_accuracy(method: str, params: dict, features: np.ndarray, owner: np.ndarray, labels: np.ndarray,
                train: np.ndarray, seed: int, max_iter: int, classifier: str, conditioning: str,
                folds: int = 3) -> float:
    """Mean hard-assignment accuracy of ``method`` by stratified ``folds``-fold CV over the *training* sequences."""
    from sklearn.model_selection import StratifiedKFold

    scores = []
    for fit_part, held_out in StratifiedKFold(folds, shuffle=True, random_state=seed).split(train, labels[train]):
        scores.append(run_classical(method, params, features, owner, labels, train[fit_part], train[held_out],
                                    seed, max_iter, classifier, conditioning, soft=False)[0]["accuracy"])
    return float(np.mean(scores))


def select_parameters(method: str, features: np.ndarray, owner: np.ndarray, labels: np.ndarray, train: np.ndarray,
                      seed: int, max_iter: int, classifier: str, conditioning: str, k_grid=SELECT_K,
                      defaults: dict | None = None) -> dict:
    """Hyper-parameters of ``method`` chosen by 3-fold CV on the training sequences ``train`` only.

    ``k`` in ``k_grid`` (default :data:`SELECT_K`; the other parameters at ``defaults`` / :data:`DEFAULT_PARAMS`),
    then GNMF ``lam`` / NMC ``lambda2`` in :data:`SELECT_GRAPH_WEIGHTS` at the chosen ``k``; ties keep the earlier
    (smaller) value. Returns
    ``{"params": ..., "cv": [{"params", "cv_accuracy"}, ...]}``.
    """
    tried = []

    def score(params):
        value = cv_accuracy(method, params, features, owner, labels, train, seed, max_iter, classifier, conditioning)
        tried.append({"params": dict(params), "cv_accuracy": value})
        print(f"[select] {method} {params}: CV accuracy {value:.2%}", flush=True)
        return value

    best = dict((defaults or DEFAULT_PARAMS)[method])
    best_score = -1.0
    for k in k_grid:
        value = score({**best, "k": k})
        if value > best_score:
            best_score, best = value, {**best, "k": k}
    if method in GRAPH_WEIGHT:
        key = GRAPH_WEIGHT[method]
        scored_weight = best[key]
        for weight in SELECT_GRAPH_WEIGHTS:
            if weight == scored_weight:
                continue                                                       # already scored with the k grid
            value = score({**best, key: weight})
            if value > best_score:
                best_score, best = value, {**best, key: weight}
    return {"params": best, "cv_accuracy": best_score, "cv": tried}


def quick_subset(root: Path, target: Path) -> Path:
    """Copy the ``--quick`` files (actions :data:`QUICK_ACTIONS`, subjects, takes; those present) into ``target``."""
    from mocapkit.datasets.formats.msr_action3d import parse_msr_name

    if target.exists():
        shutil.rmtree(target)
    target.mkdir(parents=True)
    copied = 0
    for source in sorted(root.rglob("*_skeleton3D.txt")):
        name = parse_msr_name(source)
        if name.action in QUICK_ACTIONS and name.subject in QUICK_SUBJECTS and name.take in QUICK_TAKES:
            shutil.copyfile(source, target / source.name)
            copied += 1
    if copied < 20:
        raise FileNotFoundError(f"--quick found only {copied} of its files (a08-a11, take e01, all subjects) in {root}")
    return target


def machine() -> dict:
    """Where the numbers were measured."""
    import torch

    return {"platform": platform.platform(), "processor": platform.processor() or platform.machine(),
            "cpu_count": os.cpu_count(), "python": platform.python_version(), "torch": torch.__version__,
            "torch_threads": torch.get_num_threads(), "omp_num_threads": os.environ.get("OMP_NUM_THREADS")}


def run_classical(method: str, params: dict, features: np.ndarray, owner: np.ndarray, labels: np.ndarray,
                  train: np.ndarray, test: np.ndarray, seed: int, max_iter: int, classifier: str,
                  conditioning: str = "centre", soft: bool = True) -> list[dict]:
    """One clusterer on one split: recognition accuracy, training-clip clustering metrics, timings.

    Returns the hard-assignment result (the thesis's protocol) and, when ``soft`` and the method is a
    factorisation, the soft bag of words read from the same fitted clusterer (``variant`` "hard" / "soft").
    """
    train_clip, test_clip, position = _split_clips(owner, len(labels), train, test)
    start = time.perf_counter()
    model = BagOfWordsClassifier(make_clusterer(method, params, seed, max_iter), classifier=classifier,
                                 random_state=seed, conditioner=make_conditioner(method, conditioning))
    model.fit(features[train_clip], position[train_clip], labels[train])
    accuracy = model.score(features[test_clip], position[test_clip], labels[test])
    elapsed = time.perf_counter() - start
    clusters = clustering_report(labels[owner[train_clip]], model.train_words_)
    common = {**{m: clusters[m] for m in ("acc", "nmi", "ari")}, "n_clusters_used": clusters["n_clusters"],
              "params": dict(params), "conditioning": "none" if model.conditioner_ is None else conditioning,
              "n_train_clips": int(train_clip.sum()), "n_test_clips": int(test_clip.sum())}
    results = [{"variant": "hard", "accuracy": accuracy, "best_C": model.best_C_, "time_s": elapsed,
                "cluster_time_s": model.cluster_time_, "classifier_time_s": model.classifier_time_, **common}]
    if soft and method != "kmeans":                                # k-means codes are one-hot: soft = hard
        start = time.perf_counter()
        soft_model = BagOfWordsClassifier(model.clusterer_, classifier=classifier, random_state=seed,
                                          assignment="soft", conditioner=model.conditioner_, prefit=True)
        soft_model.fit(features[train_clip], position[train_clip], labels[train])
        soft_accuracy = soft_model.score(features[test_clip], position[test_clip], labels[test])
        results.append({"variant": "soft", "accuracy": soft_accuracy, "best_C": soft_model.best_C_,
                        "time_s": model.cluster_time_ + time.perf_counter() - start,
                        "cluster_time_s": model.cluster_time_, "classifier_time_s": soft_model.classifier_time_,
                        **common})
    return results


def run_layer(root: Path, out: Path, protocol: str, seed: int, window: int, stride: int, frames_per_clip: int,
              data: MSRAction3D, labels: np.ndarray, train: np.ndarray, quick: bool,
              extra_overrides: list[str], stamp: str) -> dict:
    """Train and evaluate the end-to-end model (experiment ``msr3d_nmf_layer``) on one split.

    The run goes to ``<out>/runs/msr3d_nmf_layer/<protocol>_window<window>_seed<seed>_<stamp>/`` (``stamp``: the
    benchmark's start).
    """
    import torch

    from mocapkit.train.action_module import ActionRecognitionModule
    from mocapkit.train.config import compose_config
    from mocapkit.evaluation.evaluate import evaluate
    from mocapkit.train.training import train as train_model

    overrides = ["experiment=msr3d_nmf_layer", f"data.root={root}", f"data.split={protocol}",
                 f"data.split_seed={seed}", f"seed={seed}", f"output_root={out / 'runs'}",
                 f"run_name={protocol}_window{window}_seed{seed}_{stamp}", "trainer.enable_progress_bar=false",
                 f"model.window={window}", f"model.stride={stride}", f"model.frames_per_clip={frames_per_clip}"]
    if quick:
        overrides += ["trainer.max_epochs=2", "model.n_components=8", "model.encoder_hidden=16",
                      "data.val_fraction=0.2"]
    overrides += list(extra_overrides)
    start = time.perf_counter()
    cfg = compose_config(overrides)
    run_dir = train_model(cfg)
    report = evaluate(run_dir / "best.ckpt")
    elapsed = time.perf_counter() - start
    # the layer's clip words on the training clips: arg-max of its soft assignment, one sequence at a time
    module = ActionRecognitionModule.load_from_checkpoint(run_dir / "best.ckpt", map_location="cpu").eval()
    words, clip_labels = [], []
    with torch.no_grad():
        for i in train:
            skeleton = torch.from_numpy(data.positions(int(i)))[None, None]
            soft, valid = module.model.soft_words(skeleton)
            words.append(soft[0][valid[0]].argmax(-1).numpy())
            clip_labels.append(np.full(int(valid[0].sum()), labels[i]))
    clusters = clustering_report(np.concatenate(clip_labels), np.concatenate(words))
    return {"accuracy": float(report["top1"]), **{m: clusters[m] for m in ("acc", "nmi", "ari")},
            "n_clusters_used": clusters["n_clusters"], "time_s": elapsed, "run_dir": str(run_dir),
            "overrides": overrides}


def row_name(method: str, variant: str) -> str:
    """Table name of a (method, assignment variant): ``nmf`` (hard, the thesis) or ``nmf + soft``."""
    return method if variant == "hard" else f"{method} + soft"


def summarise(runs: list[dict], windows, methods, protocols) -> list[dict]:
    """Mean and sd over seeds per (window, method, variant, protocol)."""
    rows = []
    for window in windows:
        for protocol in protocols:
            for method in methods:
                for variant in ("hard", "soft"):
                    chosen = [r for r in runs if r["window"] == window and r["method"] == method
                              and r["variant"] == variant and r["protocol"] == protocol]
                    if not chosen:
                        continue
                    row = {"window": window, "method": method, "variant": variant, "name": row_name(method, variant),
                           "protocol": protocol, "n_seeds": len(chosen), "params": chosen[0].get("params", {})}
                    for key in ("accuracy", "acc", "nmi", "ari", "time_s"):
                        values = np.array([r[key] for r in chosen], dtype=float)
                        row[key] = float(values.mean())
                        row[key + "_sd"] = float(values.std(ddof=1)) if len(values) > 1 else 0.0
                    rows.append(row)
    return rows


def _params_text(params: dict) -> str:
    return ", ".join(f"{key} {value:g}" for key, value in params.items()) if params else "see config"


def write_markdown(path: Path, summary: list[dict], config: dict, host: dict, total_s: float) -> None:
    selection = ("chosen by 3-fold stratified CV on the **training** sequences of the first seed's split of each "
                 "protocol and window (k in " + str(list(SELECT_K)) + ", then the graph weight in "
                 + str(list(SELECT_GRAPH_WEIGHTS)) + "; see `selection` in results.json)") if config["select"] \
        else "defaults (no selection)"
    conditioning = ("centred on the mean training clip, then sign-split again" if config["conditioning"] == "centre"
                    else "raw (not centred)")
    lines = ["# MSR Action3D: bag of clip words (thesis §6.3)", "",
             f"Windows {config['windows']} frames, stride window/2, {config['frames_per_clip']} frames per clip "
             f"(sign-split normalised coordinates, d = {config['feature_dim']}). NMF family: clips "
             f"{conditioning}"
             f"; k-means: raw clips. Hyper-parameters (k, GNMF lam, NMC lambda2): {selection}. "
             f"Clusterers: max_iter {config['max_iter']}; classifier: {config['classifier']} with C by 3-fold CV on "
             f"the training sequences; seeds {config['seeds']}"
             + (" (**--quick**: small file subset, not a result)" if config["quick"] else "") + ".", "",
             "Rows: `method` = hard bag of words (arg-max word per clip, the thesis's protocol); `method + soft` = "
             "the same fitted clusterer read as a soft bag of words (mean ℓ1-normalised code per sequence, an extra, "
             "not the thesis). `layer` = the end-to-end NMF-layer model (experiment msr3d_nmf_layer, not retuned).",
             "", "Accuracy = sequence recognition on the test half (mean ± sd over seeds). ACC / NMI / ARI = the "
             f"training clips' words against their action label (NMI normalisation: {NMI_NORMALISATION}). "
             "Time = fit + predict per split (layer: training + evaluation).", "",
             "| window | method | protocol | accuracy | clip ACC | clip NMI | clip ARI | params | time (s) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for r in summary:
        params = _params_text(r["params"]) if r["method"] != "layer" else "experiment config"
        lines.append(f"| {r['window']} | {r['name']} | {r['protocol']} | {r['accuracy']:.2%} ± {r['accuracy_sd']:.2%} "
                     f"| {r['acc']:.3f} | {r['nmi']:.3f} | {r['ari']:.3f} | {params} | {r['time_s']:.1f} |")
    lines += ["", f"Thesis (Wang 2017, §6.3.4): **{THESIS_ACCURACY:.2%}** with NMC on a random half (features, k, "
              "λ, graph and classifier not stated; spec §8 item 37: a target band, not an exact reproduction). "
              "Only the random_half rows are comparable with it; cross_subject is the harder standard protocol. "
              "The thesis-faithful configuration is window 30, stride 15, hard assignment.", "",
              f"Total {total_s / 60:.1f} min on {host['processor']} ({host['cpu_count']} CPUs, "
              f"OMP_NUM_THREADS={host['omp_num_threads']}), {host['platform']}.", ""]
    path.write_text("\n".join(lines))


def plot_accuracy(path: Path, summary: list[dict], windows, protocols) -> None:
    """One panel per window: accuracy (mean ± sd over seeds) of every table row, one bar per protocol."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(dict.fromkeys(r["name"] for r in summary))
    fig, axes = plt.subplots(len(windows), 1, figsize=(0.9 * len(names) + 2, 3.2 * len(windows)), squeeze=False)
    width = 0.8 / max(len(protocols), 1)
    for ax, window in zip(axes[:, 0], windows):
        for p, protocol in enumerate(protocols):
            rows = {r["name"]: r for r in summary if r["protocol"] == protocol and r["window"] == window}
            xs = [i for i, name in enumerate(names) if name in rows]
            ax.bar([x + p * width for x in xs], [rows[names[x]]["accuracy"] for x in xs], width,
                   yerr=[rows[names[x]]["accuracy_sd"] for x in xs], capsize=3, label=protocol)
        if "random_half" in protocols:
            ax.axhline(THESIS_ACCURACY, color="k", ls="--", lw=1, label="thesis 93.33% (random half)")
        ax.set_xticks([i + width * (len(protocols) - 1) / 2 for i in range(len(names))], names, fontsize=8,
                      rotation=20)
        ax.set_ylabel("test accuracy")
        ax.set_ylim(0, 1.15)
        ax.set_title(f"MSR Action3D, bag of clip words, window {window}")
        ax.legend(fontsize=8, loc="upper center", ncol=3, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_benchmark(root: str | Path, out: str | Path, seeds=(0, 1, 2), protocols=PROTOCOLS, methods=METHODS,
                  windows=(30,), frames_per_clip: int = 10, max_iter: int = 200, classifier: str = "logistic",
                  conditioning: str = "centre", select: bool = False, k: int | None = None, quick: bool = False,
                  layer_overrides: list[str] | None = None) -> dict:
    """Run every (window, protocol, seed, method); write results.json, results.md and accuracy.png under ``out``.

    ``select``: choose each classical method's hyper-parameters per (window, protocol) by CV on the training
    sequences of the first seed's split (:func:`select_parameters`); else :data:`DEFAULT_PARAMS` (``k`` overrides
    their vocabulary size).
    """
    root, out = Path(root), Path(out)
    unknown = [m for m in methods if m not in METHODS] + [p for p in protocols if p not in PROTOCOLS]
    if unknown:
        raise ValueError(f"unknown methods/protocols {unknown}; methods: {METHODS}, protocols: {PROTOCOLS}")
    if conditioning not in CONDITIONINGS:
        raise ValueError(f"conditioning must be one of {CONDITIONINGS}, got {conditioning!r}")
    out.mkdir(parents=True, exist_ok=True)
    defaults = {m: {**p, **({"k": k} if k is not None else {})} for m, p in DEFAULT_PARAMS.items()}
    if quick:
        seeds, max_iter = tuple(seeds)[:1], min(max_iter, 20)
        defaults = {m: {**p, "k": 5} for m, p in defaults.items()}
        root = quick_subset(root, out / "quick_data")
    total_start, stamp = time.perf_counter(), time.strftime("%Y%m%d-%H%M%S")
    data = MSRAction3D(root)
    labels = data.actions - 1
    positions = [data.positions(i) for i in range(len(data))]
    classical = [m for m in methods if m != "layer"]
    config = {"root": str(root), "seeds": list(seeds), "protocols": list(protocols), "methods": list(methods),
              "windows": list(windows), "frames_per_clip": frames_per_clip, "max_iter": max_iter,
              "classifier": classifier, "classifier_Cs": [0.1, 1.0, 10.0, 100.0], "conditioning": conditioning,
              "select": select, "select_k": list(SELECT_K), "select_graph_weights": list(SELECT_GRAPH_WEIGHTS),
              "default_params": defaults, "quick": quick, "n_sequences": len(data),
              "excluded": dict(data.excluded), "nmi_normalisation": NMI_NORMALISATION,
              "layer_overrides": list(layer_overrides or []), "n_clips": {}}
    host = machine()
    runs, selection = [], {}
    for window in windows:
        stride = window // 2
        features, owner = sequence_clip_features(positions, window, stride, frames_per_clip, "msr20",
                                                 names=data.names)
        config["feature_dim"], config["n_clips"][window] = int(features.shape[1]), int(len(features))
        print(f"[benchmark] {len(data)} sequences, {len(features)} clips of d = {features.shape[1]} "
              f"(window {window}, stride {stride})", flush=True)
        for protocol in protocols:
            params = {m: dict(defaults[m]) for m in classical}
            if select and classical:
                train, _ = msr_split_indices(data, protocol, seed=seeds[0])
                start = time.perf_counter()
                chosen = {m: select_parameters(m, features, owner, labels, train, seeds[0], max_iter, classifier,
                                               conditioning, k_grid=(3, 5) if quick else SELECT_K,
                                               defaults=defaults) for m in classical}
                params = {m: chosen[m]["params"] for m in classical}
                selection[f"window{window}_{protocol}"] = {"split_seed": seeds[0], "methods": chosen,
                                                           "time_s": time.perf_counter() - start}
            for seed in seeds:
                train, test = msr_split_indices(data, protocol, seed=seed)
                for method in methods:
                    print(f"[benchmark] window {window} {protocol} seed {seed}: {method} ...", flush=True)
                    if method == "layer":
                        results = [run_layer(root, out, protocol, seed, window, stride, frames_per_clip, data,
                                             labels, train, quick, list(layer_overrides or []), stamp)]
                        results[0]["variant"] = "hard"
                    else:
                        results = run_classical(method, params[method], features, owner, labels, train, test, seed,
                                                max_iter, classifier, conditioning)
                    for result in results:
                        result.update({"method": method, "window": window, "protocol": protocol, "seed": seed,
                                       "n_train": int(len(train)), "n_test": int(len(test))})
                        runs.append(result)
                        print(f"[benchmark] window {window} {protocol} seed {seed}: "
                              f"{row_name(method, result['variant'])} accuracy {result['accuracy']:.2%}, clip ACC "
                              f"{result['acc']:.3f} NMI {result['nmi']:.3f} ARI {result['ari']:.3f}, "
                              f"{result['time_s']:.1f} s", flush=True)
    total_s = time.perf_counter() - total_start
    summary = summarise(runs, list(windows), methods, protocols)
    results = {"config": config, "machine": host, "total_time_s": total_s, "thesis_accuracy_random_half":
               THESIS_ACCURACY, "selection": selection, "summary": summary, "runs": runs}
    (out / "results.json").write_text(json.dumps(results, indent=2))
    write_markdown(out / "results.md", summary, config, host, total_s)
    plot_accuracy(out / "accuracy.png", summary, list(windows), list(protocols))
    print((out / "results.md").read_text())
    print(f"[benchmark] wrote {out / 'results.json'}, {out / 'results.md'}, {out / 'accuracy.png'} "
          f"({total_s / 60:.1f} min)")
    return results


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--root", default=os.environ.get("MOCAPKIT_MSR_ROOT", "../shared/data/msr_action3d"))
    parser.add_argument("--out", default="checkpoints/msr3d_nmf_benchmark")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--protocols", nargs="+", default=list(PROTOCOLS), choices=PROTOCOLS)
    parser.add_argument("--methods", nargs="+", default=list(METHODS), choices=METHODS)
    parser.add_argument("--windows", type=int, nargs="+", default=[30], help="clip lengths M in frames (stride M/2)")
    parser.add_argument("--k", type=int, default=None, help="words of every method without --select (default 100)")
    parser.add_argument("--select", action="store_true",
                        help="choose k and the graph weights by 3-fold CV on the training sequences")
    parser.add_argument("--conditioning", default="centre", choices=CONDITIONINGS,
                        help="NMF family: centre the clips on the mean training clip (default) or not")
    parser.add_argument("--frames-per-clip", type=int, default=10)
    parser.add_argument("--max-iter", type=int, default=200, help="iterations of the clusterers")
    parser.add_argument("--classifier", default="logistic", choices=("logistic", "linear_svc"))
    parser.add_argument("--quick", action="store_true", help="1 seed, <= 40-file subset, tiny k (for tests)")
    parser.add_argument("--layer-override", action="append", default=[],
                        help="extra Hydra override for the layer runs (repeatable), e.g. trainer.max_epochs=30")
    args = parser.parse_args(argv)
    run_benchmark(args.root, args.out, seeds=args.seeds, protocols=args.protocols, methods=args.methods,
                  windows=args.windows, frames_per_clip=args.frames_per_clip, max_iter=args.max_iter,
                  classifier=args.classifier, conditioning=args.conditioning, select=args.select, k=args.k,
                  quick=args.quick, layer_overrides=args.layer_override)
    return 0


if __name__ == "__main__":
    sys.exit(main())
