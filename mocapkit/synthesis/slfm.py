"""Zhou 2014 ch. 4: motion variants from a Semiparametric Latent Factor Model (SLFM) of every joint.

Spec: ../shared/spec/thesis-zhou-2014-retrieval-synthesis.md §3 (eq. 4.2–4.4) and gaps 12–19.

**The regression model** (§3.5, gap 12). ``D`` outputs (a joint's 3 exp-map angles) are ``y_i = f_i(x) + eps_i``
with ``f_i(x) = sum_p phi_ip u_p(x)``: ``Q = D`` independent latent GPs ``u_p``, each with the kernel of eq. 4.3
``k_p(x, x') = exp(-|x - x'|² / (2 l_p²)) + b_p`` (isotropic RBF with ``theta0 = 1`` (the mixing carries the
scale; ``theta1 = 1/l_p²``) plus a bias ``theta2 = b_p``), a rank-1 mixing column ``phi_p`` each, and noise
``eps_i ~ N(0, s_i²)`` per output. The full cross-covariance is ``Cov(f(x), f(x')) = sum_p (phi_p phi_pᵀ) ⊗
k_p(x, x')`` (:func:`slfm_covariance`), a linear model of coregionalisation; GPyTorch's ``LCMKernel`` with rank-1
``IndexKernel``\\ s (their diagonal term pinned to 0) and a per-output-noise ``MultitaskGaussianLikelihood`` is the
same model. Hyper-parameters maximise the exact log marginal likelihood with **L-BFGS** (strong Wolfe line search;
the thesis used conjugate gradients, another deterministic gradient method) on at most ``n_fit`` standardised
training pairs (:func:`fit_slfm_hyperparameters`; ``3·n_fit`` squared is the matrix GPyTorch factorises).

**Departures from the thesis, both measured on HDM05 ``hopBothLegs1hops``** (:class:`SLFMRegressor`):

- *A linear prior mean* (``mean_function="linear"``, default; ``"zero"`` is the thesis's zero-mean GP). The
  second-order dynamics at 120 Hz are nearly linear (``x_t ≈ 2 x_{t-1} - x_{t-2}``); with eq. 4.3's isotropic
  RBF + bias kernel alone the fitted models either predicted the next frame no better than copying the previous
  one (few L-BFGS steps) or ran to length-scales of 10³ whose near-singular kernels gave negative predictive
  variances, and autoregressive sampling diverged (root height 1–33 ASF units against a training range of
  15–24, within 5 frames). The mean is a ridge regression on the inputs; the SLFM models its residual.
- *Inputs clipped to the training box* at prediction time (per standardised column): a linear mean extrapolates
  without bound, and sampled limbs that wandered outside the training data otherwise kept spinning (Euler curves
  of 1700° beyond the training range). With both, variants stay near the training range (see the synthesiser).

**Prediction** (:class:`SLFMPosterior`) uses *all* training pairs through ``M`` inducing inputs ``Z`` (chosen by
farthest-point sampling): the deterministic-training-conditional (DTC) posterior, ``f(x) = sum_p phi_p
k_p(x, Z) K_p(Z, Z)⁻¹ u_p(Z)`` with the exact prior variance added back, so it equals the exact GP posterior when
``Z`` is the whole training set. Everything that does not depend on the query is cached at fit time, so one
prediction costs ``O(Q² M²)`` flops, batched over queries (the synthesis variants) in numpy.

**The synthesiser** (:class:`SLFMSynthesizer`) builds one such model per joint and per case of eq. 4.2 (§3.3,
§3.4, §3.6); see its docstring for the inputs, the root and the sampling loop.
"""

from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from mocapkit.datasets.formats.asf_amc import AsfSkeleton
from mocapkit.motion.container import Motion
from mocapkit.synthesis.base import MotionSynthesizer
from mocapkit.synthesis.clips import (
    SMOOTHING_SECONDS,
    SynthesisInputError,
    check_flag,
    clip_label,
    dof_values,
    model_frames,
    resample_clip,
    rotation_columns,
    time_warp,
)
from mocapkit.synthesis.footskate import DEFAULT_ROOT_MOVE
from mocapkit.synthesis.representation import (
    ROOT_FEATURES,
    FeatureClip,
    continuous_pieces,
    decode,
    dof_axes,
    encode,
    partition_ancestors,
    partitions,
    project_expmap,
    root_start,
)

# --------------------------------------------------------------------------- the SLFM / LMC regression model


@dataclass
class SLFMParams:
    """Hyper-parameters of an SLFM with ``D`` outputs and ``Q`` latent GPs (module docstring).

    Attributes:
        lengthscale: float64 ``[Q]``: RBF length-scale ``l_p`` of each latent GP (input units; ``theta1 = 1/l²``).
        bias: float64 ``[Q]``: bias variance ``b_p`` (eq. 4.3's ``theta2``).
        mixing: float64 ``[D, Q]``: ``phi``; column ``p`` is latent ``p``'s rank-1 mixing vector.
        noise: float64 ``[D]``: observation noise variance ``s_i²`` per output (eq. 4.3's ``1/beta``).
    """

    lengthscale: np.ndarray
    bias: np.ndarray
    mixing: np.ndarray
    noise: np.ndarray

    @property
    def n_outputs(self) -> int:
        return self.mixing.shape[0]

    @property
    def n_latent(self) -> int:
        return self.mixing.shape[1]


def latent_kernels(params: SLFMParams, X1: np.ndarray, X2: np.ndarray) -> np.ndarray:
    """float64 ``[Q, N1, N2]``: ``k_p(X1, X2) = exp(-|x - x'|²/(2 l_p²)) + b_p`` for every latent ``p``."""
    X1 = np.asarray(X1, dtype=np.float64)
    X2 = np.asarray(X2, dtype=np.float64)
    sq = (np.sum(X1**2, 1)[:, None] + np.sum(X2**2, 1)[None, :] - 2.0 * X1 @ X2.T).clip(min=0.0)
    return np.exp(-sq[None] / (2.0 * params.lengthscale[:, None, None] ** 2)) + params.bias[:, None, None]


def slfm_covariance(params: SLFMParams, X1: np.ndarray, X2: np.ndarray) -> np.ndarray:
    """float64 ``[D·N1, D·N2]``: ``Cov(f(X1), f(X2)) = sum_p (phi_p phi_pᵀ) ⊗ K_p(X1, X2)``, output-major (row
    ``i·N1 + n`` is output ``i`` at ``X1[n]``); no noise."""
    K = latent_kernels(params, X1, X2)
    return sum(np.kron(np.outer(params.mixing[:, p], params.mixing[:, p]), K[p]) for p in range(params.n_latent))


def _gpytorch_model(x, y, n_outputs: int, min_noise: float):
    """A GPyTorch exact LMC GP: ``LCMKernel`` of ``n_outputs`` latents (RBF + constant, rank-1 mixing, the
    ``IndexKernel`` diagonal pinned to 0) and per-output noise; float64."""
    import gpytorch
    import torch

    class LMCExactGP(gpytorch.models.ExactGP):
        def __init__(self):
            likelihood = gpytorch.likelihoods.MultitaskGaussianLikelihood(
                num_tasks=n_outputs,
                rank=0,
                has_global_noise=False,
                noise_constraint=gpytorch.constraints.GreaterThan(min_noise),
            )
            super().__init__(x, y, likelihood)
            self.mean_module = gpytorch.means.MultitaskMean(gpytorch.means.ZeroMean(), num_tasks=n_outputs)
            base = [gpytorch.kernels.RBFKernel() + gpytorch.kernels.ConstantKernel() for _ in range(n_outputs)]
            self.covar_module = gpytorch.kernels.LCMKernel(base, num_tasks=n_outputs, rank=1)
            for multitask in self.covar_module.covar_module_list:
                index = multitask.task_covar_module
                index.raw_var.requires_grad_(False)
                index.raw_var.data.fill_(-1e4)  # softplus(-1e4) == 0: B_p = phi_p phi_pᵀ exactly (SLFM, not B + diag)

        def forward(self, inputs):
            return gpytorch.distributions.MultitaskMultivariateNormal(
                self.mean_module(inputs), self.covar_module(inputs)
            )

    return LMCExactGP().to(torch.float64)


def _read_params(model) -> SLFMParams:
    lengthscale, bias, mixing = [], [], []
    for multitask in model.covar_module.covar_module_list:
        rbf, constant = multitask.data_covar_module.kernels
        lengthscale.append(float(rbf.lengthscale.detach().reshape(-1)[0]))
        bias.append(float(constant.constant.detach().reshape(-1)[0]))
        mixing.append(multitask.task_covar_module.covar_factor.detach().cpu().numpy()[:, 0])
    return SLFMParams(
        lengthscale=np.array(lengthscale),
        bias=np.array(bias),
        mixing=np.stack(mixing, axis=1),
        noise=model.likelihood.task_noises.detach().cpu().numpy().astype(np.float64).reshape(-1),
    )


def fit_slfm_hyperparameters(
    X: np.ndarray, Y: np.ndarray, max_iter: int = 50, min_noise: float = 1e-4, seed: int = 0
) -> SLFMParams:
    """Maximise the exact SLFM log marginal likelihood (GPyTorch, L-BFGS) on standardised data.

    Args:
        X: float64 ``[N, d]`` inputs (standardised: zero mean, unit variance per column).
        Y: float64 ``[N, D]`` outputs (standardised per column).
        max_iter: L-BFGS iterations (0: keep the initial values).
        min_noise: lower bound on each output's noise variance.
        seed: seeds the initial mixing matrix.

    Initial values: length-scales ``sqrt(d)·(1, 2, 4, …)`` (one per latent, so the latents start different),
    bias 0.1, mixing ``0.9·I`` plus ``N(0, 0.1²)``, noise 0.1. A step that fails (a non-PD matrix) keeps the last
    good values.
    """
    import gpytorch
    import torch

    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    d = X.shape[1]
    D = Y.shape[1]
    x = torch.as_tensor(X)
    y = torch.as_tensor(Y)
    model = _gpytorch_model(x, y, D, min_noise)
    generator = np.random.default_rng(seed)
    with torch.no_grad():
        for p, multitask in enumerate(model.covar_module.covar_module_list):
            rbf, constant = multitask.data_covar_module.kernels
            rbf.lengthscale = math.sqrt(max(d, 1)) * 2.0**p
            constant.constant = torch.tensor(0.1, dtype=torch.float64)
            factor = 0.1 * generator.standard_normal(D)
            factor[p] += 0.9
            multitask.task_covar_module.covar_factor.copy_(torch.as_tensor(factor).reshape(D, 1))
        model.likelihood.task_noises = torch.full((D,), 0.1, dtype=torch.float64)
    if max_iter <= 0:
        return _read_params(model)
    model.train()
    model.likelihood.train()
    mll = gpytorch.mlls.ExactMarginalLogLikelihood(model.likelihood, model)
    trainable = [p for p in model.parameters() if p.requires_grad]
    optimizer = torch.optim.LBFGS(trainable, lr=1.0, max_iter=max_iter, line_search_fn="strong_wolfe")
    best = {"loss": math.inf, "state": {k: v.clone() for k, v in model.state_dict().items()}}

    def closure():
        optimizer.zero_grad()
        loss = -mll(model(x), y)
        loss.backward()
        if loss.item() < best["loss"]:
            best["loss"] = loss.item()
            best["state"] = {k: v.detach().clone() for k, v in model.state_dict().items()}
        return loss

    with gpytorch.settings.max_cholesky_size(10**7), gpytorch.settings.cholesky_jitter(1e-8):
        try:
            optimizer.step(closure)
        except (RuntimeError, ValueError):  # linear_operator's NotPSDError is a RuntimeError
            pass
    model.load_state_dict(best["state"])
    return _read_params(model)


def farthest_points(X: np.ndarray, m: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``m`` rows of ``X`` ``[N, d]`` by greedy farthest-point sampling from a random first row (all rows
    when ``m >= N``): inducing inputs that cover the training inputs."""
    N = len(X)
    if m >= N:
        return np.arange(N)
    chosen = [int(rng.integers(N))]
    distance = np.sum((X - X[chosen[0]]) ** 2, axis=1)
    for _ in range(m - 1):
        nxt = int(np.argmax(distance))
        chosen.append(nxt)
        distance = np.minimum(distance, np.sum((X - X[nxt]) ** 2, axis=1))
    return np.array(chosen)


class SLFMPosterior:
    """The SLFM posterior through inducing inputs (DTC; module docstring), cached for fast batched prediction.

    Args:
        params: the hyper-parameters.
        X: float64 ``[N, d]`` training inputs; Y: float64 ``[N, D]`` training outputs (zero-mean model).
        Z: float64 ``[M, d]`` inducing inputs (``Z = X``: the exact GP posterior).
        jitter: added to the diagonal of each ``K_p(Z, Z)`` (relative to ``k_p(x, x) = 1 + b_p``; grown tenfold
            until the Cholesky factorisation succeeds).

    With whitened inducing values ``w_p = L_p⁻¹ u_p(Z)`` (``L_p L_pᵀ = K_p(Z, Z)``) the model is a Bayesian linear
    regression ``f_i(x) = sum_p phi_ip a_p(x)ᵀ w_p``, ``a_p(x) = L_p⁻¹ k_p(Z, x)``, ``w ~ N(0, I)``; its posterior
    ``N(m_w, S_w)`` is computed once. Prediction: ``E f(x) = sum_p phi_p k_p(x, Z)ᵀ r_p`` and ``Cov f(x) =
    sum_p phi_p phi_pᵀ k_p(x, x) + sum_pq phi_p phi_qᵀ k_p(x, Z)ᵀ H_pq k_q(x, Z)`` with ``r_p = L_p⁻ᵀ m_w,p``
    and ``H_pq = L_p⁻ᵀ (S_w - I)_pq L_q⁻¹`` cached.
    """

    def __init__(self, params: SLFMParams, X: np.ndarray, Y: np.ndarray, Z: np.ndarray, jitter: float = 1e-8):
        self.params = params
        self.Z = np.asarray(Z, dtype=np.float64)
        Q, M = params.n_latent, len(self.Z)
        Kzz = latent_kernels(params, self.Z, self.Z)
        scale = 1.0 + params.bias[:, None, None]
        for attempt in range(6):  # smooth kernels make K(Z, Z) nearly singular: grow the jitter until it factorises
            try:
                L = np.linalg.cholesky(Kzz + jitter * 10.0**attempt * scale * np.eye(M)[None])
                break
            except np.linalg.LinAlgError:
                if attempt == 5:
                    raise
        Linv = np.linalg.inv(L)  # [Q, M, M]
        A = Linv @ latent_kernels(params, self.Z, X)  # [Q, M, N]: a_p(X)
        phi, inv_noise = params.mixing, 1.0 / params.noise
        coupling = phi.T @ (inv_noise[:, None] * phi)  # [Q, Q]: sum_i phi_ip phi_iq / s_i²
        precision = np.einsum("pq,pmn,qkn->pmqk", coupling, A, A).reshape(Q * M, Q * M) + np.eye(Q * M)
        rhs = np.einsum("pmn,np->pm", A, np.asarray(Y, dtype=np.float64) @ (inv_noise[:, None] * phi)).reshape(-1)
        chol = np.linalg.cholesky(precision)
        mean_w = np.linalg.solve(chol.T, np.linalg.solve(chol, rhs)).reshape(Q, M)
        cov_w = np.linalg.inv(precision)
        self._r = np.einsum("pmk,pm->pk", Linv, mean_w)  # [Q, M]: L_p⁻ᵀ m_w,p
        G = (cov_w - np.eye(Q * M)).reshape(Q, M, Q, M)
        H = np.einsum("pmk,pmqn,qnl->pkql", Linv, G, Linv)  # [Q, M, Q, M]
        self._H = H.reshape(Q, M, Q * M)
        self._prior = np.einsum("ip,jp,p->ij", phi, phi, 1.0 + params.bias)  # [D, D]: Cov f(x) under the prior

    def predict(self, Xstar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mean float64 ``[V, D]`` and covariance ``[V, D, D]`` of the latent ``f`` at ``Xstar`` ``[V, d]`` (no
        observation noise: add ``diag(params.noise)`` for ``y``)."""
        p = self.params
        Q, M = p.n_latent, len(self.Z)
        K = latent_kernels(p, Xstar, self.Z)  # [Q, V, M]
        mean = np.sum(K * self._r[:, None, :], axis=2).T @ p.mixing.T  # [V, D]
        HK = np.matmul(K, self._H).reshape(Q, len(Xstar), Q, M)  # [p, V, q, M]: k_pᵀ H_pq
        S = np.sum(HK * K.transpose(1, 0, 2)[None], axis=3).transpose(1, 0, 2)  # [V, p, q]: k_p H_pq k_q
        cov = self._prior[None] + p.mixing[None] @ S @ p.mixing.T
        return mean, cov


def gaussian_samples(
    mean: np.ndarray, cov: np.ndarray, rng: np.random.Generator, z: np.ndarray | None = None
) -> np.ndarray:
    """One draw per row from ``N(mean [V, D], cov [V, D, D])`` (negative eigenvalues from round-off clipped to 0),
    from the standard normals ``z`` ``[V, D]`` when given (else drawn from ``rng``)."""
    values, vectors = np.linalg.eigh(0.5 * (cov + np.swapaxes(cov, 1, 2)))
    z = (rng.standard_normal(mean.shape) if z is None else z) * np.sqrt(values.clip(min=0.0))
    return mean + np.einsum("vij,vj->vi", vectors, z)


class SLFMRegressor:
    """An SLFM regression ``[N, d] → [N, D]`` in original units: standardisation, an optional linear prior mean,
    hyper-parameter fit on a subset, inducing-point posterior on all pairs, batched prediction and sampling.

    Args:
        n_fit: most training pairs used for the marginal-likelihood fit (a random subset beyond that).
        n_inducing: inducing inputs ``M`` of the posterior (farthest-point sampled; all pairs when fewer).
        max_iter: L-BFGS iterations.
        mean_function: ``"linear"``: the GP prior mean is an affine function of the inputs fitted by ridge
            regression (penalty ``ridge`` on standardised inputs) and the SLFM models the residual; ``"zero"``:
            the thesis's zero-mean GP (on standardised outputs).
        ridge: the ridge penalty of the linear mean.
        min_noise: lower bound on the noise variance of a standardised output.

    Inputs are standardised per column; outputs are centred, and the SLFM sees the residuals of the linear mean
    (the centred outputs for ``"zero"``) scaled to unit variance per column. An output column that is constant
    in the training data (e.g. the ``y, z`` exp-map angles of a 1-dof bone) is not modelled and is returned as
    that constant with zero variance.
    """

    def __init__(
        self,
        n_fit: int = 200,
        n_inducing: int = 64,
        max_iter: int = 50,
        mean_function: str = "linear",
        ridge: float = 1.0,
        min_noise: float = 1e-4,
    ):
        self.n_fit = n_fit
        self.n_inducing = n_inducing
        self.max_iter = max_iter
        self.mean_function = mean_function
        self.ridge = ridge
        self.min_noise = min_noise

    def fit(self, X: np.ndarray, Y: np.ndarray, rng: np.random.Generator) -> SLFMRegressor:
        if self.mean_function not in ("linear", "zero"):
            raise ValueError(f"mean_function must be 'linear' or 'zero', got {self.mean_function!r}")
        X = np.asarray(X, dtype=np.float64)
        Y = np.asarray(Y, dtype=np.float64)
        self.x_mean_ = X.mean(axis=0)
        x_std = X.std(axis=0)
        self.x_scale_ = np.where(x_std > 1e-12, x_std, 1.0)
        self.y_mean_ = Y.mean(axis=0)
        self.y_low_, self.y_high_ = Y.min(axis=0), Y.max(axis=0)
        self.modelled_ = np.flatnonzero(Y.std(axis=0) > 1e-9 * (1.0 + np.abs(self.y_mean_)))
        self.n_outputs_ = Y.shape[1]
        Xs = (X - self.x_mean_) / self.x_scale_
        self.x_low_, self.x_high_ = Xs.min(axis=0), Xs.max(axis=0)
        Yc = (Y - self.y_mean_)[:, self.modelled_]
        self.weights_ = np.zeros((X.shape[1], len(self.modelled_)))
        if self.mean_function == "linear" and len(self.modelled_):
            self.weights_ = np.linalg.solve(Xs.T @ Xs + self.ridge * np.eye(X.shape[1]), Xs.T @ Yc)
        residual = Yc - Xs @ self.weights_
        r_std = residual.std(axis=0)
        self.r_scale_ = np.where(r_std > 1e-12, r_std, 1.0)
        if len(self.modelled_) == 0:
            self.posterior_ = None
            return self
        residual = residual / self.r_scale_
        subset = rng.permutation(len(Xs))[: self.n_fit] if len(Xs) > self.n_fit else np.arange(len(Xs))
        params = fit_slfm_hyperparameters(
            Xs[subset],
            residual[subset],
            max_iter=self.max_iter,
            min_noise=self.min_noise,
            seed=int(rng.integers(2**31)),
        )
        Z = Xs[farthest_points(Xs, self.n_inducing, rng)]
        self.posterior_ = SLFMPosterior(params, Xs, residual, Z)
        return self

    def predict(self, X: np.ndarray, noise: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Mean ``[V, D]`` and covariance ``[V, D, D]`` (original units) of ``f`` at ``X`` ``[V, d]``, plus the
        observation noise when ``noise``."""
        V = len(X)
        mean = np.tile(self.y_mean_, (V, 1))
        cov = np.zeros((V, self.n_outputs_, self.n_outputs_))
        if self.posterior_ is None:
            return mean, cov
        Xs = np.clip((np.asarray(X, dtype=np.float64) - self.x_mean_) / self.x_scale_, self.x_low_, self.x_high_)
        m, c = self.posterior_.predict(Xs)
        if noise:
            c = c + np.diag(self.posterior_.params.noise)[None]
        scale = self.r_scale_
        idx = self.modelled_
        mean[:, idx] += m * scale + Xs @ self.weights_
        cov[:, idx[:, None], idx[None, :]] = c * scale[None, :, None] * scale[None, None, :]
        return mean, cov

    def sample(self, X: np.ndarray, rng: np.random.Generator, noise: bool = True) -> np.ndarray:
        """One draw ``[V, D]`` per input row from the predictive distribution (``noise``: of ``y``, else of ``f``)."""
        mean, cov = self.predict(X, noise=noise)
        return gaussian_samples(mean, cov, rng)


class StackedSLFM:
    """Several fitted :class:`SLFMRegressor`\\ s evaluated together (the sampling loop's hot path).

    The models' arrays are zero-padded to common sizes (inputs ``d``, outputs ``D``, latents ``Q``, inducing
    inputs ``M``) and stacked, so that one batched numpy evaluation draws every model's outputs for every
    variant. Padding contributes nothing: padded input columns are 0 in both the queries and ``Z``, padded
    inducing rows and latents have zero weight in the cached ``r``/``H``/``phi``, padded outputs have zero scale.
    Draws equal :meth:`SLFMRegressor.sample` of each model.
    """

    def __init__(self, regressors: list[SLFMRegressor]):
        G = len(regressors)
        d = max(len(r.x_mean_) for r in regressors)
        D = max(r.n_outputs_ for r in regressors)
        posts = [r.posterior_ for r in regressors if r.posterior_ is not None]
        Q = max([p.params.n_latent for p in posts], default=1)
        M = max([len(p.Z) for p in posts], default=1)
        self.x_mean, self.x_scale = np.zeros((G, d)), np.ones((G, d))
        self.x_low, self.x_high = np.zeros((G, d)), np.zeros((G, d))
        self.y_low, self.y_high = np.full((G, D), -np.inf), np.full((G, D), np.inf)
        self.y_mean, self.weights = np.zeros((G, D)), np.zeros((G, d, D))
        self.Z, self.lengthscale, self.bias = np.zeros((G, M, d)), np.ones((G, Q, 1, 1)), np.zeros((G, Q, 1, 1))
        self.r, self.H = np.zeros((G, Q, M)), np.zeros((G, Q, M, Q, M))
        self.mixing, self.prior, self.noise = np.zeros((G, D, Q)), np.zeros((G, D, D)), np.zeros((G, D))
        self.scale = np.zeros((G, D))  # r_scale_ of the modelled outputs, 0 elsewhere
        for g, reg in enumerate(regressors):
            k = len(reg.x_mean_)
            self.x_mean[g, :k], self.x_scale[g, :k] = reg.x_mean_, reg.x_scale_
            self.y_mean[g, : reg.n_outputs_] = reg.y_mean_
            self.y_low[g, : reg.n_outputs_], self.y_high[g, : reg.n_outputs_] = reg.y_low_, reg.y_high_
            if reg.posterior_ is None:
                continue
            self.x_low[g, :k], self.x_high[g, :k] = reg.x_low_, reg.x_high_
            out = reg.modelled_
            self.weights[g, :k, out] = reg.weights_.T
            self.scale[g, out] = reg.r_scale_
            post, q, m = reg.posterior_, reg.posterior_.params.n_latent, len(reg.posterior_.Z)
            self.Z[g, :m, :k] = post.Z
            self.lengthscale[g, :q, 0, 0] = post.params.lengthscale
            self.bias[g, :q, 0, 0] = post.params.bias
            self.r[g, :q, :m] = post._r
            self.H[g, :q, :m, :q, :m] = post._H.reshape(q, m, q, m)
            self.mixing[g, out[:, None], np.arange(q)[None, :]] = post.params.mixing
            self.prior[g, out[:, None], out[None, :]] = post._prior
            self.noise[g, out] = post.params.noise
        self.H = self.H.reshape(G, Q, M, Q * M)
        self.z_sq = np.sum(self.Z**2, axis=2)[:, None, :]  # [G, 1, M]

    def predict(self, X: np.ndarray, noise: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """Mean ``[G, V, D]`` and covariance ``[G, V, D, D]`` of every model at its inputs ``X`` ``[G, V, d]``
        (zero-padded), as :meth:`SLFMRegressor.predict`."""
        G, V = X.shape[:2]
        Q, M = self.r.shape[1:]
        Xs = np.clip((X - self.x_mean[:, None]) / self.x_scale[:, None], self.x_low[:, None], self.x_high[:, None])
        sq = (np.sum(Xs**2, axis=2)[:, :, None] + self.z_sq - 2.0 * Xs @ np.swapaxes(self.Z, 1, 2)).clip(min=0.0)
        K = np.exp(-sq[:, None] / (2.0 * self.lengthscale**2)) + self.bias  # [G, Q, V, M]
        latent_mean = np.einsum("gqvm,gqm->gvq", K, self.r)
        mean = (
            self.y_mean[:, None]
            + Xs @ self.weights
            + self.scale[:, None] * (latent_mean @ np.swapaxes(self.mixing, 1, 2))
        )
        HK = np.matmul(K, self.H).reshape(G, Q, V, Q, M)  # [g, p, V, q, M]
        S = np.einsum("gpvqm,gqvm->gvpq", HK, K)
        cov = self.prior[:, None] + self.mixing[:, None] @ S @ np.swapaxes(self.mixing, 1, 2)[:, None]
        if noise:
            cov = cov + self.noise[:, None, :, None] * np.eye(cov.shape[-1])
        return mean, cov * self.scale[:, None, :, None] * self.scale[:, None, None, :]

    def sample(
        self, X: np.ndarray, rng: np.random.Generator, noise: bool = True, z: np.ndarray | None = None
    ) -> np.ndarray:
        """Draws ``[G, V, D]`` given inputs ``X`` ``[G, V, d]`` (zero-padded), from standard normals ``z``
        ``[G, V, D]`` when given."""
        mean, cov = self.predict(X, noise=noise)
        G, V, D = mean.shape
        flat_z = None if z is None else z.reshape(G * V, D)
        return gaussian_samples(mean.reshape(G * V, D), cov.reshape(G * V, D, D), rng, flat_z).reshape(G, V, D)


# --------------------------------------------------------------------------- the synthesiser

CASES = ("t1", "t2", "t3", "t>3")
"""The cases of Zhou eq. 4.2 (§3.3): frame 1 (same-frame ancestors), 2, 3 and later frames."""

NOISE_SCALES = (0.1, 0.2, 0.3, 0.5, 0.7, 1.0)
"""The scales of the predictive noise ``noise_scale="auto"`` tries, smallest first."""

AUTO_VARIANTS = 10
"""Variants sampled per tried scale by ``noise_scale="auto"``."""


class RootFrameKinematics:
    """Forward kinematics of one skeleton in its root's frame (root at the origin, unrotated), from exp-maps.

    Args:
        skeleton: the skeleton (bone lengths in metres via ``metres_per_unit``).
        bones: the bones whose exp-maps are given, :attr:`FeatureClip.bones` order.
    """

    def __init__(self, skeleton: AsfSkeleton, bones: tuple[str, ...]):
        names = skeleton.joint_names
        index = {name: j for j, name in enumerate(names)}
        self.parents = skeleton.parents
        self.order = []
        frontier = ["root"]
        for parent in frontier:
            for child in skeleton.hierarchy.get(parent, []):
                self.order.append(index[child])
                frontier.append(child)
        self.offsets = skeleton.offsets()
        self.bone_joint = np.array([index[b] for b in bones])
        self.frames = np.empty((len(bones), 3, 3))
        for k, bone in enumerate(bones):
            b = skeleton.bone(bone)
            axis = np.radians(b.axis) if skeleton.angle_unit == "deg" else np.asarray(b.axis, dtype=np.float64)
            self.frames[k] = Rotation.from_euler(b.axis_order.lower(), axis).as_matrix()
        self.slot = {int(j): k for k, j in enumerate(self.bone_joint)}

    def positions(self, joints: np.ndarray) -> np.ndarray:
        """float64 ``[N, B, 3]`` metres: the end of every bone of ``bones`` in the root frame, from exp-maps
        ``joints`` ``[N, B, 3]`` (radians)."""
        N, B = joints.shape[:2]
        M = Rotation.from_rotvec(joints.reshape(-1, 3)).as_matrix().reshape(N, B, 3, 3)
        local = self.frames[None] @ M @ np.swapaxes(self.frames, 1, 2)[None]  # C·M·C⁻¹
        J = len(self.parents)
        glob = np.empty((N, J, 3, 3))
        pos = np.empty((N, J, 3))
        glob[:, 0] = np.eye(3)
        pos[:, 0] = 0.0
        for j in self.order:
            p = self.parents[j]
            k = self.slot.get(j)
            glob[:, j] = glob[:, p] if k is None else glob[:, p] @ local[:, k]
            pos[:, j] = pos[:, p] + glob[:, j] @ self.offsets[j]
        return pos[:, self.bone_joint]


@dataclass
class _NodeModel:
    """One SLFM of eq. 4.2: ``outputs`` (flat-feature columns) of ``node`` at frame ``k`` from the inputs listed in
    ``inputs``: ``(state, frames back, columns)`` with state ``"flat"`` (features) or ``"dynamic"``."""

    node: str
    case: str
    outputs: np.ndarray
    inputs: list[tuple[str, int, np.ndarray]]
    regressor: SLFMRegressor | None = None

    def features(self, flat: np.ndarray, dynamic: np.ndarray, k: int | np.ndarray) -> np.ndarray:
        """Input rows ``[N, d]`` at frame(s) ``k`` of ``flat [N, T, F]`` and ``dynamic [N, T, Fd]``."""
        states = {"flat": flat, "dynamic": dynamic}
        parts = [states[name][:, np.asarray(k) - back][..., cols] for name, back, cols in self.inputs]
        return np.concatenate(parts, axis=-1).reshape(-1, sum(len(c) for _, _, c in self.inputs))

    def context_index(self, width: dict[tuple[str, int], int]) -> np.ndarray:
        """The input columns as indices into a context row (:func:`_context`) whose blocks have ``width``."""
        offset, start = {}, 0
        for block in CONTEXT:
            offset[block] = start
            start += width[block]
        return np.concatenate([offset[(name, back)] + cols for name, back, cols in self.inputs])


CONTEXT = (("flat", 0), ("flat", 1), ("flat", 2), ("dynamic", 1), ("dynamic", 2))
"""The blocks ``(state, frames back)`` of a context row, then one zero column (the padding target)."""


def _context(flat: np.ndarray, dynamic: np.ndarray, k: int) -> np.ndarray:
    """float64 ``[V, width + 1]``: frame ``k`` of ``flat`` and ``dynamic`` (``[V, T, ·]``) and the frames before
    it (clamped at frame 0), in :data:`CONTEXT` order, plus a zero column."""
    states = {"flat": flat, "dynamic": dynamic}
    blocks = [states[name][:, max(k - back, 0)] for name, back in CONTEXT]
    return np.concatenate(blocks + [np.zeros((len(flat), 1))], axis=1)


class _CaseSampler:
    """The models of one case drawn together: a :class:`StackedSLFM`, the context columns of each model's inputs
    ``[G, d]`` (padding points at the zero column) and where the draws go in the flat features."""

    def __init__(self, models: list[_NodeModel], width: dict[tuple[str, int], int]):
        self.stack = StackedSLFM([m.regressor for m in models])
        pad = sum(width.values())
        index = [m.context_index(width) for m in models]
        self.gather = np.full((len(models), max(len(i) for i in index)), pad)
        for g, i in enumerate(index):
            self.gather[g, : len(i)] = i
        D = self.stack.y_mean.shape[1]
        self.slots = np.concatenate([g * D + np.arange(len(m.outputs)) for g, m in enumerate(models)])
        self.columns = np.concatenate([m.outputs for m in models])

    def draw(
        self,
        context: np.ndarray,
        rng: np.random.Generator,
        noise: bool,
        z: np.ndarray | None = None,
        output_margin: float | None = None,
    ) -> tuple[np.ndarray, np.ndarray]:
        """The flat-feature columns and their draws ``[V, n]`` given a context ``[V, width + 1]`` (from standard
        normals ``z`` ``[G, V, D]`` when given), clipped to each output's training range widened by
        ``output_margin`` times that range on both sides when given."""
        X = np.swapaxes(context[:, self.gather], 0, 1)  # [G, V, d]
        draws = self.stack.sample(X, rng, noise=noise, z=z)  # [G, V, D]
        if output_margin is not None:
            low, high = self.stack.y_low[:, None], self.stack.y_high[:, None]
            span = np.where(np.isfinite(high - low), high - low, 0.0)
            draws = np.clip(draws, low - output_margin * span, high + output_margin * span)
        draws = np.swapaxes(draws, 0, 1)  # [V, G, D]
        return self.columns, draws.reshape(len(context), -1)[:, self.slots]


class SLFMSynthesizer(MotionSynthesizer):
    """Zhou 2014 ch. 4 motion-variation synthesis: one SLFM per joint and per case of eq. 4.2.

    Spec: ../shared/spec/thesis-zhou-2014-retrieval-synthesis.md §3.3–3.6 and gaps 13–17, 19.

    **Nodes and features** (:mod:`mocapkit.synthesis.representation`). Each partition (§3.2) lists its nodes top
    down; the root is the top node of ``TH``. A bone node's SCF (skeleton configuration feature) is its exp-map
    (3); the root's SCF is its pose ``(height, tilt)`` (4; gap 16). The dynamic feature of a node at frame ``k``
    (gap 15) is, with ``dynamic_feature="position"`` (default, the literal "positional velocity"), the
    displacement since frame ``k-1`` of the bone's end joint in the root's frame (forward kinematics of the
    exp-maps on the clip's own skeleton, metres; the root's is its own step ``(dx, dheight, dz)`` in the heading
    frame), or with ``"scf_difference"`` the SCF difference between the frames.

    **Models** (§3.3, eq. 4.2; ``J = A ∪ {j}``, ``A`` = the node's ancestors within its partition):
    ``t1``: ``SCF(A)`` at the same frame → node (only nodes with ancestors); ``t2``: ``SCF(J)`` at ``k-1``;
    ``t3``: ``SCF(J)`` at ``k-1, k-2`` + dynamic(J) at ``k-1``; ``t>3``: ``SCF(J)`` at ``k-1, k-2`` + dynamic(J)
    at ``k-1, k-2``. A bone node's outputs are its 3 exp-map angles; the root has two models per case, its planar
    step ``(dx, dz, dyaw)`` and its pose ``(height, tilt)``, whose inputs also hold the root's previous planar
    steps (gap 16: "the root's own previous outputs"). No input crosses partitions (gap 17, literal).

    **Training sets** (gap 14): every model learns from every ``frame_stride``-th frame of every clip at which its
    inputs exist (``t1`` from frame 1 on, ``t2`` from 2, ``t3`` from 3, ``t>3`` from 4): the conditionals of eq.
    4.2 are stationary, so the ``t1``–``t3`` models are the same relations with fewer inputs. The literal
    reading (``t2``/``t3`` only from frame 2/3 of each clip, one pair per clip) was tried and rejected: ten pairs
    cannot teach that frame 2 stays close to frame 1, so frame 2 was drawn with the clips' spread (root height
    jumps of 0.8 ASF units against 0.2 per frame in the data) and the ``t>3`` models then ran off their data.
    Each model's hyper-parameters are fitted on at most ``n_fit`` pairs; its posterior uses all pairs through
    ``n_inducing`` inducing inputs (:class:`SLFMRegressor`).
    Training clips are first **cut at joint-angle flips** (``max_turn_speed``;
    :func:`~mocapkit.synthesis.representation.angle_flips`): frames where a bone's AMC rotation turns by more than
    a limb can in one frame while the joints barely move, i.e. the capture's solver switched to an equivalent
    joint configuration. HDM05's deep squats of performer ``dg`` flip ``femur`` by 180° (with ``tibia`` going
    from 202° to 158°) when the knee passes 180°; learnt as motion, those jumps made every squat model unstable
    (``mocapkit compare synthesis_hdm05`` before the cutting: jerk 47k m/s³ against the real 0.8k). Each piece between flips is a
    training sequence of its own; only clip starts feed the first-frame statistics; each flip is warned about.

    **Sampling** (§3.6), all variants at once: frame 1's nodes without ancestors (the root pose and each limb's
    top bone) are drawn per dimension from ``N(mean, std)`` of the clips' first frames (the root's planar step
    is 0), the others top-down from their ``t1`` model; every later frame from the matching model given the
    frames already made. Draws come from the predictive distribution of ``y`` (``f`` plus observation noise;
    ``sample_noise=False``: of ``f`` only; gap 13). After each frame the exp-maps of bones with fewer than 3 dofs
    are projected onto their dofs (:func:`~mocapkit.synthesis.representation.project_expmap`), so later frames
    condition on poses the skeleton can take. The root path is integrated from the planar steps
    (:func:`~mocapkit.synthesis.representation.decode`), starting at the first training clip's position and
    heading; ``footskate_cleanup`` then grounds and pins planted feet (:class:`~mocapkit.synthesis.base.
    MotionSynthesizer`, the same for every synthesiser).

    Args:
        frame_stride: every how many frames (at ``model_fps``) a training pair is taken.
        n_fit: most pairs per model for the hyper-parameter fit (exact GP: a ``D·n_fit`` square matrix).
        n_inducing: inducing inputs per model for prediction (cost per prediction ``O(D² n_inducing²)``).
        max_iter: L-BFGS iterations of each hyper-parameter fit.
        sample_noise: draw from ``y`` (True) or from ``f`` (False).
        noise_correlation: ρ in [0, 1): from frame 4 on, each frame's standard normals are
            ``ρ·z_{t−1} + √(1−ρ²)·ε_t`` (each still N(0, 1), so every frame's draw keeps its predictive
            distribution), which makes successive draws move together instead of jittering; 0 = independent
            draws, the thesis's literal procedure (§3.6). Not from the thesis; the normals are mapped through each
            frame's own covariance, so the correlation of the outputs is approximate.
        dynamic_feature: ``"position"`` or ``"scf_difference"``.
        footskate_cleanup, footskate_root: the footskate cleanup after sampling
            (:class:`~mocapkit.synthesis.base.MotionSynthesizer`).
        smoothing_seconds: the Gaussian smoothing of every variant before the cleanup, seconds (0: off;
            :class:`~mocapkit.synthesis.base.MotionSynthesizer`).
        model_fps: the frame rate the models work at (None: the clips' own, the thesis's 120 Hz). Lower, the
            clips are resampled for training (:func:`~mocapkit.synthesis.clips.resample_clip`) and the variants are
            drawn at this rate, then brought back to the clips' rate by a cubic spline before the footskate
            cleanup. Not from the thesis.
        noise_scale: the predictive draws' standard normals are multiplied by this (1 = the model's own
            predictive distribution, the thesis; 0 = its mean). ``"auto"`` (default): after fitting, the smallest
            of :data:`NOISE_SCALES` whose variants reach ``target_variation`` times the training clips' own V
            (:meth:`~mocapkit.synthesis.base.MotionSynthesizer._set_noise_scale`; training clips only). Not from
            the thesis.
        target_variation: the ``V / V_train`` that ``noise_scale="auto"`` asks for; default 1.28 = Zhou's 558.7
            / 435.8 (§3.7), the variation the thesis reports over its "visibly varied" reference set.
        output_margin: draws are clipped to each model output's training range widened by this fraction of
            the range on both sides (0, default: the range itself, joint limits from the data); None: no clip.
            Not from the thesis.
        max_turn_speed: degrees per second above which a bone's frame-to-frame turn in a training clip counts
            as a joint-angle flip (default 5400, 45° per frame at 120 Hz); None: no cutting.
        cross_partition: gap 17's ablation: every node of the limb partitions (all but ``TH``) also takes the
            root's pose ``(height, tilt)`` and its step as inputs, at the frames its own features enter (pose at
            ``k-1`` for ``t2``, at ``k-1, k-2`` after; step at ``k-1`` for ``t3``, at ``k-1, k-2`` for ``t>3``;
            not in ``t1``), so the limbs can follow the body's height and travel (default, not from the thesis);
            False: no input crosses partitions, the thesis's literal model (gap 17: limbs drift out of phase
            with the body).
        random_state: seeds the training subsets and inducing points.
        verbose: progress lines on stderr.

    Defaults ``model_fps=30`` and ``noise_correlation=0.9`` were chosen on the training clips only (the first 10
    hopBothLegs1hops cuts by path, all of performer bd), by the variants' jerk against those clips' own, 1.25k
    m/s³: the thesis's literal setting (120 Hz, independent draws) gave 19.7k; 120 Hz with ρ = 0.97, 11.5k; 30 Hz
    with independent draws, 1.7k; 30 Hz with ρ = 0.9, 1.2k (V 147 against the clips' 66). At 120 Hz successive
    frames differ less than the per-frame predictive noise, so independent draws jitter.
    ``noise_scale="auto"``, ``output_margin=0`` and ``frame_stride=1`` were chosen the same way, on the first 10
    cuts by path of hopBothLegs1hops and of squat1Reps (performer bd), by the variants' feature distance to those
    clips (:func:`~mocapkit.synthesis.metrics.feature_distances`) and the share of variants within the clips'
    own leave-one-out spread: on hops the scale 1 gave V / V_train 1.91 and 0 % within, 0.5 (the one ``"auto"``
    picks) 1.33 and 80 % (85 % with the output clip); on squats ``frame_stride`` 2 → 1 took the distance from
    7.6 to 2.7 and the jerk from 7.4k to 0.84k m/s³ (the clips': 0.51k), at a cost on hops of 85 → 75 % within.
    ``cross_partition=True`` the same way (the same 10 bd clips, with the cleanup's defaults): on hops the
    distance went from 0.76 to 0.69 (the clips' own 0.57) and the share within from 50 to 75 %; on squats the
    distance from 3.3 to 1.2 and the share of frames with a planted foot from 17 to 62 %, since the legs now
    bend as the body goes down.

    Attributes (after ``fit``): ``models_`` (every model, in sampling order), ``partitions_``, ``fit_seconds_``,
    ``noise_scale_`` and ``variation_by_noise_scale_`` (the base class's ``_set_noise_scale``), ``angle_flips_``
    (``(clip, frame, bone, degrees)``) and ``unused_pieces_`` (``(clip, start, stop)``) of the cutting, and those of
    :class:`~mocapkit.synthesis.base.MotionSynthesizer` (``floor_``, ``footskate_reports_``).
    """

    min_clips = 2
    min_frames = 4
    noise_scales = NOISE_SCALES
    auto_variants = AUTO_VARIANTS

    def __init__(
        self,
        frame_stride: int = 1,
        n_fit: int = 100,
        n_inducing: int = 32,
        max_iter: int = 30,
        sample_noise: bool = True,
        noise_correlation: float = 0.9,
        dynamic_feature: str = "position",
        footskate_cleanup: bool = True,
        footskate_root: str = DEFAULT_ROOT_MOVE,
        smoothing_seconds: float = SMOOTHING_SECONDS,
        model_fps: float | None = 30.0,
        noise_scale: float | str = "auto",
        target_variation: float = 1.28,
        output_margin: float | None = 0.0,
        max_turn_speed: float | None = 5400.0,
        cross_partition: bool = True,
        random_state: int | None = 0,
        verbose: bool = False,
    ):
        self.frame_stride = frame_stride
        self.n_fit = n_fit
        self.n_inducing = n_inducing
        self.max_iter = max_iter
        self.sample_noise = sample_noise
        self.noise_correlation = noise_correlation
        self.dynamic_feature = dynamic_feature
        self.footskate_cleanup = footskate_cleanup
        self.footskate_root = footskate_root
        self.smoothing_seconds = smoothing_seconds
        self.model_fps = model_fps
        self.noise_scale = noise_scale
        self.target_variation = target_variation
        self.output_margin = output_margin
        self.max_turn_speed = max_turn_speed
        self.cross_partition = cross_partition
        self.random_state = random_state
        self.verbose = verbose

    # ------------------------------------------------------------------ features

    def _dynamic(
        self, flat_now: np.ndarray, flat_before: np.ndarray, pos_now: np.ndarray, pos_before: np.ndarray
    ) -> np.ndarray:
        """Dynamic features ``[..., Fd]`` of frames ``flat_now`` given the frames before (flat ``[..., F]``, bone
        positions ``[..., B, 3]``); column layout in :meth:`_columns`."""
        if self.dynamic_feature == "position":
            root = np.stack([flat_now[..., 0], flat_now[..., 3] - flat_before[..., 3], flat_now[..., 1]], axis=-1)
            bones = (pos_now - pos_before).reshape(*pos_now.shape[:-2], -1)
            return np.concatenate([root, bones], axis=-1)
        return flat_now[..., 3:] - flat_before[..., 3:]

    def _columns(self, node: str) -> tuple[np.ndarray, np.ndarray]:
        """The node's SCF columns in the flat features and its dynamic-feature columns."""
        if node == "root":
            dyn = np.arange(3) if self.dynamic_feature == "position" else np.arange(4)
            return np.arange(3, ROOT_FEATURES), dyn
        b = self.bones_.index(node)
        start = 3 if self.dynamic_feature == "position" else 4
        return ROOT_FEATURES + 3 * b + np.arange(3), start + 3 * b + np.arange(3)

    def _clip_states(self, clip: Motion) -> tuple[np.ndarray, np.ndarray]:
        """Flat features ``[T, F]`` and dynamic features ``[T, Fd]`` (row 0 = 0) of a training clip."""
        features: FeatureClip = encode(clip)
        flat = features.flat()
        positions = RootFrameKinematics(clip.metadata["asf"], features.bones).positions(features.joints)
        dynamic = np.zeros((len(flat), self._dynamic(flat[:1], flat[:1], positions[:1], positions[:1]).shape[1]))
        dynamic[1:] = self._dynamic(flat[1:], flat[:-1], positions[1:], positions[:-1])
        return flat, dynamic

    def _node_models(self, partition: tuple[str, ...], ancestors: dict[str, tuple[str, ...]]) -> list[_NodeModel]:
        out = []
        pelvis = ("root",) if self.cross_partition and "root" not in partition else ()
        for node in partition:
            members = pelvis + ancestors[node] + (node,)
            scf = [self._columns(m)[0] for m in members]
            if node == "root":
                scf = [np.arange(3)] + scf  # the root's own previous planar steps
            scf_cols = np.concatenate(scf)
            dyn_cols = np.concatenate([self._columns(m)[1] for m in members])
            outputs = [np.arange(3), np.arange(3, ROOT_FEATURES)] if node == "root" else [self._columns(node)[0]]
            for out_cols in outputs:
                if ancestors[node]:
                    same_frame = np.concatenate([self._columns(m)[0] for m in ancestors[node]])
                    out.append(_NodeModel(node, "t1", out_cols, [("flat", 0, same_frame)]))
                out.append(_NodeModel(node, "t2", out_cols, [("flat", 1, scf_cols)]))
                out.append(
                    _NodeModel(
                        node, "t3", out_cols, [("flat", 1, scf_cols), ("flat", 2, scf_cols), ("dynamic", 1, dyn_cols)]
                    )
                )
                out.append(
                    _NodeModel(
                        node,
                        "t>3",
                        out_cols,
                        [
                            ("flat", 1, scf_cols),
                            ("flat", 2, scf_cols),
                            ("dynamic", 1, dyn_cols),
                            ("dynamic", 2, dyn_cols),
                        ],
                    )
                )
        return out

    # ------------------------------------------------------------------ fit

    def _fit_clips(self, clips: list[Motion]) -> None:
        if self.dynamic_feature not in ("position", "scf_difference"):
            raise ValueError(f"dynamic_feature must be 'position' or 'scf_difference', got {self.dynamic_feature!r}")
        if self.frame_stride < 1:
            raise ValueError(f"frame_stride must be >= 1, got {self.frame_stride}")
        self._check_noise_scale()
        check_flag(self, "cross_partition")
        start = time.perf_counter()
        if self.model_fps is not None and not float(self.model_fps) > 0:
            raise ValueError(f"model_fps must be positive (or None), got {self.model_fps!r}")
        self.model_fps_ = self.fps_ if self.model_fps is None else float(self.model_fps)
        resampled = [resample_clip(clip, self.model_fps_) for clip in clips]
        short = [c for c in resampled if c.num_frames < self.min_frames]
        if short:
            raise SynthesisInputError(
                f"SLFMSynthesizer.fit: {clip_label(short[0])} has {short[0].num_frames} frames "
                f"at model_fps={self.model_fps_:g}; the second-order model needs "
                f"{self.min_frames} (raise model_fps)"
            )
        rng = np.random.default_rng(self.random_state)
        self.bones_ = tuple(self.layout_.bones[1:])
        self.partitions_ = partitions(self.skeleton_)
        cut = continuous_pieces(
            clips, self.model_fps_, self.min_frames, self.max_turn_speed, what="SLFMSynthesizer.fit"
        )
        self.angle_flips_, self.unused_pieces_ = cut.flips, cut.unused
        states, first = [], []
        for piece, starts_clip in zip(cut.pieces, cut.starts_clip):
            try:
                states.append(self._clip_states(piece))
            except ValueError as exc:
                raise SynthesisInputError(f"SLFMSynthesizer.fit: {clip_label(piece)}: {exc}") from exc
            if starts_clip:
                first.append(states[-1][0][0])
        if not first:
            raise SynthesisInputError(
                "SLFMSynthesizer.fit: every clip's first frames are cut off by angle flips "
                "(see the warnings); no first-frame statistics"
            )
        first = np.stack(first)
        self.first_frame_mean_ = first.mean(axis=0)
        self.first_frame_std_ = first.std(axis=0)
        self.start_xz_, self.start_yaw_ = root_start(clips[0])
        self.models_ = []
        for partition in self.partitions_.values():
            self.models_.extend(self._node_models(partition, partition_ancestors(self.skeleton_, partition)))
        self.reduced_bones_ = self._reduced_bones()
        self._fit_models([self._training_pairs(model, states) for model in self.models_], states, rng)
        self._set_noise_scale(clips)
        self.fit_seconds_ = time.perf_counter() - start

    def _training_pairs(
        self, model: _NodeModel, states: list[tuple[np.ndarray, np.ndarray]]
    ) -> tuple[np.ndarray, np.ndarray]:
        X, Y = [], []
        for flat, dynamic in states:
            T = len(flat)
            frames = {
                "t1": np.arange(0, T, self.frame_stride),
                "t2": np.arange(1, T, self.frame_stride),
                "t3": np.arange(2, T, self.frame_stride),
                "t>3": np.arange(3, T, self.frame_stride),
            }[model.case]
            X.append(model.features(flat[None], dynamic[None], frames))
            Y.append(flat[frames][:, model.outputs])
        return np.concatenate(X), np.concatenate(Y)

    def _fit_models(
        self,
        pairs: list[tuple[np.ndarray, np.ndarray]],
        states: list[tuple[np.ndarray, np.ndarray]],
        rng: np.random.Generator,
    ) -> None:
        """Fit every model on its ``(X, Y)`` pairs and stack them into the samplers of each case."""
        for n, (model, (X, Y)) in enumerate(zip(self.models_, pairs)):
            tick = time.perf_counter()
            model.regressor = SLFMRegressor(n_fit=self.n_fit, n_inducing=self.n_inducing, max_iter=self.max_iter).fit(
                X, Y, rng
            )
            if self.verbose:
                print(
                    f"[slfm] model {n + 1}/{len(self.models_)}: {model.node} {model.case}, {len(X)} pairs, "
                    f"{X.shape[1]}-D inputs, {time.perf_counter() - tick:.2f} s",
                    file=sys.stderr,
                    flush=True,
                )
        width = {("flat", b): len(self.first_frame_mean_) for b in (0, 1, 2)}
        width.update({("dynamic", b): states[0][1].shape[1] for b in (1, 2)})
        self.samplers_ = {"t1": [_CaseSampler([m], width) for m in self.models_ if m.case == "t1"]}
        self.samplers_.update(
            {case: _CaseSampler([m for m in self.models_ if m.case == case], width) for case in CASES[1:]}
        )

    # ------------------------------------------------------------------ sample

    def _project(self, flat: np.ndarray) -> None:
        """Project, in place, the exp-maps of the 2-dof bones in ``flat [V, F]`` onto their dofs."""
        for axes, bones in self.reduced_bones_.items():
            cols = (ROOT_FEATURES + 3 * bones[:, None] + np.arange(3)).reshape(-1)
            v = flat[:, cols].reshape(len(flat), len(bones), 3)
            flat[:, cols] = project_expmap(v, axes).reshape(len(flat), -1)

    def _reduced_bones(self) -> dict[str, np.ndarray]:
        """The bones with exactly 2 dofs, grouped by their axes (``"xy"`` → bone indices), for :meth:`_project`."""
        dofs = dict(zip(self.layout_.bones, self.layout_.dofs))
        groups: dict[str, list[int]] = {}
        for b, bone in enumerate(self.bones_):
            axes = dof_axes(dofs[bone])
            # a 1-dof bone's exp-map is (angle along its axis, 0, 0) in every training frame, so its off-axis
            # outputs are constant and drawn as 0 (SLFMRegressor): already on its dof; 2-dof bones need projecting
            if len(axes) == 2:
                groups.setdefault(axes, []).append(b)
        return {axes: np.array(bones) for axes, bones in groups.items()}

    def _start_arrays(self, flat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bone positions ``[V, T, B, 3]`` and dynamic features ``[V, T, Fd]`` for flat features ``[V, T, F]`` whose
        frame 0 is set: frame 0's positions filled, everything else zero."""
        V, T = flat.shape[:2]
        positions = np.zeros((V, T, len(self.bones_), 3))
        positions[:, 0] = RootFrameKinematics(self.skeleton_, self.bones_).positions(
            flat[:, 0, ROOT_FEATURES:].reshape(V, -1, 3)
        )
        width = self._dynamic(flat[:, 0], flat[:, 0], positions[:, 0], positions[:, 0]).shape[1]
        return positions, np.zeros((V, T, width))

    def _rollout(self, flat: np.ndarray, positions: np.ndarray, dynamic: np.ndarray, rng: np.random.Generator) -> None:
        """Draw frames 1 … ``T-1`` of ``flat [V, T, F]`` (and their ``positions``, ``dynamic``) in place, each
        from the model of its case given the frames before (the sampling loop of the class docstring)."""
        kinematics = RootFrameKinematics(self.skeleton_, self.bones_)
        V, T = flat.shape[:2]
        tau, rho, z = self._noise_scale(), float(self.noise_correlation), None
        for k in range(1, T):
            sampler = self.samplers_["t2" if k == 1 else "t3" if k == 2 else "t>3"]
            G, D = sampler.stack.y_mean.shape
            eps = rng.standard_normal((G, V, D))
            # from frame 4 on, AR(1) standard normals: each stays N(0, 1), successive frames' draws correlate by rho
            z = rho * z + math.sqrt(1.0 - rho * rho) * eps if k > 3 and rho > 0 and z is not None else eps
            columns, draws = sampler.draw(
                _context(flat, dynamic, k), rng, self.sample_noise, tau * z, self.output_margin
            )
            flat[:, k, columns] = draws
            self._project(flat[:, k])
            positions[:, k] = kinematics.positions(flat[:, k, ROOT_FEATURES:].reshape(V, -1, 3))
            dynamic[:, k] = self._dynamic(flat[:, k], flat[:, k - 1], positions[:, k], positions[:, k - 1])

    def _sample_values(self, n_variants: int, n_frames: int, rng: np.random.Generator) -> list[dict[str, np.ndarray]]:
        V, F = n_variants, ROOT_FEATURES + 3 * len(self.bones_)
        T = max(model_frames(n_frames, self.fps_, self.model_fps_), 2)  # frames at the model's rate
        flat = np.zeros((V, T, F))
        # frame 1: nodes without ancestors from the first-frame statistics, the others top-down from t1
        top = np.concatenate(
            [np.arange(3, ROOT_FEATURES)]
            + [self._columns(part[0])[0] for name, part in self.partitions_.items() if name != "TH"]
        )
        flat[:, 0, top] = self.first_frame_mean_[top] + self.first_frame_std_[top] * rng.standard_normal((V, len(top)))
        self._project(flat[:, 0])
        _, dynamic = self._start_arrays(flat)
        for sampler in self.samplers_["t1"]:
            G, D = sampler.stack.y_mean.shape
            columns, draws = sampler.draw(
                _context(flat, dynamic, 0),
                rng,
                self.sample_noise,
                self._noise_scale() * rng.standard_normal((G, V, D)),
                self.output_margin,
            )
            flat[:, 0, columns] = draws
            self._project(flat[:, 0])
        positions, dynamic = self._start_arrays(flat)
        self._rollout(flat, positions, dynamic, rng)
        out = []
        for v in range(V):
            values = decode(
                FeatureClip.from_flat(flat[v], self.bones_),
                self.skeleton_,
                start_xz=self.start_xz_,
                start_yaw=self.start_yaw_,
            )
            if T != n_frames:  # back to the data's rate by a cubic spline
                matrix = np.concatenate([values[bone] for bone in self.layout_.bones], axis=1)
                values = dof_values(
                    time_warp(matrix, n_frames, rotation_columns(self.layout_), kind="cubic"), self.layout_
                )
            out.append(values)
        return out
