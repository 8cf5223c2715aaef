"""PSC: poselet-based masked dictionary learning with LLC coding for missing-marker recovery (Wang 2017, ch. 3).

Zhao Wang, *Motion Capture Data Processing, Retrieval and Recognition*, PhD thesis, Bournemouth University
2017, chapter 3 (also Wang et al., CASA 2016). The pipeline, per thesis section:

1. **Local coordinates** (§3.2): every frame is translated so that the root joint is the origin and rotated
   so that the plane through the two hip joints and the upper neck is parallel to the XY plane (x along the
   hips, z its normal). Frames whose reference joints are missing take the reference frame interpolated from
   their neighbours. Undone after recovery.
2. **Poselets** (§3.2): five overlapping body parts, torso, left/right arm, left/right leg (Fig. 3.1, whose
   joint lists are only in the figure; :data:`CMU_POSELETS` defines them on the CMU/HDM05 31-joint skeleton,
   adjacent joints shared as the thesis describes).
3. **Grouping** (§3.2): windows of ``M`` consecutive frames, stride 1 (``N = S − M + 1`` windows; the
   thesis's index formula describes non-overlapping blocks, a misprint), each stacked into one column
   ``Y_j ∈ R^{M·d_i}`` (frame-major); masks the same way.
4. **Masked dictionary learning** (eqs. 3.9–3.12): for each poselet a dictionary ``D ∈ R^{M·d_i × K}``,
   ``‖D_m‖₂ ≤ 1``, learnt so that the code computed from the **observed** part of a training window
   reconstructs its **missing** part. Every training window is paired with a synthetic marker-level
   missing mask (the thesis's augmentation, ``N_Ω = 1`` here: 1…⌈J/2⌉ of the poselet's joints over a
   random span of the window); initial atoms are random training windows; then alternately

   * codes: the approximated LLC code (below) of each window from its observed rows, the coder used at
     recovery (the thesis codes with the ℓ1 problem 3.11 in training but recovers with LLC 3.15; using one
     coder for both learns the dictionary for the coder that uses it, and is O(K + k²) per window instead of
     a masked lasso per window);
   * dictionary (eq. 3.10): ``min_D ½‖Ω ∘ (Y − D W)‖²_F`` over the missing entries ``Ω``, by majorised
     (diagonally scaled) gradient steps, which decrease 3.10 monotonically for k-sparse codes, then
     projection onto ``‖D_m‖₂ ≤ 1``. Atoms no code uses are re-drawn from the training windows;
   * stopping rule 3.12, here when either of its two ratios (relative missing-part error, relative change
     of the missing-part reconstruction) is ≤ ``tol``, or after ``max_iter`` iterations (thesis: about 30).
     On real data the error ratio stays far above 1e-4, so the change ratio or ``max_iter`` decides.

   Windows are scaled per poselet by the largest training window norm so that the atom-norm constraint
   and the affine (sum-to-one) LLC codes are compatible: every training window lies in the unit ball.
5. **Recovery** (Algorithm 1, eqs. 3.13–3.17): trust-data detection, then for each window with an
   unobserved entry the LLC code from its observed rows, ``Ŷ = D W``, averaged over overlapping windows
   and poselets, only unobserved or flagged entries replaced, back to world coordinates.

**LLC** (Wang, Yang, Yu, Lv, Huang & Gong, CVPR 2010, approximated version; thesis eqs. 3.15–3.17): the
``k`` atoms nearest to the window on its observed rows, then
``w = (C + λ·(tr C / k)·diag(g)) \\ 1``, ``w ← w / 1ᵀw``, with ``C = (D̃ − ỹ1ᵀ)ᵀ(D̃ − ỹ1ᵀ)`` on the
observed rows and the locality adaptor ``g = exp(dist/σ)`` normalised to (0, 1] over the ``k`` neighbours
(σ = their mean distance). λ is relative to ``tr C / k``, so it does not depend on the data's scale.

**Trust-data detection (TDD)**: the thesis uses Feng et al. 2014's B-spline detector with φ = 6 cm and
gives no details. Here every coordinate track is fitted with a cubic smoothing spline
(``scipy.interpolate.make_smoothing_spline``, penalty chosen for a ``tdd_cutoff_hz`` low-pass in seconds),
an observed marker whose 3-D distance to the fit exceeds φ is flagged, the fit is repeated without the
flagged samples (``tdd_passes`` times). Flagged observed markers are treated as missing and returned in
``repaired``. Known failure (thesis §3.5): very sudden motions (kicks).

Cost: ``fit`` is ``O(max_iter · windows · (K + k²) · M·d_i)`` per poselet (about 2.5 minutes on one core
with the defaults, three HDM05 performers); ``refine`` codes only the windows that contain an unobserved
entry, ``O((K + k²) · M·d_i)`` each, plus the TDD spline fits, ``O(T)`` per marker track.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import scipy.sparse as sp
import torch
from scipy.interpolate import make_smoothing_spline

from mocapkit.motion.container import Motion, all_coordinates
from mocapkit.refinement.base import MotionRefiner, RefinementError
from mocapkit.refinement.gap_filling import linear_fill

#: Wang 2017 Fig. 3.1 on the CMU / HDM05 31-joint ASF skeleton (the joint lists exist only in the figure):
#: torso, arms, legs;
#: the thorax is shared by torso and arms, the hip joints by torso and legs.
CMU_POSELETS: dict[str, tuple[str, ...]] = {
    "TO": (
        "root",
        "lhipjoint",
        "rhipjoint",
        "lowerback",
        "upperback",
        "thorax",
        "lowerneck",
        "upperneck",
        "head",
        "lclavicle",
        "rclavicle",
    ),
    "LA": ("thorax", "lclavicle", "lhumerus", "lradius", "lwrist", "lhand", "lfingers", "lthumb"),
    "RA": ("thorax", "rclavicle", "rhumerus", "rradius", "rwrist", "rhand", "rfingers", "rthumb"),
    "LL": ("lhipjoint", "lfemur", "ltibia", "lfoot", "ltoes"),
    "RL": ("rhipjoint", "rfemur", "rtibia", "rfoot", "rtoes"),
}
#: Joints defining the local frame (thesis §3.2: CMU markers 1, 2, 7, 14 = root, the two hip joints and
#: the upper neck; in the 31-joint ASF order markers 2 and 7 are lhipjoint and rhipjoint, the hip centres,
#: whereas the joints *named* lfemur/rfemur are the knees).
CMU_REFERENCE = ("root", "lhipjoint", "rhipjoint", "upperneck")


class PSCRefiner(MotionRefiner):
    """Poselet sparse coding (masked dictionary + LLC) for missing markers (Wang 2017, ch. 3).

    Parameters:
        window: frames per group ``M``. Default 10 (thesis §3.5, chosen there from {8, 10, 16, 24}).
        dilation: frames between the ``M`` frames of a group. Default 1 (thesis: consecutive frames).
        n_atoms: atoms per poselet dictionary ``K``. Default 512 (thesis: 1024; here K ∈ {256, 512, 1024}
            gave the same gap-filling RMSE within 0.2 cm, and the fit cost grows with K).
        n_neighbors: ``k`` of the approximated LLC. Default 20 (Wang et al. 2010 use 5; measured k = 10, 20,
            40: 2.5, 2.0, 2.1 cm, see below).
        llc_lambda: locality weight λ, relative to ``tr C / k``. Default 1e-3 (tuned over the thesis's grid
            {1e-3, 1e-2, 1e-1, 1}: smaller is better here, 1e-2 costs +0.2 cm; the thesis's λ = 10 is in
            its own, unnormalised scale).
        max_iter: dictionary-learning iterations. Default 20 (thesis: "converges in about 30"; the missing-
            part error is still falling slowly at 30, by under 1 % per iteration after 15).
        tol: ε of the stopping rule 3.12. Default 1e-4.
        dictionary_steps: majorised gradient steps on D per iteration. Default 3.
        max_train_windows: training windows per poselet, a seeded random subset. Default 10000. This,
            ``n_atoms``, ``n_neighbors`` and ``max_iter`` set the fit cost
            ``O(max_iter · windows · (K + k²) · M·d_i)``.
        poselets: ``{name: joint names}``; None = :data:`CMU_POSELETS` if the layout has those joints,
            else one poselet of all joints.
        reference_joints: (root, left hip, right hip, neck) of the local frame; None =
            :data:`CMU_REFERENCE` if the layout has them, else translation only (origin = the first joint);
            ``()`` forces translation only.
        tdd_threshold: φ of the trust-data detection in metres (default 0.06, thesis eq. 3.13); None
            turns detection off (only ``motion.missing`` is filled).
        tdd_cutoff_hz: low-pass cutoff of the TDD smoothing spline. Default 6 Hz (my choice; on 34 clean
            HDM05 clips, 182,094 marker entries, 3 / 6 / 10 Hz flag 1027 / 9 / 4 entries, and all 1,819
            injected 10–30 cm spikes at each).
        tdd_passes: fits of the TDD spline (each without the samples flagged before). Default 2.
        random_state: seed of the window subset, the masks and the initial atoms.

    Measured (trained on HDM05 bd + bk, 10 000 windows, 15 iterations; ``continuous_missing`` 30-frame gaps
    in 11 clips of mm): RMSE 2.0 cm against 2.8 cm for linear interpolation.

    Attributes (after ``fit``): ``dictionaries_`` {poselet: float64 [M·3·joints, K]} (frame-major
    windows in local coordinates divided by ``scales_[poselet]``, metres), ``poselets_`` {poselet: joint
    indices}, ``reference_`` (indices or None), ``history_`` {poselet: [(missing-part error, change)] per
    iteration, the two ratios of eq. 3.12}, ``fps_``, ``up_axis_``, ``joint_names_``.
    """

    requires_fit = True
    fixed_sampling = True

    def __init__(
        self,
        window: int = 10,
        dilation: int = 1,
        n_atoms: int = 512,
        n_neighbors: int = 20,
        llc_lambda: float = 1e-3,
        max_iter: int = 20,
        tol: float = 1e-4,
        dictionary_steps: int = 3,
        max_train_windows: int = 10000,
        poselets: dict[str, Sequence[str]] | None = None,
        reference_joints: Sequence[str] | None = None,
        tdd_threshold: float | None = 0.06,
        tdd_cutoff_hz: float = 6.0,
        tdd_passes: int = 2,
        random_state: int | None = 0,
    ):
        self.window = window
        self.dilation = dilation
        self.n_atoms = n_atoms
        self.n_neighbors = n_neighbors
        self.llc_lambda = llc_lambda
        self.max_iter = max_iter
        self.tol = tol
        self.dictionary_steps = dictionary_steps
        self.max_train_windows = max_train_windows
        self.poselets = poselets
        self.reference_joints = reference_joints
        self.tdd_threshold = tdd_threshold
        self.tdd_cutoff_hz = tdd_cutoff_hz
        self.tdd_passes = tdd_passes
        self.random_state = random_state

    # ------------------------------------------------------------------ layout

    def fit(self, motions: Sequence[Motion] | None = None, y=None) -> PSCRefiner:
        """Learn one masked dictionary per poselet from clean ``motions`` (one layout, frame rate, up axis)."""
        motions = list(motions or [])
        if motions:
            self._resolve_layout(motions[0].joint_names)
        return super().fit(motions, y)

    def _resolve_layout(self, names: Sequence[str]) -> None:
        names = tuple(names)

        def indices(joints: Sequence[str], what: str) -> list[int]:
            absent = [j for j in joints if j not in names]
            if absent:
                raise RefinementError(
                    f"{type(self).__name__}: {what} joints {absent} are not in the training "
                    f"layout ({len(names)} joints: {list(names[:6])}...)"
                )
            return [names.index(j) for j in joints]

        if self.poselets is not None:
            poselets = {k: indices(v, f"poselet {k!r}") for k, v in self.poselets.items()}
        elif all(j in names for p in CMU_POSELETS.values() for j in p):
            poselets = {k: indices(v, "poselet") for k, v in CMU_POSELETS.items()}
        else:
            poselets = {"body": list(range(len(names)))}
        covered = sorted({j for p in poselets.values() for j in p})
        if len(covered) != len(names):
            missing = [names[j] for j in range(len(names)) if j not in covered]
            raise RefinementError(f"{type(self).__name__}: joints {missing} belong to no poselet")
        if self.reference_joints is not None:
            ref = indices(self.reference_joints, "reference") if len(self.reference_joints) else None
            if ref is not None and len(ref) != 4:
                raise ValueError("reference_joints must be (root, left hip, right hip, neck) or ()")
        elif all(j in names for j in CMU_REFERENCE):
            ref = indices(CMU_REFERENCE, "reference")
        else:
            ref = None
        self.poselets_, self.reference_ = poselets, ref

    # ------------------------------------------------------------------ local coordinates

    def _local_frames(self, P: np.ndarray, obs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-frame origin ``o`` [T, 3] and rotation ``R`` [T, 3, 3] (rows: the local axes in world coordinates).

        ``o`` is the root joint (the first joint when there is no reference); ``R`` turns the hip line onto x and
        the normal of the hips–neck plane onto z (identity without a reference). Where a reference joint is
        missing, the origin and the two axis vectors are interpolated over time (held at the ends); a root
        never observed is replaced by the centroid of the observed joints.
        """
        T = P.shape[0]
        r = self.reference_[0] if self.reference_ is not None else 0
        o_obs = np.repeat(obs[:, [r]], 3, 1)
        origin = P[:, r]
        if not o_obs.any():
            cnt = obs.sum(1)
            origin = np.where(obs[..., None], P, 0).sum(1) / np.maximum(cnt, 1)[:, None]
            o_obs = np.repeat(cnt[:, None] > 0, 3, 1)
        origin = np.nan_to_num(linear_fill(np.where(o_obs, origin, 0), o_obs))
        identity = np.broadcast_to(np.eye(3), (T, 3, 3)).copy()
        if self.reference_ is None:
            return origin, identity
        _, lh, rh, nk = self.reference_
        both, plane = obs[:, lh] & obs[:, rh], obs[:, lh] & obs[:, rh] & obs[:, nk]
        if not plane.any():
            return origin, identity
        across = linear_fill(np.where(both[:, None], P[:, rh] - P[:, lh], 0), np.repeat(both[:, None], 3, 1))
        upv = linear_fill(
            np.where(plane[:, None], P[:, nk] - 0.5 * (P[:, lh] + P[:, rh]), 0), np.repeat(plane[:, None], 3, 1)
        )
        x = across / np.linalg.norm(across, axis=1, keepdims=True).clip(1e-9)
        zax = np.cross(x, upv)
        zax /= np.linalg.norm(zax, axis=1, keepdims=True).clip(1e-9)
        return origin, np.stack([x, np.cross(zax, x), zax], axis=1)

    # ------------------------------------------------------------------ fit

    def _windows(self, L: np.ndarray, joints: list[int]) -> np.ndarray:
        """Frame-major windows ``[S, M·3·len(joints)]`` of local positions ``L`` [T, J, 3]; window ``s`` holds
        frames ``s, s+δ, …, s+(M−1)δ`` (δ = ``dilation``)."""
        M, delta = int(self.window), int(self.dilation)
        Y = L[:, joints].reshape(L.shape[0], -1)
        S = Y.shape[0] - (M - 1) * delta
        idx = np.arange(S)[:, None] + delta * np.arange(M)[None, :]
        return Y[idx].reshape(S, -1)

    def _to_local(self, P: np.ndarray, obs: np.ndarray):
        """Local coordinates ``(Lc [T, J, 3], origin [T, 3], R [T, 3, 3])``, ``Lc = R (P − origin)`` (0 where missing)."""
        origin, R = self._local_frames(P, obs)
        Lc = np.einsum("tab,tjb->tja", R, np.where(obs[..., None], P, 0.0) - origin[:, None])
        return Lc, origin, R

    def _fit_matrices(self, data: list[tuple[np.ndarray, np.ndarray]]) -> None:
        rng = np.random.default_rng(self.random_state)
        M = int(self.window)
        per_poselet: dict[str, list[np.ndarray]] = {k: [] for k in self.poselets_}
        for X, observed in data:
            T = X.shape[0]
            if T < (M - 1) * int(self.dilation) + 1:
                continue
            P, obs = X.reshape(T, -1, 3), observed[:, ::3]
            Lc = self._to_local(P, obs)[0]
            for name, joints in self.poselets_.items():
                full = self._windows(obs[:, :, None].astype(np.float64), joints).min(1) > 0
                per_poselet[name].append(self._windows(Lc, joints)[full])
        self.dictionaries_, self.scales_, self.history_ = {}, {}, {}
        for name, joints in self.poselets_.items():
            Y = np.concatenate(per_poselet[name]) if per_poselet[name] else np.empty((0, 0))
            if len(Y) < 2:
                raise RefinementError(
                    f"{type(self).__name__}.fit: no fully observed {M}-frame training window for poselet {name!r}"
                )
            if len(Y) > self.max_train_windows:
                Y = Y[rng.choice(len(Y), int(self.max_train_windows), replace=False)]
            scale = float(np.linalg.norm(Y, axis=1).max()) or 1.0
            D, history = self._learn_dictionary(Y / scale, len(joints), rng)
            self.dictionaries_[name], self.scales_[name], self.history_[name] = D, scale, history

    def _training_masks(self, n: int, J: int, rng: np.random.Generator) -> np.ndarray:
        """Synthetic marker-level missing masks ``[n, M·3·J]`` (True = missing): 1…⌈J/2⌉ joints of the
        poselet, each window missing them over a random span of frames (the whole window half the time)."""
        M = int(self.window)
        count = rng.integers(1, max(1, (J + 1) // 2) + 1, size=n)
        pick = rng.random((n, J)).argsort(1) < count[:, None]  # [n, J]
        length = np.where(rng.random(n) < 0.5, M, rng.integers(1, M + 1, size=n))
        start = rng.integers(0, M - length + 1)
        frames = np.arange(M)[None, :]
        span = (frames >= start[:, None]) & (frames < (start + length)[:, None])  # [n, M]
        miss = span[:, :, None] & pick[:, None, :]  # [n, M, J]
        return np.repeat(miss, 3, axis=2).reshape(n, -1)

    def _learn_dictionary(self, Y: np.ndarray, J: int, rng: np.random.Generator) -> tuple[np.ndarray, list]:
        """Masked dictionary learning (eqs. 3.9–3.12) on windows ``Y`` [N, d] (rows; unit-ball scaled)."""
        N = Y.shape[0]
        K = int(min(self.n_atoms, N))
        missing = self._training_masks(N, J, rng)
        obs = ~missing
        D = Y[rng.choice(N, K, replace=False)].T.copy()  # [d, K] initial atoms
        prev = None
        Yo = np.where(missing, Y, 0.0)  # Ω ∘ Y
        history = []
        for _ in range(int(self.max_iter)):
            W = self._llc(Y, obs, D)  # sparse [N, K]
            Wt = W.T.tocsr()
            diag_h = np.asarray((Wt.multiply(Wt)) @ missing.astype(np.float64))  # [K, d] Σ_j Ω_rj w_mj²
            step = 1.0 / (W.getnnz(axis=1).max() * diag_h + 1e-12)  # k-sparse codes: H ≼ k·diag(H)
            for _ in range(int(self.dictionary_steps)):  # eq. 3.10, majorised steps
                resid = np.where(missing, np.asarray(W @ D.T) - Y, 0.0)  # Ω ∘ (D W − Y)  [N, d]
                grad = np.asarray(Wt @ resid)  # [K, d]
                D = D - (step * grad).T
                D /= np.maximum(np.linalg.norm(D, axis=0), 1.0)  # ‖D_m‖₂ ≤ 1
            unused = np.asarray(abs(W).sum(0)).ravel() == 0
            if unused.any():
                D[:, unused] = Y[rng.choice(N, int(unused.sum()), replace=False)].T
            recon = np.where(missing, np.asarray(W @ D.T), 0.0)
            err = np.linalg.norm(recon - Yo) / max(np.linalg.norm(Yo), 1e-12)
            change = np.inf if prev is None else np.linalg.norm(recon - prev) / max(np.linalg.norm(recon), 1e-12)
            prev = recon
            history.append((float(err), float(change)))
            if err <= self.tol or change <= self.tol:  # eq. 3.12
                break
        return D, history

    # ------------------------------------------------------------------ LLC coding

    def _llc(self, Y: np.ndarray, obs: np.ndarray, D: np.ndarray) -> sp.csr_matrix:
        """Approximated LLC codes (eqs. 3.15–3.17) of rows ``Y`` [n, d] from their ``obs`` rows; sparse [n, K]."""
        n, d = Y.shape
        K = D.shape[1]
        k = int(min(self.n_neighbors, K))
        Dt = torch.from_numpy(np.ascontiguousarray(D.T))  # [K, d] float64
        Dt32 = Dt.float()
        D2 = (Dt32 * Dt32).T  # [d, K]
        eye = torch.eye(k, dtype=torch.float64)
        cols, vals = [], []
        chunk = max(1, int(3e7 // (max(K, k * d) * 8)))
        for a in range(0, n, chunk):
            y = torch.from_numpy(Y[a : a + chunk])
            o = torch.from_numpy(obs[a : a + chunk])
            yo = torch.where(o, y, 0.0)
            yo32 = yo.float()
            dist2 = (yo32 * yo32).sum(1, keepdim=True) - 2 * yo32 @ Dt32.T + o.float() @ D2  # masked distances
            d2nn, nn = torch.topk(dist2, k, dim=1, largest=False)  # k nearest atoms
            Z = torch.where(o[:, None, :], Dt[nn] - y[:, None, :], 0.0)  # D̃ − ỹ1ᵀ, observed rows
            C = Z @ Z.transpose(1, 2)  # [c, k, k]
            dist = d2nn.double().clamp(min=0).sqrt()
            sigma = dist.mean(1, keepdim=True).clamp(min=1e-12)
            g = torch.exp((dist - dist.amax(1, keepdim=True)) / sigma)  # locality adaptor, (0, 1]
            tr = C.diagonal(dim1=1, dim2=2).sum(1).clamp(min=1e-12)[:, None, None]
            C = C + tr * (self.llc_lambda / k) * torch.diag_embed(g) + tr * 1e-8 * eye
            w = torch.linalg.solve(C, torch.ones(len(y), k, 1, dtype=torch.float64))[..., 0]
            w = w / w.sum(1, keepdim=True)
            cols.append(nn.numpy().ravel())
            vals.append(w.numpy().ravel())
        rows = np.repeat(np.arange(n), k)
        return sp.csr_matrix((np.concatenate(vals), (rows, np.concatenate(cols))), shape=(n, K))

    # ------------------------------------------------------------------ TDD

    def _trust_detection(self, P: np.ndarray, obs: np.ndarray) -> np.ndarray:
        """Observed markers more than φ from a smoothing-spline fit of their track (bool [T, J])."""
        T, J = obs.shape
        flagged = np.zeros((T, J), bool)
        if self.tdd_threshold is None or T < 5:
            return flagged
        t = np.arange(T) / self.fps_
        lam = self.fps_ / (2 * np.pi * float(self.tdd_cutoff_hz)) ** 4  # |H(ω)| = ½ at the cutoff
        for _ in range(max(1, int(self.tdd_passes))):
            trusted = obs & ~flagged
            patterns: dict[bytes, list[int]] = {}
            for j in range(J):
                if trusted[:, j].sum() >= 5:
                    patterns.setdefault(trusted[:, j].tobytes(), []).append(j)
            new = np.zeros_like(flagged)
            for joints in patterns.values():
                use = trusted[:, joints[0]]
                ys = P[use][:, joints].reshape(int(use.sum()), -1)
                fit = make_smoothing_spline(t[use], ys, lam=lam)(t).reshape(T, len(joints), 3)
                dev = np.linalg.norm(P[:, joints] - fit, axis=2)
                new[:, joints] = (dev > float(self.tdd_threshold)) & obs[:, joints]
            if (new == flagged).all():
                break
            flagged = new
        return flagged

    # ------------------------------------------------------------------ recovery

    def _refine_matrix(self, X: np.ndarray, observed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        T, C3 = X.shape
        J = C3 // 3
        M = int(self.window)
        P, obs_in = X.reshape(T, J, 3), observed[:, ::3]
        flagged = self._trust_detection(P, obs_in)
        obs = obs_in & ~flagged
        Lc, origin, R = self._to_local(P, obs)
        # pad (M-1)·δ unobserved frames at both ends: every frame is then in M windows and short takes work
        delta = int(self.dilation)
        pad = (M - 1) * delta
        Lp = np.pad(Lc, ((pad, pad), (0, 0), (0, 0)))
        op = np.pad(obs, ((pad, pad), (0, 0)))
        Tp = T + 2 * pad
        total = np.zeros((Tp, J, 3))
        count = np.zeros((Tp, J))
        for name, joints in self.poselets_.items():
            D, scale = self.dictionaries_[name], self.scales_[name]
            Yw = self._windows(Lp, joints) / scale  # [S, d]
            Ow = self._windows(np.repeat(op[:, :, None], 3, 2).astype(np.float64), joints) > 0
            todo = ~Ow.all(1) & Ow.any(1)  # a gap and something to code from
            if not todo.any():
                continue
            W = self._llc(Yw[todo], Ow[todo], D)
            recon = np.asarray(W @ D.T) * scale  # [n, d]
            starts = np.flatnonzero(todo)
            Jp = len(joints)
            rec = recon.reshape(len(starts), M, Jp, 3)
            for m in range(M):
                np.add.at(total, (starts[:, None] + m * delta, np.asarray(joints)[None, :]), rec[:, m])
                np.add.at(count, (starts[:, None] + m * delta, np.asarray(joints)[None, :]), 1.0)
        total, count = total[pad : pad + T], count[pad : pad + T]
        est = np.where(count[..., None] > 0, total / np.maximum(count, 1)[..., None], np.nan)
        world = np.einsum("tba,tjb->tja", R, est) + origin[:, None]  # R^T p + o
        # the root of the local frame is the origin itself: where it is missing, use the interpolated origin
        r = self.reference_[0] if self.reference_ is not None else 0
        world[:, r] = np.where(np.isnan(world[:, r]), origin, world[:, r])
        flagged &= all_coordinates(np.isfinite(world))  # a flagged marker nothing could recover stays as it was
        obs = obs_in & ~flagged
        filled = np.where(np.repeat(obs, 3, 1), X, world.reshape(T, C3))
        return filled, flagged
