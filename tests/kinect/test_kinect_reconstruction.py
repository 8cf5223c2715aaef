"""Kinect posture reconstruction (Zhou 2014 ch. 5): the GP + temporal + reliability reconstructor and the
random-forest baseline on synthetic paired clips whose "Kinect" corruption is a known pose-dependent offset
(hands and wrists pulled toward the spine by an amount growing with the elbow bend, elbows and knees pushed
forward by their flexion, the head raised) plus 5 mm noise; the reliability cues; the normalisation F and its
inverse; the SGPR objective and predictive against dense formulas; the energy's closed form and its ablations;
input checks and determinism."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from sklearn.base import clone
from sklearn.exceptions import NotFittedError

from mocapkit.kinect import reconstruction as kr
from mocapkit.kinect.metrics import bone_length_sd_cm, jitter_cm, joint_error_cm
from mocapkit.kinect.reconstruction import (
    INFERRED,
    NEIGHBOURS,
    NOT_TRACKED,
    TRACKED,
    KinectPostureReconstructor,
    RandomForestPoseCorrector,
    joint_reliability,
    kinematic_reliability,
    normalise_posture,
)
from mocapkit.motion.geometry import TEMPLATE_BONES, face_forward, retarget
from mocapkit.motion.layouts import LANDMARK_NAMES

HAND_R, WRIST_R, ELBOW_R, HEAD, FOOT_L = (
    LANDMARK_NAMES.index(n) for n in ("r_hand", "r_wrist", "r_elbow", "head", "l_foot")
)


# ------------------------------------------------------------------------------------------------ synthetic data


def _unit(v):
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _turn(p, angle):
    """Turn ``[T, ..., 3]`` about y by ``angle`` ``[T]`` (right-handed)."""
    c = np.cos(angle).reshape((-1,) + (1,) * (p.ndim - 2))
    s = np.sin(angle).reshape(c.shape)
    out = p.copy()
    out[..., 0] = c * p[..., 0] + s * p[..., 2]
    out[..., 2] = -s * p[..., 0] + c * p[..., 2]
    return out


def make_motion(rng, T=120, fps=30.0):
    """A clean 20-joint clip (world, m, y up) of a random-size body swinging its arms and legs while turning and
    walking: ``(positions [T, 20, 3], elbow bends [T, 2], knee bends [T, 2], facing direction [T, 3])``."""
    t = np.arange(T) / fps
    size = rng.uniform(0.9, 1.1)
    L = {k: v * size for k, v in TEMPLATE_BONES.items()}
    w, ph = rng.uniform(2.0, 5.0), rng.uniform(0, 2 * np.pi, 8)
    P = np.zeros((T, 20, 3))
    lean = 0.15 * rng.uniform() * (1 + np.sin(0.5 * w * t + ph[0]))
    spine = np.stack([np.zeros(T), np.cos(lean), np.sin(lean)], -1)
    P[:, 0] = [0, 0.95 * size, 0]
    P[:, 1] = P[:, 0] + spine * L["spine"]
    P[:, 2] = P[:, 1] + spine * L["neck"]
    P[:, 3] = P[:, 2] + spine * L["head"]
    elbows, knees, forward = [], [], np.array([0.0, 0.0, 1.0])
    for k, (side, (sh, el, wr, ha)) in enumerate(((1, (4, 5, 6, 7)), (-1, (8, 9, 10, 11)))):
        P[:, sh] = P[:, 2] + np.array([side, -0.05, 0]) * L["l_shoulder"]
        flex = rng.uniform(0.2, 0.9) * np.sin(w * t + ph[1 + k]) + rng.uniform(-0.2, 0.3)
        abduct = rng.uniform(0.05, 0.5) * (1 + np.sin(0.7 * w * t + ph[3 + k])) / 2
        upper = _unit(
            np.stack([side * np.sin(abduct), -np.cos(abduct) * np.cos(flex), np.cos(abduct) * np.sin(flex)], -1)
        )
        bend = 0.1 + rng.uniform(0.8, 1.9) * (1 + np.sin(1.3 * w * t + ph[5 + k])) / 2
        normal = _unit(forward - (upper @ forward)[:, None] * upper)
        fore = np.cos(bend)[:, None] * upper + np.sin(bend)[:, None] * normal
        P[:, el] = P[:, sh] + upper * L["l_elbow"]
        P[:, wr] = P[:, el] + fore * L["l_wrist"]
        P[:, ha] = P[:, wr] + fore * L["l_hand"]
        elbows.append(bend)
    for k, (side, (hp, kn, an, ft)) in enumerate(((1, (12, 13, 14, 15)), (-1, (16, 17, 18, 19)))):
        P[:, hp] = P[:, 0] + np.array([side, -0.3, 0]) / math.hypot(1, 0.3) * L["l_hip"]
        hip = rng.uniform(0.1, 0.6) * np.sin(0.8 * w * t + ph[7] + np.pi * k)
        knee = rng.uniform(0.1, 1.0) * (1 + np.sin(0.8 * w * t + ph[7] + np.pi * k + 1.0)) / 2
        thigh = np.stack([np.zeros(T), -np.cos(hip), np.sin(hip)], -1)
        shin = np.stack([np.zeros(T), -np.cos(hip - knee), np.sin(hip - knee)], -1)
        P[:, kn] = P[:, hp] + thigh * L["l_knee"]
        P[:, an] = P[:, kn] + shin * L["l_ankle"]
        P[:, ft] = P[:, an] + _unit(np.array([0, -0.3, 1.0])) * L["l_foot"]
        knees.append(knee)
    yaw = rng.uniform(-np.pi, np.pi) + rng.uniform(-0.5, 0.5) * t
    root = P[:, :1].copy()
    P = _turn(P - root, yaw) + root
    P += np.stack([rng.uniform(-1, 1) + 0.2 * t * rng.uniform(-1, 1), np.zeros(T), rng.uniform(1.5, 3) + 0.1 * t], -1)[
        :, None
    ]
    facing = _turn(np.tile(forward, (T, 1, 1)), yaw)[:, 0]
    return P, np.stack(elbows, 1), np.stack(knees, 1), facing


def corrupt(rng, P, elbows, knees, facing, noise=0.005):
    """The known pose-dependent "Kinect" error, plus iid noise."""
    K = P.copy()
    for k, (el, wr, ha) in enumerate(((5, 6, 7), (9, 10, 11))):
        pull = 0.12 * (elbows[:, k] / 2.0) ** 2  # up to 12 cm toward the spine
        K[:, ha] += pull[:, None] * _unit(P[:, 1] - P[:, ha])
        K[:, wr] += 0.6 * pull[:, None] * _unit(P[:, 1] - P[:, wr])
        K[:, el] += 0.03 * np.sin(elbows[:, k])[:, None] * facing
    for k, kn in enumerate((13, 17)):
        K[:, kn] += 0.06 * (knees[:, k] / 1.1)[:, None] * facing
    K[:, HEAD] += [0, 0.03, 0]
    return K + noise * rng.normal(size=K.shape)


def paired_clips(seed, n):
    rng = np.random.default_rng(seed)
    kinect, mocap = [], []
    for _ in range(n):
        P, elbows, knees, facing = make_motion(rng)
        mocap.append(P)
        kinect.append(corrupt(rng, P, elbows, knees, facing))
    return kinect, mocap


def _error(pred, mocap):
    return float(np.mean([joint_error_cm(p, m) for p, m in zip(pred, mocap)]))


SMALL_GP = {"n_inducing": 40, "gp_iterations": 30}


@pytest.fixture(scope="module")
def data():
    return paired_clips(0, 8), paired_clips(1, 3)  # training takes and separate held-out takes


@pytest.fixture(scope="module")
def fitted(data):
    (ktr, mtr), _ = data
    return KinectPostureReconstructor(**SMALL_GP, random_state=0).fit(ktr, mtr)


# --------------------------------------------------------------------------------------------- reconstruction


def test_reconstructor_cuts_the_error_on_held_out_clips(fitted, data):
    _, (kte, mte) = data
    raw = _error(kte, mte)
    rec = fitted.predict(kte)  # a list in, a list out
    assert isinstance(rec, list) and all(r.shape == k.shape for r, k in zip(rec, kte))
    err = _error(rec, mte)
    assert raw > 1.2  # the corruption is substantial
    assert err < 0.6 * raw, (err, raw)
    # the pose-dependent joints are the ones fixed: the right hand's error drops the most
    per_joint_raw = np.mean([joint_error_cm(k, m, per_joint=True) for k, m in zip(kte, mte)], 0)
    per_joint = np.mean([joint_error_cm(r, m, per_joint=True) for r, m in zip(rec, mte)], 0)
    assert per_joint[HAND_R] < 0.5 * per_joint_raw[HAND_R]
    assert per_joint[HEAD] < 0.5 * per_joint_raw[HEAD]
    assert fitted.training_loss_[-1] < fitted.training_loss_[0]
    assert fitted.n_train_frames_ == 8 * 120 and fitted.n_inducing_ == 40
    assert clone(fitted).get_params() == fitted.get_params()


def test_random_forest_baseline_beats_raw_but_not_the_gp(fitted, data):
    (ktr, mtr), (kte, mte) = data
    rf = RandomForestPoseCorrector(n_estimators=30, random_state=0).fit(ktr, mtr)
    raw, rf_err = _error(kte, mte), _error(rf.predict(kte), mte)
    assert rf_err < 0.85 * raw, (rf_err, raw)
    assert _error(fitted.predict(kte), mte) < rf_err  # the thesis's ordering, on this set
    again = RandomForestPoseCorrector(n_estimators=30, random_state=0).fit(ktr, mtr)
    np.testing.assert_array_equal(rf.predict(kte[0]), again.predict(kte[0]))


def test_only_reliability_returns_the_input_and_only_temporal_extrapolates(fitted, data):
    _, (kte, _) = data
    x = kte[0]
    est = copy.deepcopy(fitted)  # keep the fixture's weights
    est.set_params(w_spatial=0.0, w_temporal=0.0, w_reliability=0.2)
    np.testing.assert_array_equal(est.predict(x), x)
    state = np.full(x.shape[:2], TRACKED)
    state[:, HAND_R] = NOT_TRACKED  # r = 0: flat energy, the input is kept
    np.testing.assert_array_equal(est.predict(x, state), x)
    est.set_params(w_temporal=0.2, w_reliability=0.0)
    out = est.predict(x)
    np.testing.assert_array_equal(out[:2], x[:2])
    t = np.arange(len(x))[:, None, None]
    np.testing.assert_allclose(out, x[0] + t * (x[1] - x[0]), atol=1e-9)  # constant-velocity drift


def test_spatial_term_alone_is_the_gp_mean_and_every_ablation_runs(fitted, data):
    _, (kte, mte) = data
    x, m = kte[0], mte[0]
    est = copy.deepcopy(fitted)  # keep the fixture's weights
    mu, var = est.predict_offsets(x)
    assert mu.shape == x.shape and var.shape == x.shape[:2] and (var > 0).all()
    est.set_params(w_spatial=0.6, w_temporal=0.0, w_reliability=0.0)
    np.testing.assert_allclose(est.predict(x), x + mu, atol=1e-12)
    raw = joint_error_cm(x, m)
    errors = {}
    for ws, wt, wr in [
        (0.6, 0, 0),
        (0, 0.2, 0),
        (0, 0, 0.2),
        (0.6, 0.2, 0),
        (0.6, 0, 0.2),
        (0, 0.2, 0.2),
        (0.6, 0.2, 0.2),
    ]:
        out = est.set_params(w_spatial=ws, w_temporal=wt, w_reliability=wr).predict(x)
        assert out.shape == x.shape and np.isfinite(out).all()
        errors[(ws, wt, wr)] = joint_error_cm(out, m)
    assert errors[(0, 0, 0.2)] == pytest.approx(raw)  # Table 5.3 (b): raw Kinect
    assert errors[(0, 0.2, 0)] > raw  # (a): extrapolation drifts
    for key, err in errors.items():
        if key[0] > 0:
            assert err < 0.7 * raw, (key, err, raw)
    # a not-tracked joint (r = 0) under S + R is pure GP correction; a tracked one is pulled toward the input
    state = np.full(x.shape[:2], TRACKED)
    state[:, HAND_R] = NOT_TRACKED
    out = est.set_params(w_spatial=0.6, w_temporal=0.0, w_reliability=0.2).predict(x, state)
    np.testing.assert_allclose(out[:, HAND_R], x[:, HAND_R] + mu[:, HAND_R], atol=1e-12)
    shrink = np.linalg.norm(out[:, HEAD] - x[:, HEAD], axis=-1) / np.linalg.norm(mu[:, HEAD], axis=-1)
    assert (shrink < 1).all() and (shrink > 0).all()


def test_each_frame_minimises_the_energy(fitted, data):
    """The closed form against the energy itself (in the energy's cm unit), at random perturbations."""
    _, (kte, _) = data
    x = kte[1]
    est = copy.deepcopy(fitted)  # keep the fixture's weights
    est.set_params(w_spatial=0.6, w_temporal=0.2, w_reliability=0.2)
    out = est.predict(x)
    mu, var = est.predict_offsets(x)
    r = est.reliability_of(x)
    u = est.energy_unit
    rng = np.random.default_rng(0)
    for t in (0, 1, 5, 60, len(x) - 1):
        c = 2 * out[t - 1] - out[t - 2] - x[t] if t >= 2 else None

        def energy(y, t=t, c=c):
            e = 0.6 * ((y - mu[t]) ** 2).sum(-1) / (2 * var[t]) + 0.2 * r[t] ** 2 * (y**2).sum(-1) / u**2
            if c is not None:
                e = e + 0.2 * ((y - c) ** 2).sum(-1) / u**2
            return e

        best = energy(out[t] - x[t])
        for _ in range(5):
            assert (energy(out[t] - x[t] + 0.002 * rng.normal(size=(20, 3))) > best).all()


def test_sgpr_objective_and_predictive_match_dense_formulas():
    rng = np.random.default_rng(0)
    J, N, M, D = 20, 25, 6, kr._MAX_INPUT_DIM
    mask = kr._input_mask()
    X = rng.normal(size=(J, N, D)) * mask[:, None]
    Y = rng.normal(size=(J, N, 3))
    Z = X[:, :M].copy()
    params, history = kr._train_sgpr(X, Y, mask, Z, 1, 0.05, "cpu")
    # the starting hyper-parameters of the one step's loss
    upper = np.triu_indices(N, 1)
    ls0 = np.array([np.median(d[upper]) for d in np.linalg.norm(X[:, :, None] - X[:, None], axis=-1)])
    os0, c0, s2 = np.ones(J), np.full(J, 0.1), np.full(J, 0.1)
    total = 0.0
    for j in range(J):

        def k(a, b, j=j):
            return kr._rbf_bias(a[None], b[None], ls0[j : j + 1], os0[j : j + 1], c0[j : j + 1])[0]

        Kzz, Kxz = k(Z[j], Z[j]), k(X[j], Z[j])
        Q = Kxz @ np.linalg.solve(Kzz, Kxz.T)
        C = Q + s2[j] * np.eye(N)
        _, logdet = np.linalg.slogdet(C)
        quad = np.einsum("nk,nk->", Y[j], np.linalg.solve(C, Y[j]))
        bound = (
            -0.5 * (quad + 3 * logdet + 3 * N * math.log(2 * math.pi))
            - 3 * 0.5 * (np.trace(k(X[j], X[j])) - np.trace(Q)) / s2[j]
        )
        total -= bound / (3 * N)
    assert history[0] == pytest.approx(total, rel=1e-6)
    # predictive (DTC / SGPR): mean = K*z (σ²Kzz + KzxKxz)⁻¹ Kzx y, var = k** − Q** + σ² K*z(...)⁻¹Kz* + σ²
    W, V = kr._sgpr_predictive(X, Y, params)
    gp = kr.JointSGPRs(weights=W, var_matrix=V, y_mean=np.zeros((J, 3)), y_scale=np.ones(J), **params)
    Xs = rng.normal(size=(J, 7, D)) * mask[:, None]
    mean, var = gp.predict(Xs)
    for j in (0, 2, 11):
        p = {k: params[k][j : j + 1] for k in ("lengthscale", "outputscale", "constant")}

        def k(a, b, p=p):
            return kr._rbf_bias(a[None], b[None], p["lengthscale"], p["outputscale"], p["constant"])[0]

        Zj, noise = params["inducing"][j], params["noise"][j]
        Kzz = k(Zj, Zj) + 1e-6 * (p["outputscale"][0] + p["constant"][0]) * np.eye(M)
        Kxz, Ksz = k(X[j], Zj), k(Xs[j], Zj)
        A = noise * Kzz + Kxz.T @ Kxz
        np.testing.assert_allclose(mean[:, j], Ksz @ np.linalg.solve(A, Kxz.T @ Y[j]), atol=1e-8)
        dense_var = (
            np.diag(k(Xs[j], Xs[j]))
            - np.einsum("nm,nm->n", Ksz, np.linalg.solve(Kzz, Ksz.T).T)
            + noise * np.einsum("nm,nm->n", Ksz, np.linalg.solve(A, Ksz.T).T)
            + noise
        )
        np.testing.assert_allclose(var[:, j], dense_var, rtol=1e-6)
    assert (params["inducing"] * (1 - mask[:, None]) == 0).all()  # padded input dimensions stay 0


def test_same_random_state_same_model(data):
    (ktr, mtr), (kte, _) = data
    kwargs = {"n_inducing": 10, "gp_iterations": 5, "max_train_frames": 200, "random_state": 3}
    a = KinectPostureReconstructor(**kwargs).fit(ktr[:3], mtr[:3])
    b = KinectPostureReconstructor(**kwargs).fit(ktr[:3], mtr[:3])
    np.testing.assert_array_equal(a.predict(kte[0]), b.predict(kte[0]))
    assert a.n_train_frames_ == 200 and a.training_loss_ == b.training_loss_
    c = KinectPostureReconstructor(**{**kwargs, "random_state": 4}).fit(ktr[:3], mtr[:3])
    assert not np.array_equal(a.gp_.inducing, c.gp_.inducing)  # another frame subset


# ---------------------------------------------------------------------------------------------------- reliability


def _rigid_walk(T=40):
    """A fixed pose carried at constant velocity: reliability exactly 1."""
    P, *_ = make_motion(np.random.default_rng(5), T=1)
    return P[0] + np.arange(T)[:, None, None] * np.array([0.02, 0.0, 0.01])


def test_reliability_is_one_on_clean_smooth_clips():
    np.testing.assert_allclose(joint_reliability(_rigid_walk()), 1.0, atol=1e-12)
    for seed in range(4):
        P, *_ = make_motion(np.random.default_rng(seed))
        np.testing.assert_allclose(kinematic_reliability(P), 1.0, atol=1e-9)
        r = joint_reliability(P)
        assert r.min() > 0.95 and r.mean() > 0.999


def test_reliability_drops_for_jumps_stretched_bones_and_inferred_joints():
    P, *_ = make_motion(np.random.default_rng(2))
    jump = P.copy()
    jump[50, HAND_R] += [0.4, 0.0, 0.0]  # a one-frame glitch of 40 cm
    r = joint_reliability(jump)
    assert r[50, HAND_R] < 0.3 and r[51, HAND_R] < 0.3  # in and back out
    assert r[50, FOOT_L] == pytest.approx(1.0)
    assert joint_reliability(jump, combine="min")[50, HAND_R] >= r[50, HAND_R]

    stretch = P.copy()
    forearm = stretch[40:60, WRIST_R] - stretch[40:60, ELBOW_R]
    stretch[40:60, [WRIST_R, HAND_R]] += 0.3 * forearm[:, None]  # forearm 30 % too long, hand bone intact
    r = kinematic_reliability(stretch)
    expected = math.exp(-5.0 * 0.3 / 2)  # mean of (0.3, 0) over the two bones
    np.testing.assert_allclose(r[45:56, [WRIST_R, ELBOW_R]], expected, rtol=1e-6)
    np.testing.assert_allclose(r[45:56, HAND_R], 1.0, atol=1e-9)
    np.testing.assert_allclose(np.delete(r[45:56], [WRIST_R, ELBOW_R], axis=1), 1.0, atol=1e-9)

    state = np.full(P.shape[:2], TRACKED)
    state[:, HEAD] = INFERRED
    state[10:20, HAND_R] = NOT_TRACKED
    clean = joint_reliability(_rigid_walk(len(P)), state)
    assert (clean[:, HEAD] == 0.5).all() and (clean[10:20, HAND_R] == 0).all() and clean[:10, HAND_R].min() == 1


# ---------------------------------------------------------------------------------------------------- normalisation


def test_normalisation_removes_position_heading_and_size_and_inverts():
    P, *_ = make_motion(np.random.default_rng(7))
    norm, tf = normalise_posture(P)
    # the retrieval module's F on the same data (retarget, pelvis to origin, per-frame heading)
    np.testing.assert_allclose(norm, face_forward(retarget(P - P[:, :1]), "frame"), atol=1e-12)
    np.testing.assert_allclose(norm[:, 0], 0.0, atol=1e-12)
    hips = norm[:, 16] - norm[:, 12]
    assert (hips[:, 0] < 0).all() and np.abs(hips[:, 2]).max() < 1e-12  # hip line along −x: facing +z
    rng = np.random.default_rng(1)
    turn = rng.uniform(-np.pi, np.pi, len(P))  # a different heading in every frame
    moved = _turn(P, turn) * 1.2 + rng.normal(size=(len(P), 1, 3))
    norm2, tf2 = normalise_posture(moved)
    np.testing.assert_allclose(norm2, norm, atol=1e-9)
    assert tf2.scale == pytest.approx(1.2 * tf.scale)
    bones = np.median(
        np.linalg.norm(P[:, 1:] - P[:, [0, 1, 2, 2, 4, 5, 6, 2, 8, 9, 10, 0, 12, 13, 14, 0, 16, 17, 18]], axis=-1),
        axis=0,
    )
    assert tf.scale == pytest.approx(bones.sum() / sum(TEMPLATE_BONES.values()))
    np.testing.assert_allclose(tf.to_world(norm), P, atol=1e-9)  # exact inverse of F
    np.testing.assert_allclose(tf2.to_world(norm2), moved, atol=1e-9)
    offsets = rng.normal(size=P.shape)
    np.testing.assert_allclose(tf2.offsets_to_world(tf2.offsets_to_normalised(offsets)), offsets, atol=1e-12)
    # an offset that turns and scales with the body is one offset in the normalised frame
    np.testing.assert_allclose(
        tf2.offsets_to_normalised(_turn(offsets, turn) * 1.2), tf.offsets_to_normalised(offsets), atol=1e-12
    )
    assert tf2.variance_to_world(np.ones(3)) == pytest.approx(np.full(3, tf2.scale**2))


def test_neighbours_follow_the_kinect_tree():
    assert NEIGHBOURS[HAND_R] == (WRIST_R,)
    assert NEIGHBOURS[0] == (1, 12, 16)  # hip centre: spine, hips
    assert NEIGHBOURS[WRIST_R] == (ELBOW_R, HAND_R)
    assert NEIGHBOURS[2] == (1, 3, 4, 8)


def test_joint_error_cm():
    a = np.zeros((4, 20, 3))
    b = a.copy()
    b[..., 0] = 0.03
    assert joint_error_cm(a, b) == pytest.approx(3.0)
    b[:, 5, 1] = 0.04  # joint 5: 5 cm
    np.testing.assert_allclose(joint_error_cm(a, b, per_joint=True)[[4, 5]], [3.0, 5.0])
    with pytest.raises(ValueError):
        joint_error_cm(a, b[:2])


def test_bone_length_sd_and_jitter_cm():
    rng = np.random.default_rng(0)
    pose = rng.normal(size=(20, 3))
    pose[3] = pose[2] + [0.0, 0.2, 0.0]  # the head bone (ShoulderCenter → Head) points up
    t = np.arange(30.0)[:, None, None]
    moving = pose + 0.01 * t * np.array([1.0, 0.0, 0.0])  # rigid, constant velocity 1 cm/frame
    assert bone_length_sd_cm(moving) == pytest.approx(0.0, abs=1e-9)
    assert jitter_cm(moving) == pytest.approx(0.0, abs=1e-9)
    stretched = moving.copy()
    stretched[::2, 3, 1] += 0.02  # the head bone alternates between +0 and +2 cm
    assert bone_length_sd_cm(stretched) == pytest.approx(1.0 / 19)  # 1 cm sd on one of 19 bones
    assert jitter_cm(stretched) == pytest.approx(100 * 0.04 / 20, rel=0.05)  # |Δ²| = 4 cm on 1 of 20 joints


# ------------------------------------------------------------------------------------------------- the contract


def test_not_fitted_errors():
    x = np.zeros((3, 20, 3))
    with pytest.raises(NotFittedError):
        KinectPostureReconstructor().predict(x)
    with pytest.raises(NotFittedError):
        KinectPostureReconstructor().predict_offsets(x)
    with pytest.raises(NotFittedError):
        RandomForestPoseCorrector().predict(x)


@pytest.mark.parametrize("estimator", [KinectPostureReconstructor(**SMALL_GP), RandomForestPoseCorrector()])
def test_bad_inputs_name_the_clip(estimator, data):
    (ktr, mtr), _ = data
    k, m = [c[:20] for c in ktr[:3]], [c[:20] for c in mtr[:3]]
    with pytest.raises(ValueError, match=r"kinect_clips\[1\].*\[T, 20, 3\]"):
        estimator.fit([k[0], k[1][:, :19], k[2]], m)
    nan = m[2].copy()
    nan[7, 4, 1] = np.nan
    with pytest.raises(ValueError, match=r"mocap_clips\[2\].*frame 7, joint 4"):
        estimator.fit(k, [m[0], m[1], nan])
    with pytest.raises(ValueError, match=r"clip 1: kinect_clips\[1\] has 20 frames but mocap_clips\[1\] has 19"):
        estimator.fit(k, [m[0], m[1][:19], m[2]])
    with pytest.raises(ValueError, match="3 kinect clips but 2 mocap clips"):
        estimator.fit(k, m[:2])
    with pytest.raises(ValueError, match=r"states\[0\]"):
        estimator.fit(k, m, states=[np.full((20, 20), 5), None, None])
    with pytest.raises(ValueError, match="no clips"):
        estimator.fit([], [])


def test_rigid_bones_keep_each_bone_at_its_median_length_and_direction(fitted, data):
    from mocapkit.kinect.reconstruction import bone_lengths
    from mocapkit.motion.layouts import LANDMARK_PARENTS

    _, (kte, _) = data
    est = copy.deepcopy(fitted)
    loose = est.set_params(rigid_bones=False).predict(kte[0])
    rigid = est.set_params(rigid_bones=True).predict(kte[0])
    assert bone_lengths(loose)[:, 1:].std(axis=0).mean() > 1e-3  # the per-joint energy wobbles
    np.testing.assert_allclose(
        bone_lengths(rigid), np.broadcast_to(np.median(bone_lengths(loose), axis=0), rigid.shape[:2]), atol=1e-9
    )
    np.testing.assert_array_equal(rigid[:, 0], loose[:, 0])  # HipCenter stays
    for j in range(1, 20):
        a = loose[:, j] - loose[:, LANDMARK_PARENTS[j]]
        b = rigid[:, j] - rigid[:, LANDMARK_PARENTS[j]]
        cos = (a * b).sum(-1) / np.linalg.norm(a, axis=-1) / np.linalg.norm(b, axis=-1)
        assert (cos > 1 - 1e-9).all()
    with pytest.raises(ValueError, match="rigid_bones"):
        est.set_params(rigid_bones="yes").predict(kte[0])


def test_bad_parameters_and_predict_inputs(fitted, data):
    (ktr, mtr), (kte, _) = data
    for bad in (
        {"w_spatial": -0.1},
        {"w_spatial": 0, "w_temporal": 0, "w_reliability": 0},
        {"reliability": "max"},
        {"n_inducing": 0},
        {"energy_unit": 0.0},
        {"gp_iterations": 1.5},
    ):
        with pytest.raises(ValueError):
            KinectPostureReconstructor(**{**SMALL_GP, **bad}).fit(ktr[:1], mtr[:1])
    x = kte[0].copy()
    x[3, 7, 0] = np.inf
    with pytest.raises(ValueError, match=r"kinect: .*frame 3, joint 7"):
        fitted.predict(x)
    with pytest.raises(ValueError, match=r"kinect\[1\]"):
        fitted.predict([kte[0], x])
    with pytest.raises(ValueError, match="tracking-state"):
        fitted.predict(kte[0], state=np.ones((5, 20)))
    with pytest.raises(ValueError, match="reliability"):
        fitted.predict(kte[0], reliability=np.full((len(kte[0]), 20), 1.5))


def test_whole_posture_gp_input_sees_every_joint():
    rng = np.random.default_rng(0)
    postures = rng.normal(size=(7, 20, 3))
    inputs, mask = kr._gp_inputs(postures, "posture"), kr._input_mask("posture")
    assert inputs.shape == (20, 7, 60) and mask.all()
    np.testing.assert_array_equal(inputs[5], postures.reshape(7, 60))
    neighbours = kr._gp_inputs(postures, "neighbours")
    assert neighbours.shape == (20, 7, 15)
    np.testing.assert_array_equal(neighbours[3, :, :6], postures[:, [3, 2]].reshape(7, 6))  # head: itself, neck
    with pytest.raises(ValueError, match="gp_input"):
        KinectPostureReconstructor(gp_input="arms").fit([postures], [postures])
