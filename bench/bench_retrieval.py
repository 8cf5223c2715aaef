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

A DTW row may carry parameters after a colon (``dtw_world_frame:prefilter=100,n_reference=128``). A row with
``prefilter`` (the two-stage search: a FAISS prefilter on fixed-length descriptors, then DTW on the ``K`` it returns)
also reports **recall@10 against the same method's exact search** (every clip ranked, ``--recall-queries`` queries;
also over the real clips behind the exact top 10, as the order among one clip's near copies is noise) and the
memory of what it keeps (the database's feature sequences, the reference statistics and the FAISS index).

``--cold`` drops a row's frame files (a library built in parts, ``--chunk``) from the page cache before each timed
query: each query reads its candidates' frames from the disk, the state of a library larger than memory. The same
queries then run cold with and without the prefetch of their candidates' pages, alternating (the reference).

``--fresh-query`` also saves each DTW row's fitted method as an index folder (``mocapkit index``'s format) and times
the same queries in a **new process that loads it** (what ``mocapkit search`` does): query p50 / p95 on a first and
a second pass, and that process's memory (private, file-backed, peak), without what building left behind.

Each size prints DTW / embedding latency as a ratio, in the same run (without ``--onnx``, the DTW rows alone, the
prefiltered one against the same method's exact search). A PNG of latency against size goes beside the results
(``--plot``).

    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_retrieval.py --onnx checkpoints/retrieval_supcon/fold_bd/model.onnx
    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_retrieval.py --sizes 1000,10000 \
        --dtw-methods "dtw_world_frame:n_reference=128;dtw_world_frame:n_reference=128,prefilter=100;dtw_large" --plot ""
    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_retrieval.py --sizes 100000 --dtw-max 100000 --kernel-clips 0 \
        --dtw-methods dtw_large --prefilter-grid 100,300,600,1000 --plot ""
    OMP_NUM_THREADS=1 .venv/bin/python bench/bench_retrieval.py --sizes 100000 --dtw-max 100000 --kernel-clips 0 \
        --dtw-methods dtw_large --chunk 50000 --fresh-query --plot ""
"""

from __future__ import annotations

import argparse
import gc
import os
import platform
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
DEFAULT_DATA = ROOT.parent / "shared" / "data" / "hdm05_cuts11"


def augmented(motions, count: int, seed: int = 0):
    """``count`` clips: the real ones first, then copies time-scaled, cropped and jittered (seeded)."""
    return list(augmented_clips(motions, count, seed))


def augmented_clips(motions, count: int, seed: int = 0):
    """:func:`augmented`'s clips one at a time (a library larger than memory is built from them in parts)."""
    rng = np.random.default_rng(seed)
    yield from motions[:count]
    made = min(count, len(motions))
    while made < count:
        m = motions[int(rng.integers(len(motions)))]
        speed = rng.uniform(0.8, 1.25)
        fps = m.fps * speed
        start = rng.uniform(0, 0.1)
        T = m.num_frames
        a, b = int(start * T), int(T - rng.uniform(0, 0.1) * T)
        positions = m.positions[a : max(b, a + 8)] + rng.normal(
            scale=0.01, size=(max(b, a + 8) - a,) + m.positions.shape[1:]
        )
        yield replace(m, positions=positions.astype(np.float32), missing=None, fps=fps, name=f"{m.name}~{made}")
        made += 1


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
    parser.add_argument(
        "--onnx", default=None, help="an exported retrieval encoder (mocapkit export); none: DTW rows only"
    )
    parser.add_argument("--sizes", default="1000,10000,100000,1000000")
    parser.add_argument("--dtw-max", type=int, default=10000, help="largest library DTW is measured on")
    parser.add_argument(
        "--dtw-methods",
        default="dtw_relational;dtw_world_frame",
        help="DTW rows, separated by ';': retrieval method names of the registry (mocapkit methods retrieval), "
        "each with optional parameters after ':' (name:key=value,key=value)",
    )
    parser.add_argument("--recall-queries", type=int, default=20, help="queries scored against exact search")
    parser.add_argument(
        "--chunk",
        type=int,
        default=100000,
        help="DTW libraries larger than this are built in parts of this many clips, their frames in files",
    )
    parser.add_argument("--frames-dir", default=None, help="where those files go (default: the system's temp folder)")
    parser.add_argument("--encode", type=int, default=5000, help="augmented clips actually encoded")
    parser.add_argument("--hnsw-max", type=int, default=1000000)
    parser.add_argument("--plot", default=str(ROOT / "docs" / "img" / "retrieval_latency.png"))
    parser.add_argument(
        "--prefilter-grid",
        default="",
        help="for each prefiltered row, also search the fitted method with these candidate counts (e.g. 100,300,600)",
    )
    parser.add_argument(
        "--kernel-clips",
        type=int,
        default=2000,
        help="clips for the DTW kernel comparison (mocapkit's against dtaidistance's, one query); 0: skip it",
    )
    parser.add_argument(
        "--fresh-query",
        action="store_true",
        help="also time each DTW row's queries in a new process that loads the row's index from disk",
    )
    parser.add_argument(
        "--cold",
        action="store_true",
        help="drop a row's frame files from the page cache before each timed query (and before each query of the new "
        "process's first pass): every candidate's frames are read from the disk, as in a library larger than memory",
    )
    parser.add_argument("--query-index", default=None, help=argparse.SUPPRESS)  # the new process's own mode
    args = parser.parse_args()
    if args.query_index:
        query_saved_index(args.query_index, args.cold)
        return

    import faiss

    from mocapkit.datasets.mocap.folders import list_clips, read_clips

    faiss.omp_set_num_threads(1)
    sizes = [int(s) for s in args.sizes.split(",")]
    print(
        f"# retrieval at scale — {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS')}, faiss {faiss.__version__} (1 thread)"
    )
    real = read_clips(list_clips("hdm05", args.data))
    queries = augmented(real, len(real) + 50, seed=99)[len(real) :]  # 50 augmented clips, not indexed

    rows = []
    if args.kernel_clips:
        kernel_rows(args, real, queries)
    query_encode_ms = 0.0
    if args.onnx:
        query_encode_ms = embedding_rows(args, real, queries, sizes, rows)
    dtw_rows(args, real, queries, sizes, rows, query_encode_ms)
    report(args, rows, query_encode_ms)


def kernel_rows(args, real, queries) -> None:
    """Exact DTW of one query (of median duration) against ``--kernel-clips`` clips, per feature: dtaidistance's C
    (the reference, one thread) against :class:`~mocapkit.retrieval.frames.CandidateCosts` (matrix products + compiled programme), the
    same sequences, in one run; medians of 5 alternating repeats, and the largest relative difference."""
    from dtaidistance import dtw_ndim

    from mocapkit.retrieval.dtw import DTWRetrieval
    from mocapkit.retrieval.frames import CandidateCosts, RaggedFrames

    method = DTWRetrieval(features=["positions", "relational"], world_frame="off").fit(real[:2])
    library = augmented(real, args.kernel_clips, seed=0)
    lengths = [m.num_frames / m.fps for m in queries]
    typical = queries[int(np.argsort(lengths)[len(lengths) // 2])]  # the query of median duration
    encoded, query = method.encode(library), method.encode([typical])
    for name in method.features_:
        store = RaggedFrames.from_list(encoded[name])
        sequences = list(store)  # the float32-rounded frames, in float64: both see the same numbers
        q = query[name][0]
        times = {"dtaidistance": [], "mocapkit": []}
        for _ in range(5):
            start = time.perf_counter()
            reference = np.asarray(
                dtw_ndim.distance_matrix_fast(
                    [q] + sequences, block=((0, 1), (1, len(sequences) + 1)), compact=True, parallel=False
                )
            )
            times["dtaidistance"].append(1000 * (time.perf_counter() - start))
            start = time.perf_counter()
            ours = CandidateCosts(q, store).distances()
            times["mocapkit"].append(1000 * (time.perf_counter() - start))
        a, b = np.median(times["dtaidistance"]), np.median(times["mocapkit"])
        worst = float(np.max(np.abs(ours - reference) / np.maximum(reference, 1e-12)))
        frames = int(store.lengths.sum())
        print(
            f"DTW kernel, {name} ({store.dim} dims), one query ({len(q)} frames) against {len(store)} clips "
            f"({frames} frames): dtaidistance {a:.1f} ms, mocapkit {b:.1f} ms = {a / b:.1f}x faster; largest "
            f"relative difference {worst:.1e}",
            flush=True,
        )


def embedding_rows(args, real, queries, sizes, rows) -> float:
    """The embedding's flat and HNSW rows; returns the query encoding time (ms)."""
    from mocapkit.retrieval.embedding import EmbeddingRetrieval

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
    return query_encode_ms


def method_bytes(method) -> tuple[int, int]:
    """``(in memory, on disk)``: bytes of what a fitted method keeps (its state's arrays, the FAISS index serialised
    among them), those memory-mapped from files apart (a search reads only its candidates' frames from them)."""
    arrays = method._state().values()
    return (
        int(sum(np.asarray(v).nbytes for v in arrays if not isinstance(v, np.memmap))),
        int(sum(v.nbytes for v in arrays if isinstance(v, np.memmap))),
    )


def process_memory_mb(field: str = "RssAnon") -> float:
    """This process's resident memory not backed by files (``RssAnon``; memory-mapped frames read from disk are
    the kernel's page cache, given back under pressure), or another memory line of ``/proc/self/status``
    (``RssFile``, ``VmHWM``: the peak), MB; NaN where /proc is absent."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith(f"{field}:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return float("nan")


def evict_frames(method) -> None:
    """Drop ``method``'s memory-mapped frame files from the page cache (``--cold``): this process's mappings of their
    pages first (``madvise(MADV_DONTNEED)``; the kernel keeps a page mapped by a process), then the files' cached
    pages (written back first, ``posix_fadvise(POSIX_FADV_DONTNEED)``). The next query reads its candidates' frames
    from the disk."""
    import mmap

    for name in method.features_:
        data = method.database_[name].data
        if not isinstance(data, np.memmap):
            continue
        data._mmap.madvise(mmap.MADV_DONTNEED)
        descriptor = os.open(data.filename, os.O_RDONLY)
        try:
            os.fdatasync(descriptor)
            os.posix_fadvise(descriptor, 0, 0, os.POSIX_FADV_DONTNEED)
        finally:
            os.close(descriptor)


def cold_reference(dtw, queries, size: int) -> None:
    """``--cold``'s reference in the same run: each query searched cold with the gather's prefetch
    (:func:`mocapkit.retrieval.frames.prefetch`) and cold without it (every page fault waits for its own read),
    alternating; prints both medians and their ratio."""
    from unittest import mock

    from mocapkit.retrieval import frames

    times = {True: [], False: []}
    for i, query in enumerate(queries):
        for prefetched in (True, False) if i % 2 else (False, True):
            with mock.patch.object(frames, "prefetch", frames.prefetch if prefetched else lambda *args: None):
                evict_frames(dtw)
                start = time.perf_counter()
                dtw.search([query], 10)
                times[prefetched].append(1000 * (time.perf_counter() - start))
    with_, without = np.median(times[True]), np.median(times[False])
    print(
        f"size {size:>8}:   cold queries, alternating: p50 {with_:.1f} ms (p95 {np.percentile(times[True], 95):.1f}) "
        f"with the prefetch, {without:.1f} ms (p95 {np.percentile(times[False], 95):.1f}) without: "
        f"{without / with_:.1f}x",
        flush=True,
    )


def fresh_query(dtw, spec: str, queries, folder: str, cold: bool = False) -> dict:
    """Save ``dtw`` as an index in ``folder`` (frames already there stay where they are) and time ``queries`` in a
    new process that loads it (:func:`query_saved_index`); its JSON report."""
    import json
    import pickle
    import subprocess

    from mocapkit.retrieval.index import MotionIndex

    name = spec.partition(":")[0]
    files = [{"path": f"clip{i}"} for i in range(dtw.n_database_)]
    MotionIndex(name, dtw, files, landmarks=[], skipped=[]).save(folder)
    with open(Path(folder) / "bench_queries.pkl", "wb") as handle:
        pickle.dump(list(queries), handle)
    done = subprocess.run(
        [sys.executable, __file__, "--query-index", folder] + (["--cold"] if cold else []),
        capture_output=True,
        text=True,
        check=True,
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def query_saved_index(folder: str, cold: bool = False) -> None:
    """The new process of :func:`fresh_query`: load the index, search each query twice (a first pass, with ``cold``
    each query's frames read from the disk, then a second with whatever the first left in the page cache), print one
    JSON line."""
    import json
    import pickle

    import faiss

    from mocapkit.retrieval.index import MotionIndex

    faiss.omp_set_num_threads(1)
    with open(Path(folder) / "bench_queries.pkl", "rb") as handle:
        queries = pickle.load(handle)
    start = time.perf_counter()
    method = MotionIndex.load(folder).method
    load_s = time.perf_counter() - start
    loaded_mb = process_memory_mb()
    passes = []
    for second in (False, True):
        times = []
        for query in queries:
            if cold and not second:
                evict_frames(method)
            start = time.perf_counter()
            method.search([query], 10)
            times.append(1000 * (time.perf_counter() - start))
        passes.append(times)
    report = {"load_s": load_s, "private_after_load_mb": loaded_mb}
    for label, times in zip(("first", "second"), passes):
        report[f"{label}_p50_ms"], report[f"{label}_p95_ms"] = float(np.median(times)), float(np.percentile(times, 95))
    report.update(
        private_mb=process_memory_mb(), file_backed_mb=process_memory_mb("RssFile"), peak_mb=process_memory_mb("VmHWM")
    )
    print(json.dumps(report))


def source_name(clip) -> str:
    """The real clip an augmented one was made from (:func:`augmented_clips` names a copy ``{source}~{number}``)."""
    return clip.name.partition("~")[0]


def build_streamed(dtw, real, size: int, chunk: int, folder: str) -> list[str]:
    """Fit ``dtw`` on the first ``chunk`` clips of the augmented library, move its frames to ``.npy`` files in
    ``folder`` (``store_frames``) and add the rest ``chunk`` clips at a time: no more than ``chunk`` clips' motions
    and features are in memory at once. Making the augmented clips is part of the time. Returns each clip's
    :func:`source_name`."""
    from itertools import islice

    clips = augmented_clips(real, size, seed=0)
    start = time.perf_counter()
    first = list(islice(clips, chunk))
    sources = [source_name(c) for c in first]
    dtw.fit(first)
    del first
    dtw.store_frames(folder)
    while batch := list(islice(clips, chunk)):
        sources += [source_name(c) for c in batch]
        dtw.add(batch)
        del batch  # before the next part is made: one part's motions in memory at a time
        print(
            f"  built {dtw.n_database_:,} / {size:,} clips in {time.perf_counter() - start:.0f} s "
            f"({process_memory_mb():.0f} MB private)",
            flush=True,
        )
    return sources


def source_recall(found: np.ndarray, exact: np.ndarray, sources: np.ndarray) -> float:
    """The mean share of the real clips behind each query's exact top ``k`` that its ``found`` top ``k`` also
    returns a copy of: recall over distinct motions, where the exact order among a real clip's near copies (thousands
    of them in a library of 10^6 augmented clips) is noise."""
    return float(np.mean([len(set(sources[a]) & set(sources[b])) / len(set(sources[b])) for a, b in zip(found, exact)]))


def dtw_rows(args, real, queries, sizes, rows, query_encode_ms: float) -> None:
    """One row per DTW method and size: build, query p50 / p95, memory; recall@10 against exact search for a
    prefiltered row."""
    from mocapkit.retrieval.base import top_k
    from mocapkit.retrieval.index import make_method

    for spec in args.dtw_methods.split(";"):
        name, _, params = spec.partition(":")
        overrides = [p for p in params.split(",") if p]
        for size in [s for s in sizes if s <= args.dtw_max]:
            dtw = make_method(name, overrides)
            streamed = size > args.chunk
            lib = None if streamed else augmented(real, size, seed=0)  # (a streamed build augments as it goes)
            folder = tempfile.mkdtemp(prefix="bench_retrieval_", dir=args.frames_dir) if streamed else None
            start = time.perf_counter()
            if streamed:
                sources = build_streamed(dtw, real, size, args.chunk, folder)
            else:
                sources = [source_name(c) for c in lib]
                dtw.fit(lib)
            build_s = time.perf_counter() - start
            sources = np.asarray(sources)
            del lib
            gc.collect()
            repeats = min(len(queries), 20 if size <= 1000 or dtw.prefilter else 2)
            times = []
            for i in range(repeats):
                if args.cold:
                    evict_frames(dtw)
                start = time.perf_counter()
                dtw.search([queries[i]], 10)
                times.append(1000 * (time.perf_counter() - start))
            private_mb = process_memory_mb()
            if args.cold and streamed:
                cold_reference(dtw, queries[:repeats], size)
            recall = motions_recall = None
            if dtw.prefilter:
                n = min(args.recall_queries, len(queries))
                exact = top_k(dtw.distances(queries[:n]), 10)[0]
                found = dtw.search(queries[:n], 10)[0]
                recall = float(np.mean([len(set(a) & set(b)) / 10 for a, b in zip(exact, found)]))
                motions_recall = source_recall(found, exact, sources)
                for candidates in [int(c) for c in args.prefilter_grid.split(",") if c]:
                    grid_row(dtw, candidates, queries[:n], exact, size)
            in_memory, on_disk = method_bytes(dtw)
            fresh = None
            if args.fresh_query:
                folder = folder or tempfile.mkdtemp(prefix="bench_retrieval_", dir=args.frames_dir)
                fresh = fresh_query(dtw, spec, queries[: min(len(queries), 20)], folder, args.cold)
                print(
                    f"size {size:>8}:   {spec} in a new process loading the index ({fresh['load_s']:.1f} s): "
                    f"query p50 {fresh['first_p50_ms']:.1f} ms (p95 {fresh['first_p95_ms']:.1f}) on a first pass, "
                    f"{fresh['second_p50_ms']:.1f} ms (p95 {fresh['second_p95_ms']:.1f}) on a second; memory "
                    f"{fresh['private_mb']:.0f} MB private ({fresh['private_after_load_mb']:.0f} MB after loading), "
                    f"{fresh['file_backed_mb']:.0f} MB of mapped files resident, peak {fresh['peak_mb']:.0f} MB",
                    flush=True,
                )
            if folder is not None:
                del dtw  # (its memory maps of the files)
                shutil.rmtree(folder)
            row = {
                "size": size,
                "method": spec,
                "build_s": build_s,
                "query_ms": float(np.median(times)),
                "query_p95_ms": float(np.percentile(times, 95)),
                "memory_mb": in_memory / 2**20,
                "disk_mb": on_disk / 2**20,
                "process_mb": private_mb,
                "recall@10": recall,
                "recall@10 of real clips": motions_recall,
                "fresh": fresh,
            }
            rows.append(row)
            flat = next((r for r in rows if r["size"] == size and r["method"] == "embedding/flat"), None)
            ratio = (
                f" = {row['query_ms'] / (flat['query_ms'] + query_encode_ms):,.0f}x the embedding flat index"
                if flat
                else ""
            )
            print(
                f"size {size:>8}: {spec} build {build_s:8.2f} s, query p50 {row['query_ms']:9.1f} ms, "
                f"p95 {row['query_p95_ms']:9.1f} ms, {row['memory_mb']:.0f} MB in memory + {row['disk_mb']:.0f} MB "
                f"memory-mapped (process {private_mb:.0f} MB private after the timed queries)"
                + (
                    f", recall@10 vs exact {recall:.3f} ({motions_recall:.3f} of the real clips behind the exact top 10)"
                    if recall is not None
                    else ""
                )
                + ratio,
                flush=True,
            )


def grid_row(dtw, candidates: int, queries, exact: np.ndarray, size: int) -> None:
    """The same fitted method searched with ``prefilter=candidates``: query p50 / p95 with a query's features on
    one thread and on their own threads (``parallel``, alternating), and recall@10 against ``exact``
    (``--prefilter-grid``: the candidates of ``dtw_large``, docs/decisions.md)."""
    kept = dtw.prefilter, dtw.parallel
    dtw.prefilter = candidates
    times = {False: [], True: []}
    for query in queries:
        for parallel in (False, True):
            dtw.parallel = parallel
            start = time.perf_counter()
            dtw.search([query], 10)
            times[parallel].append(1000 * (time.perf_counter() - start))
    found = dtw.search(queries, 10)[0]
    dtw.prefilter, dtw.parallel = kept
    recall = float(np.mean([len(set(a) & set(b)) / 10 for a, b in zip(exact, found)]))
    one, each = times[False], times[True]
    print(
        f"size {size:>8}:   prefilter={candidates}: query p50 {np.median(one):.1f} ms, p95 {np.percentile(one, 95):.1f}"
        f" ms on one thread; p50 {np.median(each):.1f} ms, p95 {np.percentile(each, 95):.1f} ms with a thread a "
        f"feature; recall@10 vs exact {recall:.3f}",
        flush=True,
    )


def report(args, rows, query_encode_ms: float) -> None:
    print(
        "\n| library size | method | build (s) | query p50 (ms) | query p95 (ms) | memory (MB) | memory-mapped (MB) "
        "| process private (MB) | recall@10 | recall@10 of real clips |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        cells = [
            "" if r.get(key) is None else f"{r[key]:{spec}}"
            for key, spec in [
                ("query_p95_ms", ".1f"),
                ("memory_mb", ".0f"),
                ("disk_mb", ".0f"),
                ("process_mb", ".0f"),
                ("recall@10", ".3f"),
                ("recall@10 of real clips", ".3f"),
            ]
        ]
        print(
            f"| {r['size']:,} | {r['method']} | {r['build_s']:.2f} | {r['query_ms']:.3f} | " + " | ".join(cells) + " |"
        )
    if args.onnx:
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
