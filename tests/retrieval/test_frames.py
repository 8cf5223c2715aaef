"""RaggedFrames (clips' frames end to end) and CandidateCosts (one query against many clips) against dtaidistance."""

from __future__ import annotations

import numpy as np
import pytest
from dtaidistance import dtw_ndim

from mocapkit.retrieval.dtw import DTWRetrieval
from mocapkit.retrieval.frames import CandidateCosts, RaggedFrames, candidate_dtw


def clips(rng, n, d=5, longest=30):
    return [rng.normal(size=(int(rng.integers(1, longest)), d)) for _ in range(n)]


def test_candidate_dtw_is_dtaidistances_unconstrained_dtw():
    rng = np.random.default_rng(0)
    database = clips(rng, 40)
    store = RaggedFrames.from_list(database)
    for query in clips(rng, 5) + [rng.normal(size=(1, 5))]:  # one-frame query and candidates among them
        picked = store.subset(rng.permutation(len(store))[:25])
        costs = CandidateCosts(query, picked)
        got = costs.distances()
        expected = [dtw_ndim.distance(query, picked[k]) for k in range(len(picked))]
        np.testing.assert_allclose(got, expected, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(candidate_dtw(query, picked), got)
        np.testing.assert_allclose(costs.distances([3, 0]), got[[3, 0]])
        bounds = costs.lower_bounds()
        assert (bounds <= got + 1e-9).all() and (bounds > 0.3 * got).all()  # a bound, and not a trivial one


def test_candidate_costs_reject_mismatched_input():
    q = np.zeros((4, 3))
    with pytest.raises(ValueError, match=r"\[T >= 1, 2\].*got \(4, 3\)"):
        CandidateCosts(q, RaggedFrames(np.zeros((6, 2), np.float32), np.array([0, 6])))
    with pytest.raises(ValueError, match="at least one frame"):
        CandidateCosts(q, RaggedFrames(np.zeros((6, 3), np.float32), np.array([0, 6, 6])))
    assert candidate_dtw(q, RaggedFrames.from_list([], dim=3)).shape == (0,)


def test_ragged_frames_keeps_every_clip_through_subset_extend_chunks_and_state():
    rng = np.random.default_rng(1)
    arrays = clips(rng, 12)
    store = RaggedFrames.from_list(arrays)
    assert len(store) == 12 and store.data.dtype == np.float32 and store.dim == 5
    for i, a in enumerate(arrays):
        np.testing.assert_allclose(store[i], a, rtol=1e-6)
        assert store[i].dtype == np.float64 and store[i].flags.c_contiguous
    picked = store.subset([7, 2, 7])
    np.testing.assert_array_equal(picked.lengths, [len(arrays[7]), len(arrays[2]), len(arrays[7])])
    np.testing.assert_array_equal(picked[1], store[2])
    reference = np.array([7, 2, 7])  # a subset every query reads: gathered once per index array
    kept = store.kept_subset(reference)
    np.testing.assert_array_equal(kept.data, picked.data)
    assert store.kept_subset(reference) is kept and store.kept_subset(np.array([2])) is not kept
    np.testing.assert_array_equal(store.kept_subset(np.array([2])).data, store.subset([2]).data)
    grown = store.extend(arrays[:3])
    assert len(grown) == 15 and len(store) == 12
    np.testing.assert_array_equal(grown[13], store[1])
    chunks = store.chunks(40)
    assert chunks[0][0] == 0 and chunks[-1][1] == 12
    assert all(a < b for a, b in chunks) and all(b == c for (_, b), (c, _) in zip(chunks, chunks[1:]))
    for a, b in chunks:  # at most 40 frames, unless one clip alone is longer
        assert store.offsets[b] - store.offsets[a] <= 40 or b == a + 1
    back = RaggedFrames.from_state("x", store.to_state("x"))
    np.testing.assert_array_equal(back.data, store.data)
    with pytest.raises(ValueError, match="offsets"):
        RaggedFrames(np.zeros((5, 2), np.float32), np.array([0, 3]))


def test_dtw_distances_without_a_band_equal_dtaidistance_across_chunks(monkeypatch):
    """The unbanded path (matrix products, database in chunks, queries on threads) gives dtaidistance's values,
    length-normalised, whatever the chunk size."""
    import mocapkit.retrieval.dtw as dtw_module

    rng = np.random.default_rng(2)
    queries, database = clips(rng, 6), clips(rng, 9)
    method = DTWRetrieval(parallel=True)
    whole = method._feature_distances(queries, database)
    monkeypatch.setattr(dtw_module, "CHUNK_FRAMES", 7)
    chunked = method._feature_distances(queries, RaggedFrames.from_list(database))
    np.testing.assert_allclose(chunked, whole, rtol=1e-6, atol=1e-6)
    expected = np.array([[dtw_ndim.distance(q, x) / np.sqrt(len(q) + len(x)) for x in database] for q in queries])
    np.testing.assert_allclose(whole, expected, rtol=1e-6, atol=1e-6)


def test_a_saved_store_grows_in_place_and_an_interrupted_append_is_overwritten(tmp_path):
    """:meth:`RaggedFrames.save` returns the store on its .npy file; ``extend`` then appends to that file (the same
    file, its first frames untouched) and the result reads back with ``np.load``. Frames past a store's count (an
    append whose index was never saved) are ignored on opening and written over by the next append."""
    from mocapkit.retrieval.frames import open_frames

    rng = np.random.default_rng(2)
    arrays = clips(rng, 6)
    path = tmp_path / "x_frames.npy"
    store = RaggedFrames.from_list(arrays).save(path)
    assert isinstance(store.data, np.memmap) and store.data.mode == "r+"
    inode, before = path.stat().st_ino, path.read_bytes()
    grown = store.extend(arrays[:4])
    after = path.read_bytes()
    header = len(before) - store.data.nbytes
    assert path.stat().st_ino == inode and after[header : len(before)] == before[header:]  # in place, frames kept
    assert isinstance(grown.data, np.memmap) and len(grown) == 10
    on_disk = np.load(path)
    assert on_disk.shape == (grown.offsets[-1], 5)
    np.testing.assert_array_equal(on_disk, np.concatenate([a.astype(np.float32) for a in arrays + arrays[:4]]))
    # an append interrupted after writing its frames: the 6-clip store does not see them, and appends over them
    reopened = RaggedFrames(open_frames(path, int(store.offsets[-1]), writable=True), store.offsets)
    assert len(reopened.data) == store.offsets[-1]
    again = reopened.extend(arrays[5:])
    np.testing.assert_array_equal(np.load(path), np.concatenate([a.astype(np.float32) for a in arrays + arrays[5:]]))
    np.testing.assert_array_equal(again[6], again[5])
    # a read-only map grows in memory, leaving the file as it is
    frozen = RaggedFrames(open_frames(path), again.offsets)
    assert not isinstance(frozen.extend(arrays[:1]).data, np.memmap) and np.load(path).shape[0] == again.offsets[-1]
    np.save(tmp_path / "bad.npy", np.zeros((3, 5)))  # float64: not frames
    with pytest.raises(ValueError, match=r"bad\.npy: expected float32 frames"):
        open_frames(tmp_path / "bad.npy")
    with pytest.raises(ValueError, match=r"x_frames\.npy: expected float32 frames \[at least 999"):
        open_frames(path, 999)


def test_the_pages_prefetched_for_a_gather_cover_each_clip_of_a_memory_mapped_store(tmp_path):
    """A memory-mapped store's gather first asks the kernel for each clip's pages (``prefetch``): the ranges
    :func:`mapped_pages` gives start on page boundaries of the map and hold the clip's bytes, for a ``.npy`` file
    (frames after its header) and for a map cut short (``open_frames`` with fewer rows than the file); the gather
    returns the same frames as in memory."""
    import mmap

    from mocapkit.retrieval.frames import mapped_pages, open_frames

    rng = np.random.default_rng(4)
    arrays = clips(rng, 40)
    path = tmp_path / "x_frames.npy"
    in_memory = RaggedFrames.from_list(arrays)
    np.save(path, in_memory.data)
    for data in (open_frames(path), open_frames(path, int(in_memory.offsets[30]))):
        store = RaggedFrames(data, in_memory.offsets[: 31 if len(data) < len(in_memory.data) else None])
        picked = rng.permutation(len(store))[:12]
        ranges = mapped_pages(store.data, store.offsets[picked], store.lengths[picked])
        mapped = bytes(store.data._mmap)
        assert len(ranges) == len(picked)
        for (offset, length), clip in zip(ranges, picked):
            assert offset % mmap.PAGESIZE == 0 and offset + length <= len(mapped)
            wanted = np.ascontiguousarray(in_memory.data[store.offsets[clip] : store.offsets[clip + 1]]).tobytes()
            assert mapped[offset : offset + length].endswith(wanted)  # the range ends where the clip's frames end
        np.testing.assert_array_equal(store.subset(picked).data, in_memory.subset(picked).data)
    assert mapped_pages(in_memory.data[:0], np.zeros(0, np.int64), np.zeros(0, np.int64)) == []
