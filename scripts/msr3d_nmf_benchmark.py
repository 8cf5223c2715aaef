"""MSR Action3D bag-of-clip-words benchmark: k-means, NMF, ONMF, GNMF, NMC and the end-to-end NMF layer.

The thesis's recognition protocol (§6.3.4, spec §5.3, §8 items 35-37), once per protocol and seed:

1. split the sequences (:func:`~mocapkit.datasets.msr_action3d.msr_split_indices`): ``random_half`` = a seeded
   random half of each action trains (the thesis's protocol; seed = the run seed), ``cross_subject`` = odd
   subjects train (fixed; the seed then only moves the clusterers' and classifiers' initialisation);
2. cut every sequence into clips of ``--window`` frames, stride window/2, and encode each clip as non-negative
   sign-split normalised coordinates of ``--frames-per-clip`` frames (:mod:`mocapkit.datasets.clips`);
3. fit each clusterer with ``--k`` words on the **training clips only**: ``kmeans`` = ``sklearn.cluster.KMeans``;
   ``nmf`` / ``onmf`` / ``gnmf`` / ``nmc`` = :mod:`mocapkit.classical` (word = arg-max of a clip's code row).
   Test clips get ``KMeans.predict`` or the arg-max of ``transform`` with the components fixed; for GNMF and NMC
   the kNN graph couples the training clips only (test clips are coded without it);
4. ℓ1-normalised word histogram per sequence → ``LogisticRegression`` whose ``C`` is chosen by 3-fold
   stratified cross-validation on the training sequences (never the test) → recognition accuracy on the test;
5. clip clustering quality of the training clips' words against their sequence's action: ACC (Hungarian),
   NMI (**arithmetic** normalisation, scikit-learn's default) and ARI;
6. ``layer``: the end-to-end model of :mod:`mocapkit.models.clip_bow`, trained with
   ``compose_config(["experiment=msr3d_nmf_layer", "data.split=<protocol>", "data.split_seed=<seed>", ...])``
   and :func:`~mocapkit.train.training.train`, scored with :func:`~mocapkit.train.evaluate.evaluate` (top-1 of
   ``best.ckpt`` on the same test sequences). It trains on 90 % of the training sequences (10 % select the
   checkpoint) and, like every run of the data module, sees sequences longer than 128 frames subsampled to 128
   (one of 566); its clip words are the arg-max of its soft assignments.

Writes ``<out>/results.json`` (every run, the configuration, timings, the machine), ``<out>/results.md`` (table)
and ``<out>/accuracy.png``. Run it with ``OMP_NUM_THREADS=1``: the tensors are small, and two threads on a
busy 2-core machine made the layer's training 4x slower in our runs. ``--quick`` (tests): one seed, a subset
of ≤ 40 files, few words and iterations.

    python scripts/msr3d_nmf_benchmark.py --root ../shared/data/msr_action3d --out checkpoints/msr3d_nmf_benchmark \
        --seeds 0 1 2 [--protocols random_half cross_subject] [--methods kmeans nmf onmf gnmf nmc layer] [--k 100]
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
from mocapkit.datasets.clips import sequence_clip_features  # noqa: E402
from mocapkit.datasets.msr_action3d import MSRAction3D, msr_split_indices  # noqa: E402
from mocapkit.evaluation.clustering import NMI_NORMALISATION, clustering_report  # noqa: E402

METHODS = ("kmeans", "nmf", "onmf", "gnmf", "nmc", "layer")
PROTOCOLS = ("random_half", "cross_subject")
THESIS_ACCURACY = 0.9333  # random half, NMC; the thesis's features, k, λ and classifier are not stated

#: --quick: the first take of actions a08-a11 by every subject (40 sequences in the release; all 10 subjects
#: recorded them, so the cross-subject protocol has its training and test subjects)
QUICK_ACTIONS, QUICK_SUBJECTS, QUICK_TAKES = range(8, 12), range(1, 11), (1,)


def make_clusterer(method: str, k: int, seed: int, max_iter: int):
    """The unfitted clusterer of ``method``.

    NMF and GNMF start from NNDSVDa, ONMF and NMC from k-means (the thesis's NMC initialisation). The graph
    weights (GNMF ``lam = 0.1``, NMC ``lambda2 = 0.1``, kNN graph with 5 neighbours, NMC ``lambda1 = 1e-3``,
    ``eta = 0.5``) were chosen among {0.01, 0.1, 1} (GNMF also 10) by the NMI of the *training* clips' clusters on the
    random-half split of seed 0 (no test data; k = 100, window 30).
    """
    from sklearn.cluster import KMeans

    from mocapkit.classical import GNMF, NMC, NMF, OrthogonalNMF

    if method == "kmeans":
        return KMeans(n_clusters=k, n_init=10, max_iter=max_iter, random_state=seed)
    if method == "nmf":
        return NMF(k, init="nndsvda", max_iter=max_iter, tol=1e-4, random_state=seed)
    if method == "onmf":
        return OrthogonalNMF(k, init="kmeans", max_iter=max_iter, tol=1e-4, random_state=seed)
    if method == "gnmf":
        return GNMF(k, lam=0.1, graph="knn", n_neighbors=5, init="nndsvda", max_iter=max_iter, tol=1e-4,
                    random_state=seed)
    if method == "nmc":
        return NMC(k, lambda1=1e-3, lambda2=0.1, graph="knn", n_neighbors=5, eta=0.5, init="kmeans",
                   max_iter=max_iter, tol=1e-4, random_state=seed)
    raise ValueError(f"unknown method {method!r}; choose from {METHODS}")


def quick_subset(root: Path, target: Path) -> Path:
    """Copy the ``--quick`` files (actions :data:`QUICK_ACTIONS`, subjects, takes; those present) into ``target``."""
    from mocapkit.datasets.msr_action3d import parse_msr_name

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


def run_classical(method: str, features: np.ndarray, owner: np.ndarray, labels: np.ndarray, train: np.ndarray,
                  test: np.ndarray, k: int, seed: int, max_iter: int, classifier: str) -> dict:
    """One clusterer on one split: recognition accuracy, training-clip clustering metrics, timings."""
    # clips of each side, with their owner renumbered 0..n_side-1 in split order
    train_clip, test_clip = np.isin(owner, train), np.isin(owner, test)
    position = np.full(len(labels), -1)
    position[train] = np.arange(len(train))
    position_test = np.full(len(labels), -1)
    position_test[test] = np.arange(len(test))
    start = time.perf_counter()
    model = BagOfWordsClassifier(make_clusterer(method, k, seed, max_iter), classifier=classifier, random_state=seed)
    model.fit(features[train_clip], position[owner[train_clip]], labels[train])
    accuracy = model.score(features[test_clip], position_test[owner[test_clip]], labels[test])
    elapsed = time.perf_counter() - start
    clusters = clustering_report(labels[owner[train_clip]], model.train_words_)
    return {"accuracy": accuracy, **{m: clusters[m] for m in ("acc", "nmi", "ari")},
            "n_clusters_used": clusters["n_clusters"], "best_C": model.best_C_, "time_s": elapsed,
            "cluster_time_s": model.cluster_time_, "classifier_time_s": model.classifier_time_,
            "n_train_clips": int(train_clip.sum()), "n_test_clips": int(test_clip.sum())}


def run_layer(root: Path, out: Path, protocol: str, seed: int, window: int, stride: int, frames_per_clip: int,
              data: MSRAction3D, labels: np.ndarray, train: np.ndarray, quick: bool,
              extra_overrides: list[str], stamp: str) -> dict:
    """Train and evaluate the end-to-end model (experiment ``msr3d_nmf_layer``) on one split.

    The run goes to ``<out>/runs/msr3d_nmf_layer/<protocol>_seed<seed>_<stamp>/`` (``stamp``: the benchmark's start).
    """
    import torch

    from mocapkit.train.action_module import ActionRecognitionModule
    from mocapkit.train.config import compose_config
    from mocapkit.train.evaluate import evaluate
    from mocapkit.train.training import train as train_model

    overrides = ["experiment=msr3d_nmf_layer", f"data.root={root}", f"data.split={protocol}",
                 f"data.split_seed={seed}", f"seed={seed}", f"output_root={out / 'runs'}",
                 f"run_name={protocol}_seed{seed}_{stamp}", "trainer.enable_progress_bar=false",
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


def summarise(runs: list[dict], methods, protocols) -> list[dict]:
    """Mean and sd over seeds per (method, protocol)."""
    rows = []
    for protocol in protocols:
        for method in methods:
            chosen = [r for r in runs if r["method"] == method and r["protocol"] == protocol]
            if not chosen:
                continue
            row = {"method": method, "protocol": protocol, "n_seeds": len(chosen)}
            for key in ("accuracy", "acc", "nmi", "ari", "time_s"):
                values = np.array([r[key] for r in chosen], dtype=float)
                row[key] = float(values.mean())
                row[key + "_sd"] = float(values.std(ddof=1)) if len(values) > 1 else 0.0
            rows.append(row)
    return rows


def write_markdown(path: Path, summary: list[dict], config: dict, host: dict, total_s: float) -> None:
    lines = ["# MSR Action3D: bag of clip words (thesis §6.3)", "",
             f"Window {config['window']} frames, stride {config['stride']}, "
             f"{config['frames_per_clip']} frames per clip "
             f"(sign-split normalised coordinates, d = {config['feature_dim']}); k = {config['k']} words; "
             f"clusterers: max_iter {config['max_iter']}; classifier: {config['classifier']} with C by 3-fold CV on "
             f"the training sequences; seeds {config['seeds']}"
             + (" (**--quick**: small file subset, not a result)" if config["quick"] else "") + ".",
             "", "Accuracy = sequence recognition on the test half (mean ± sd over seeds). ACC / NMI / ARI = the "
             f"training clips' words against their action label (NMI normalisation: {NMI_NORMALISATION}). "
             "Time = fit + predict per split (layer: training + evaluation).", "",
             "| method | protocol | accuracy | clip ACC | clip NMI | clip ARI | time (s) |",
             "|---|---|---|---|---|---|---|"]
    for r in summary:
        lines.append(f"| {r['method']} | {r['protocol']} | {r['accuracy']:.2%} ± {r['accuracy_sd']:.2%} | "
                     f"{r['acc']:.3f} | {r['nmi']:.3f} | {r['ari']:.3f} | {r['time_s']:.1f} |")
    lines += ["", f"Thesis (Wang 2017, §6.3.4): **{THESIS_ACCURACY:.2%}** with NMC on a random half (features, k, "
              "λ, graph and classifier not stated; spec §8 item 37: a target band, not an exact reproduction). "
              "Only the random_half rows are comparable with it; cross_subject is the harder standard protocol.", "",
              f"Total {total_s / 60:.1f} min on {host['processor']} ({host['cpu_count']} CPUs, "
              f"OMP_NUM_THREADS={host['omp_num_threads']}), {host['platform']}.", ""]
    path.write_text("\n".join(lines))


def plot_accuracy(path: Path, summary: list[dict], methods, protocols) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1.2 * len(methods) + 2, 3.5))
    width = 0.8 / max(len(protocols), 1)
    for p, protocol in enumerate(protocols):
        rows = {r["method"]: r for r in summary if r["protocol"] == protocol}
        xs = [m for m in range(len(methods)) if methods[m] in rows]
        ax.bar([x + p * width for x in xs], [rows[methods[x]]["accuracy"] for x in xs], width,
               yerr=[rows[methods[x]]["accuracy_sd"] for x in xs], capsize=3, label=protocol)
    if "random_half" in protocols:
        ax.axhline(THESIS_ACCURACY, color="k", ls="--", lw=1, label="thesis 93.33% (random half)")
    ax.set_xticks([m + width * (len(protocols) - 1) / 2 for m in range(len(methods))], list(methods))
    ax.set_ylabel("test accuracy")
    ax.set_ylim(0, 1.15)
    ax.set_title("MSR Action3D, bag of clip words")
    ax.legend(fontsize=8, loc="upper center", ncol=3, frameon=False)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def run_benchmark(root: str | Path, out: str | Path, seeds=(0, 1, 2), protocols=PROTOCOLS, methods=METHODS,
                  k: int = 100, window: int = 30, stride: int | None = None, frames_per_clip: int = 10,
                  max_iter: int = 200, classifier: str = "logistic", quick: bool = False,
                  layer_overrides: list[str] | None = None) -> dict:
    """Run every (protocol, seed, method); write results.json, results.md and accuracy.png under ``out``."""
    root, out = Path(root), Path(out)
    unknown = [m for m in methods if m not in METHODS] + [p for p in protocols if p not in PROTOCOLS]
    if unknown:
        raise ValueError(f"unknown methods/protocols {unknown}; methods: {METHODS}, protocols: {PROTOCOLS}")
    out.mkdir(parents=True, exist_ok=True)
    stride = window // 2 if stride is None else stride
    if quick:
        seeds, k, max_iter = tuple(seeds)[:1], min(k, 5), min(max_iter, 20)
        root = quick_subset(root, out / "quick_data")
    total_start, stamp = time.perf_counter(), time.strftime("%Y%m%d-%H%M%S")
    data = MSRAction3D(root)
    labels = data.actions - 1
    positions = [data.positions(i) for i in range(len(data))]
    features, owner = sequence_clip_features(positions, window, stride, frames_per_clip, "msr20", names=data.names)
    print(f"[benchmark] {len(data)} sequences, {len(features)} clips of d = {features.shape[1]} "
          f"(window {window}, stride {stride}); k = {k}")
    config = {"root": str(root), "seeds": list(seeds), "protocols": list(protocols), "methods": list(methods),
              "k": k, "window": window, "stride": stride, "frames_per_clip": frames_per_clip,
              "feature_dim": int(features.shape[1]), "max_iter": max_iter, "classifier": classifier,
              "classifier_Cs": [0.1, 1.0, 10.0, 100.0], "quick": quick, "n_sequences": len(data),
              "n_clips": int(len(features)), "excluded": dict(data.excluded),
              "nmi_normalisation": NMI_NORMALISATION, "layer_overrides": list(layer_overrides or [])}
    host = machine()
    runs = []
    for protocol in protocols:
        for seed in seeds:
            train, test = msr_split_indices(data, protocol, seed=seed)
            for method in methods:
                print(f"[benchmark] {protocol} seed {seed}: {method} ...", flush=True)
                if method == "layer":
                    result = run_layer(root, out, protocol, seed, window, stride, frames_per_clip, data, labels,
                                       train, quick, list(layer_overrides or []), stamp)
                else:
                    result = run_classical(method, features, owner, labels, train, test, k, seed, max_iter,
                                           classifier)
                result.update({"method": method, "protocol": protocol, "seed": seed,
                               "n_train": int(len(train)), "n_test": int(len(test))})
                runs.append(result)
                print(f"[benchmark] {protocol} seed {seed}: {method} accuracy {result['accuracy']:.2%}, "
                      f"clip ACC {result['acc']:.3f} NMI {result['nmi']:.3f} ARI {result['ari']:.3f}, "
                      f"{result['time_s']:.1f} s", flush=True)
    total_s = time.perf_counter() - total_start
    summary = summarise(runs, methods, protocols)
    results = {"config": config, "machine": host, "total_time_s": total_s, "thesis_accuracy_random_half":
               THESIS_ACCURACY, "summary": summary, "runs": runs}
    (out / "results.json").write_text(json.dumps(results, indent=2))
    write_markdown(out / "results.md", summary, config, host, total_s)
    plot_accuracy(out / "accuracy.png", summary, list(methods), list(protocols))
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
    parser.add_argument("--k", type=int, default=100, help="words (clusters / NMF components)")
    parser.add_argument("--window", type=int, default=30, help="clip length M in frames (stride M/2)")
    parser.add_argument("--frames-per-clip", type=int, default=10)
    parser.add_argument("--max-iter", type=int, default=200, help="iterations of the clusterers")
    parser.add_argument("--classifier", default="logistic", choices=("logistic", "linear_svc"))
    parser.add_argument("--quick", action="store_true", help="1 seed, <= 40-file subset, tiny k (for tests)")
    parser.add_argument("--layer-override", action="append", default=[],
                        help="extra Hydra override for the layer runs (repeatable), e.g. trainer.max_epochs=30")
    args = parser.parse_args(argv)
    run_benchmark(args.root, args.out, seeds=args.seeds, protocols=args.protocols, methods=args.methods, k=args.k,
                  window=args.window, frames_per_clip=args.frames_per_clip, max_iter=args.max_iter,
                  classifier=args.classifier, quick=args.quick, layer_overrides=args.layer_override)
    return 0


if __name__ == "__main__":
    sys.exit(main())
