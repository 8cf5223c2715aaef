"""TSR + STPM retrieval (Zhou 2014 ch. 3) and its K-SVD dictionary: the TSR pairs, the pyramid partition, the
sparse kernel against a dense brute force, K-SVD/OMP, the state round trip, short queries, real HDM05."""

from __future__ import annotations

import io
import warnings

import numpy as np
import pytest
from sklearn.linear_model import orthogonal_mp_gram

from mocapkit.motion.container import Motion
from mocapkit.motion.geometry import SkeletonInputError
from mocapkit.motion.layouts import MSR20
from mocapkit.retrieval.ksvd import KSVD, batch_omp, codes_to_dense
from mocapkit.retrieval.tsr_stpm import (
    TSRSTPMRetrieval,
    n_cubes,
    pyramids_from_codes,
    rows_per_clip,
    stpm_cubes,
    stpm_kernel,
    tsr_pairs,
)
from tests.shared_data import SHARED, needs

HDM05 = SHARED / "data" / "hdm05_cuts11"


# --------------------------------------------------------------------------- TSR and the partition
def test_tsr_pairs_follow_the_toy_example():
    i, j = tsr_pairs(7, 2)  # t = 7, σ = 2 → (1,3), (3,5), (5,7) 1-based
    assert list(zip(i + 1, j + 1)) == [(1, 3), (3, 5), (5, 7)]
    i, j = tsr_pairs(8, 2)  # 1 + 3σ = 7 < 8: a 4th slice, partner = last frame
    assert list(zip(i + 1, j + 1)) == [(1, 3), (3, 5), (5, 7), (7, 8)]
    i, j = tsr_pairs(8, 7)  # σ + 1 frames: exactly one slice
    assert list(zip(i, j)) == [(0, 7)]
    assert len(tsr_pairs(1, 3)[0]) == 0
    with pytest.raises(ValueError):
        tsr_pairs(10, 0)


@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_cubes_per_level_tile_the_tsr(level):
    assert n_cubes(level) == 2**level * (level + 1) ** 2 == [1, 8, 36, 128][level]
    n_slices, q = 11, 10  # uneven: 10 atoms in 3 blocks, 11 slices in 4 segments
    cubes = stpm_cubes(n_slices, q, level)
    assert len(cubes) == n_cubes(level)
    cover = np.zeros((n_slices, q, q), dtype=int)
    for t, r, c in cubes:
        cover[t, r, c] += 1
    assert (cover == 1).all()
    sizes = {r.stop - r.start for _, r, _ in cubes}
    assert max(sizes) - min(sizes) <= 1
    # fewer slices than segments: empty segments
    assert sum((t.stop - t.start) == 0 for t, _, _ in stpm_cubes(2, q, 2)) == 2 * 9


# --------------------------------------------------------------------------- sparse kernel vs dense brute force
def _random_codes(rng, n_frames, q, m):
    indices = np.stack([rng.choice(q, m, replace=False) for _ in range(n_frames)])
    coefs = rng.normal(size=(n_frames, m))
    stopped = rng.random(n_frames) < 0.3  # OMP rows that stopped early: zero, repeated slot
    coefs[stopped, -1] = 0.0
    indices[stopped, -1] = indices[stopped, 0]
    return indices, coefs


def _dense_pyramid(indices, coefs, q, sigma, n_levels, block_norm, whole_segments=False):
    X = codes_to_dense(np.where(coefs != 0, indices, 0), coefs, q)
    i, j = tsr_pairs(len(X), sigma)
    S = np.abs(X[i])[:, :, None] * np.abs(X[j])[:, None, :]  # [slices, q, q]
    out = []
    for level in range(n_levels):
        cubes = stpm_cubes(len(S), q, level)
        if whole_segments:  # one q × q cube per temporal segment
            cubes = [(t, slice(0, q), slice(0, q)) for t, r, c in cubes if r.start == 0 and c.start == 0]
        for t, r, c in cubes:
            Z = S[t, r, c].max(axis=0) if t.stop > t.start else np.zeros((r.stop - r.start, c.stop - c.start))
            if block_norm != "none":
                norm = Z.sum() if block_norm == "l1" else np.sqrt((Z**2).sum())
                Z = Z / norm if norm > 0 else Z
            out.append((level, Z))
    return out


def _dense_kernel(pa, pb):
    return sum(2.0**-la * np.minimum(za, zb).sum() for (la, za), (_, zb) in zip(pa, pb))


@pytest.mark.parametrize("block_norm", ["none", "l1", "l2"])
@pytest.mark.parametrize("n_levels", [1, 3, 4])
def test_sparse_kernel_equals_dense_brute_force(block_norm, n_levels):
    rng = np.random.default_rng(n_levels)
    q, m, sigma = 10, 3, 3
    clips = [_random_codes(rng, n, q, m) for n in (30, 4, 17, 9, 41)]  # 4 frames: 1 slice < 2^l segments
    pyr = pyramids_from_codes(clips, q, sigma, n_levels, block_norm)
    assert pyr.n_clips == len(clips) and pyr.matrix.shape == (len(clips) * rows_per_clip(n_levels), q * q)
    K = stpm_kernel(pyr, pyr)
    dense = [_dense_pyramid(i, c, q, sigma, n_levels, block_norm) for i, c in clips]
    expected = np.array([[_dense_kernel(a, b) for b in dense] for a in dense])
    np.testing.assert_allclose(K, expected, rtol=2e-6)
    assert np.allclose(K, K.T, rtol=1e-6)
    # a query batch against a database subset gives the same numbers
    sub = pyramids_from_codes(clips[1:4], q, sigma, n_levels, block_norm)
    np.testing.assert_allclose(stpm_kernel(pyr, sub), expected[:, 1:4], rtol=2e-6)
    # normalised kernel: 1 on the diagonal
    Kn = stpm_kernel(pyr, pyr, normalize=True)
    np.testing.assert_allclose(np.diag(Kn), 1.0, rtol=1e-6)
    np.testing.assert_allclose(Kn, K / np.sqrt(np.outer(np.diag(K), np.diag(K))), rtol=1e-5)


def test_spatial_split_is_a_no_op_without_block_normalisation():
    rng = np.random.default_rng(5)
    q, m, sigma, n_levels = 9, 4, 2, 3
    clips = [_random_codes(rng, n, q, m) for n in (25, 12, 33)]
    cubes = [_dense_pyramid(i, c, q, sigma, n_levels, "none") for i, c in clips]
    whole = [_dense_pyramid(i, c, q, sigma, n_levels, "none", whole_segments=True) for i, c in clips]
    for a in range(3):
        for b in range(3):
            assert np.isclose(_dense_kernel(cubes[a], cubes[b]), _dense_kernel(whole[a], whole[b]))
    K = stpm_kernel(*(2 * [pyramids_from_codes(clips, q, sigma, n_levels, "none")]))
    np.testing.assert_allclose(K, [[_dense_kernel(a, b) for b in whole] for a in whole], rtol=2e-6)
    # with block normalisation the split matters
    l2 = [_dense_pyramid(i, c, q, sigma, n_levels, "l2") for i, c in clips]
    l2_whole = [_dense_pyramid(i, c, q, sigma, n_levels, "l2", whole_segments=True) for i, c in clips]
    assert not np.isclose(_dense_kernel(l2[0], l2[1]), _dense_kernel(l2_whole[0], l2_whole[1]))


# --------------------------------------------------------------------------- K-SVD and OMP
def test_batch_omp_matches_scikit_learn():
    rng = np.random.default_rng(0)
    D = rng.normal(size=(60, 20))
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    Y = rng.normal(size=(200, 20))
    indices, coefs = batch_omp(Y, D, 7)
    assert indices.shape == coefs.shape == (200, 7)
    ref = orthogonal_mp_gram(D @ D.T, D @ Y.T, n_nonzero_coefs=7).T
    np.testing.assert_allclose(codes_to_dense(indices, coefs, 60), ref, atol=1e-10)


def test_ksvd_learns_unit_atoms_and_reduces_the_error():
    # Aharon et al.'s synthetic check: 50 atoms in 20-D, 3 per signal, 1500 signals, 20 dB noise
    rng = np.random.default_rng(1)
    true = rng.normal(size=(50, 20))
    true /= np.linalg.norm(true, axis=1, keepdims=True)
    codes = np.zeros((1500, 50))
    for row in codes:
        row[rng.choice(50, 3, replace=False)] = rng.normal(size=3)
    Y = codes @ true
    Y += rng.normal(size=Y.shape) * np.sqrt(np.mean(Y**2)) * 0.1
    model = KSVD(n_atoms=50, n_nonzero=3, max_iter=20, random_state=0).fit(Y)
    assert model.components_.shape == (50, 20)
    np.testing.assert_allclose(np.linalg.norm(model.components_, axis=1), 1.0, atol=1e-12)
    assert model.error_[-1] < model.error_[0]
    assert all(b <= a + 1e-9 for a, b in zip(model.error_, model.error_[1:]))
    X = model.transform(Y)
    assert X.shape == (1500, 50) and ((X != 0).sum(axis=1) <= 3).all()
    err_final = np.sqrt(np.mean((Y - model.inverse_transform(X)) ** 2))
    init = Y[np.random.default_rng(0).choice(1500, 50, replace=False)]
    init /= np.linalg.norm(init, axis=1, keepdims=True)
    i0, c0 = batch_omp(Y, init, 3)
    err_init = np.sqrt(np.mean((Y - codes_to_dense(i0, c0, 50) @ init) ** 2))
    assert err_final < 0.5 * err_init
    recovered = (np.abs(model.components_ @ true.T).max(axis=0) > 0.99).mean()
    assert recovered >= 0.6, recovered
    # sub-sampled fit, more atoms than the signals need
    small = KSVD(n_atoms=30, n_nonzero=2, max_iter=2, max_samples=100).fit(Y)
    assert small.components_.shape == (30, 20) and small.n_iter_ == 2


# --------------------------------------------------------------------------- the retrieval method
def _motion(kind: int, frames: int = 48, fps: float = 30.0, seed: int = 0, source: str | None = None) -> Motion:
    """An MSR-20 skeleton doing one of three motions (arm swing, squat, kick), a little noise."""
    rng = np.random.default_rng(seed)
    rest = {
        "HipCenter": (0, 1.0, 0),
        "Spine": (0, 1.2, 0),
        "ShoulderCenter": (0, 1.45, 0),
        "Head": (0, 1.65, 0),
        "ShoulderLeft": (0.18, 1.42, 0),
        "ElbowLeft": (0.2, 1.15, 0),
        "WristLeft": (0.2, 0.9, 0),
        "HandLeft": (0.2, 0.82, 0),
        "ShoulderRight": (-0.18, 1.42, 0),
        "ElbowRight": (-0.2, 1.15, 0),
        "WristRight": (-0.2, 0.9, 0),
        "HandRight": (-0.2, 0.82, 0),
        "HipLeft": (0.1, 0.95, 0),
        "KneeLeft": (0.1, 0.52, 0),
        "AnkleLeft": (0.1, 0.1, 0),
        "FootLeft": (0.1, 0.02, 0.12),
        "HipRight": (-0.1, 0.95, 0),
        "KneeRight": (-0.1, 0.52, 0),
        "AnkleRight": (-0.1, 0.1, 0),
        "FootRight": (-0.1, 0.02, 0.12),
    }
    t = np.arange(frames) / fps
    phase = np.sin(2 * np.pi * (0.8 + 0.1 * rng.random()) * t)[:, None]
    P = np.repeat(np.array([rest[n] for n in MSR20.joint_names], dtype=float)[None], frames, axis=0)
    names = list(MSR20.joint_names)
    if kind == 0:  # both arms swing forward
        for n in ("ElbowLeft", "WristLeft", "HandLeft", "ElbowRight", "WristRight", "HandRight"):
            P[:, names.index(n)] += 0.4 * phase * np.array([0, 0.3, 1.0])
    elif kind == 1:  # squat: everything above the knees goes down
        for n in names:
            if not n.startswith(("Knee", "Ankle", "Foot")):
                P[:, names.index(n)] -= 0.3 * np.abs(phase) * np.array([0, 1.0, 0])
    else:  # left kick
        for n in ("KneeLeft", "AnkleLeft", "FootLeft"):
            P[:, names.index(n)] += 0.5 * np.abs(phase) * np.array([0, 0.5, 1.0])
    P += rng.normal(scale=0.005, size=P.shape)
    return Motion(
        P, MSR20.joint_names, fps, parents=MSR20.parents, layout_name="msr20", name=f"k{kind}_{seed}", source=source
    )


SMALL = {"n_atoms": 24, "n_nonzero": 4, "sigma": 2, "ksvd_iter": 3, "fps": 30.0, "max_dictionary_frames": None}


@pytest.fixture(scope="module")
def fitted():
    db = [_motion(k, frames=40 + 7 * s, seed=s) for k in range(3) for s in range(4)]
    labels = np.repeat(np.arange(3), 4)
    return TSRSTPMRetrieval(**SMALL).fit(db), db, labels


def test_method_ranks_synthetic_classes_and_state_round_trips(fitted):
    method, _, labels = fitted
    queries = [_motion(k, frames=50, seed=10 + k) for k in range(3)]
    d = method.distances(queries)
    assert d.shape == (3, 12) and d.dtype == np.float64
    assert (labels[d.argmin(axis=1)] == np.arange(3)).all()
    state = method._state()
    assert all(isinstance(v, np.ndarray) and v.dtype != object for v in state.values())
    buffer = io.BytesIO()
    np.savez(buffer, **state)
    buffer.seek(0)
    with np.load(buffer, allow_pickle=False) as data:
        loaded = {k: data[k] for k in data.files}
    restored = TSRSTPMRetrieval(**method.get_params())
    restored._set_state(loaded)
    assert restored.n_database_ == 12
    np.testing.assert_array_equal(restored.distances(queries), d)
    np.testing.assert_array_equal(restored.ksvd_.components_, method.ksvd_.components_)
    with pytest.raises(ValueError, match="n_levels"):
        TSRSTPMRetrieval(**{**SMALL, "n_levels": 2})._set_state(loaded)


def test_block_norm_and_levels_variants_run(fitted):
    _, db, labels = fitted
    for params in ({"block_norm": "l2", "n_levels": 4}, {"block_norm": "l1", "normalize_kernel": True}):
        other = TSRSTPMRetrieval(**{**SMALL, **params}).fit(db)
        d = other.distances(db)
        assert np.isfinite(d).all() and (labels[np.argsort(d, axis=1)[:, 1]] == labels).mean() >= 0.75
    with pytest.raises(ValueError, match="block_norm"):
        TSRSTPMRetrieval(**{**SMALL, "block_norm": "max"}).fit(db)


def test_short_query_is_refused_naming_the_file(fitted):
    method, _, _ = fitted
    assert TSRSTPMRetrieval.min_frames == 8 and method.min_frames == SMALL["sigma"] + 1
    with pytest.raises(SkeletonInputError, match="tiny_query.bvh"):
        method.distances([_motion(0, frames=SMALL["sigma"], source="tiny_query.bvh")])
    assert method.distances([_motion(0, frames=SMALL["sigma"] + 1)]).shape == (1, 12)
    # σ counts frames at the method's fps: a 10 Hz query of 2 frames is 6 frames at 30 Hz
    assert method.distances([_motion(0, frames=2, fps=10.0)]).shape == (1, 12)


# --------------------------------------------------------------------------- real HDM05
CLASSES = ("squat1Reps", "hopBothLegs1hops", "kickLFront1Reps", "elbowToKnee1RepsLelbowStart", "throwBasketball")


@needs(HDM05)
def test_hdm05_cross_actor_precision_beats_chance():
    from mocapkit.datasets import read_motion
    from mocapkit.datasets.mocap.folders import list_clips

    picked = {}
    for clip in list_clips("hdm05", HDM05):
        key = (clip["group"], clip["class"])
        if clip["class"] in CLASSES and clip["group"] in ("bd", "bk", "mm") and len(picked.get(key, [])) < 3:
            picked.setdefault(key, []).append(clip)
    clips = [c for group in picked.values() for c in group]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        motions = [read_motion(c["path"]) for c in clips]
    labels = np.array([c["class"] for c in clips])
    is_query = np.array([c["group"] == "mm" for c in clips])
    db = [m for m, q in zip(motions, is_query) if not q]
    queries = [m for m, q in zip(motions, is_query) if q]
    method = TSRSTPMRetrieval(n_atoms=48, n_nonzero=6, ksvd_iter=2, max_dictionary_frames=4000, fps=60.0, sigma=4)
    method.fit(db)
    d = method.distances(queries)
    p1 = (labels[~is_query][d.argmin(axis=1)] == labels[is_query]).mean()
    # 5 balanced classes: chance P@1 is 0.2
    assert p1 >= 0.6, p1
