"""Retrieval at scale: index build time and query latency against library size, DTW against the embedding index.

The library is real HDM05 clips (``../shared/data/hdm05_cuts11``, 232 clips) replicated with augmentation
(time scaling 0.8–1.25×, a temporal crop of 80–100 %, 1 cm joint jitter) up to the size asked:

- **DTW** (:class:`~mocapkit.retrieval.dtw.DTWRetrieval`, the baseline a user would otherwise reach for, and the
  ``mocapkit index`` default, DTW on positions and relational features with mutual proximity): the augmented clips
  themselves, one row per name of ``--dtw-methods`` (registry names: ``mocapkit methods retrieval``); build = ``fit``
  (normalise + per-frame features; with mutual proximity also DTW from every clip to at most 512 reference clips),
  query = one query clip ranked against the whole library (median over queries), measured up to ``--dtw-max``
  clips;
- **embedding** (:class:`~mocapkit.retrieval.embedding.EmbeddingRetrieval` from an exported ONNX encoder):
  ``--encode`` augmented clips are encoded (their throughput is reported); larger libraries repeat those
  embeddings with Gaussian noise (σ = 0.05 per dimension, renormalised) — the index sees vectors with the spread
  of real ones, but they are not encodings of distinct clips. Build = adding the vectors to FAISS (flat, exact
  inner product; HNSW, approximate); query = the FAISS search of one query (k = 10, median over 200) plus, as its
  own column, encoding the query clip.

Each size prints DTW / embedding latency as a ratio, in the same run. A PNG of latency against size goes beside
the results (``--plot``).

    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_retrieval.py --onnx checkpoints/retrieval_supcon/fold_bd/model.onnx
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "hdm05_cuts11"


def augmented(motions, count: int, seed: int = 0):
    """``count`` clips: the real ones first, then copies time-scaled, cropped and jittered (seeded)."""
    rng = np.random.default_rng(seed)
    out = list(motions[:count])
    while len(out) < count:
        m = motions[int(rng.integers(len(motions)))]
        speed = rng.uniform(0.8, 1.25)
        fps = m.fps * speed
        start = rng.uniform(0, 0.1)
        T = m.num_frames
        a, b = int(start * T), int(T - rng.uniform(0, 0.1) * T)
        positions = m.positions[a : max(b, a + 8)] + rng.normal(
            scale=0.01, size=(max(b, a + 8) - a,) + m.positions.shape[1:]
        )
        out.append(
            replace(m, positions=positions.astype(np.float32), missing=None, fps=fps, name=f"{m.name}~{len(out)}")
        )
    return out


def median_ms(fn, repeats: int) -> float:
    times = []
    for i in range(repeats):
        start = time.perf_counter()
        fn(i)
        times.append(1000 * (time.perf_counter() - start))
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--data", default=str(DEFAULT_DATA))
    parser.add_argument("--onnx", required=True, help="an exported retrieval encoder (mocapkit export)")
    parser.add_argument("--sizes", default="1000,10000,100000,1000000")
    parser.add_argument("--dtw-max", type=int, default=10000, help="largest library DTW is measured on")
    parser.add_argument(
        "--dtw-methods",
        default="dtw_relational,dtw_mutual_proximity",
        help="DTW rows: retrieval method names of the registry (mocapkit methods retrieval)",
    )
    parser.add_argument("--encode", type=int, default=5000, help="augmented clips actually encoded")
    parser.add_argument("--hnsw-max", type=int, default=1000000)
    parser.add_argument("--plot", default=str(ROOT / "docs" / "img" / "retrieval_latency.png"))
    args = parser.parse_args()

    import faiss

    from mocapkit.datasets.mocap.folders import list_clips, read_clips
    from mocapkit.retrieval.embedding import EmbeddingRetrieval
    from mocapkit.retrieval.index import make_method

    faiss.omp_set_num_threads(1)
    sizes = [int(s) for s in args.sizes.split(",")]
    print(
        f"# retrieval at scale — {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}, faiss {faiss.__version__} (1 thread)"
    )
    real = read_clips(list_clips("hdm05", args.data))
    queries = augmented(real, len(real) + 50, seed=99)[len(real) :]  # 50 augmented clips, not indexed

    rows = []
    # ---------------------------------------------------------------- embedding
    method = EmbeddingRetrieval(onnx=args.onnx)
    encode_n = min(args.encode, max(sizes))
    library = augmented(real, encode_n, seed=0)
    start = time.perf_counter()
    method.fit(library)
    encode_s = time.perf_counter() - start
    print(
        f"encoded {encode_n} clips in {encode_s:.1f} s ({encode_n / encode_s:.0f} clips/s, "
        f"{1000 * encode_s / encode_n:.2f} ms/clip incl. normalisation)"
    )
    base = np.asarray(method.database_, dtype=np.float32)
    rng = np.random.default_rng(0)
    query_encode_ms = median_ms(lambda i: method.encode([queries[i % len(queries)]]), 50)
    q_vectors = method.encode(queries)
    for size in sizes:
        reps = int(np.ceil(size / len(base)))
        vectors = np.concatenate(
            [base] + [base + rng.normal(scale=0.05, size=base.shape).astype(np.float32) for _ in range(reps - 1)]
        )[:size]
        vectors /= np.linalg.norm(vectors, axis=1, keepdims=True)
        for kind in ("flat", "hnsw"):
            if kind == "hnsw" and size > args.hnsw_max:
                continue
            m = EmbeddingRetrieval(onnx=args.onnx, index=kind)
            m.__dict__.update(
                {k: v for k, v in method.__dict__.items() if k in ("_predict", "model_sha1_", "frames_", "model_info_")}
            )
            m.database_, m.n_database_ = vectors, size
            start = time.perf_counter()
            m._build_index()
            build_s = time.perf_counter() - start
            if kind == "hnsw":
                m.index_.hnsw.efSearch = 64
            search_ms = median_ms(lambda i, m=m: m.index_.search(q_vectors[i % len(q_vectors)][None], 10), 200)
            recall = None
            if kind == "hnsw":
                exact = np.argsort(-(q_vectors @ vectors.T), axis=1)[:, :10]
                found = m.index_.search(q_vectors, 10)[1]
                recall = float(np.mean([len(set(a) & set(b)) / 10 for a, b in zip(exact, found)]))
            rows.append(
                {
                    "size": size,
                    "method": f"embedding/{kind}",
                    "build_s": build_s + encode_s * size / encode_n if size <= encode_n else build_s,
                    "query_ms": search_ms,
                    "recall@10": recall,
                }
            )
            print(
                f"size {size:>8}: embedding {kind:5s} build {build_s:8.2f} s (FAISS add), search {search_ms:7.3f} ms"
                f" + encode query {query_encode_ms:.2f} ms" + (f", recall@10 vs exact {recall:.3f}" if recall else ""),
                flush=True,
            )
    # ---------------------------------------------------------------- DTW
    for name in args.dtw_methods.split(","):
        for size in [s for s in sizes if s <= args.dtw_max]:
            dtw = make_method(name)
            lib = augmented(real, size, seed=0)
            start = time.perf_counter()
            dtw.fit(lib)
            build_s = time.perf_counter() - start
            repeats = 5 if size <= 1000 else 2
            query_ms = median_ms(lambda i, dtw=dtw: dtw.search([queries[i]], 10), repeats)
            rows.append({"size": size, "method": name, "build_s": build_s, "query_ms": query_ms})
            flat = next(r for r in rows if r["size"] == size and r["method"] == "embedding/flat")
            ratio = query_ms / (flat["query_ms"] + query_encode_ms)
            print(
                f"size {size:>8}: {name} build {build_s:8.2f} s, query {query_ms:9.1f} ms "
                f"= {ratio:,.0f}x the embedding flat index (search + query encoding)",
                flush=True,
            )

    print("\n| library size | method | build (s) | query (ms) | recall@10 |")
    print("|---:|---|---:|---:|---:|")
    for r in rows:
        recall = "" if r.get("recall@10") is None else f"{r['recall@10']:.3f}"
        print(f"| {r['size']:,} | {r['method']} | {r['build_s']:.2f} | {r['query_ms']:.3f} | {recall} |")
    print(f"\nquery encoding (normalise + ONNX encoder, one clip): {query_encode_ms:.2f} ms")
    if args.plot:
        from mocapkit.evaluation.plots import pyplot, save_figure

        plt = pyplot()
        fig, ax = plt.subplots(figsize=(6, 4))
        for name in dict.fromkeys(r["method"] for r in rows):
            pts = [
                (r["size"], r["query_ms"] + (query_encode_ms if name.startswith("embedding") else 0))
                for r in rows
                if r["method"] == name
            ]
            ax.plot(*zip(*pts), marker="o", label=name + (" (+ query encoding)" if name.startswith("emb") else ""))
        ax.axhline(10, color="grey", ls="--", lw=0.8)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("library size (clips)")
        ax.set_ylabel("query latency (ms, median)")
        ax.legend(fontsize=8)
        ax.set_title("Retrieval latency, one CPU thread")
        Path(args.plot).parent.mkdir(parents=True, exist_ok=True)
        save_figure(fig, args.plot)
        print(f"wrote {args.plot}")


if __name__ == "__main__":
    main()
