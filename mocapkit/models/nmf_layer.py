"""A differentiable NMF layer: non-negative codes of a batch of item sets against a learned dictionary.

Geng et al., "Is Attention Better Than Matrix Decomposition?", ICLR 2021 (Hamburger) run a few
NMF multiplicative updates (MU) as a layer and back-propagate through the **last step only**
("one-step gradient"), which avoids the unstable gradients of deep unrolling.
This layer does the same for items as rows (scikit-learn orientation):

* **Input** ``x`` ``[batch, n, d]``, non-negative (negative values are clamped to 0): ``n`` items per
  batch element, e.g. the clips of one sequence.
* **Dictionary** ``D`` ``[k, d]`` = ``softplus(raw)`` of a learned parameter (``learn_dictionary=True``)
  or a fixed buffer: always strictly positive, no clamping or projection needed in the optimiser.
  It is shared by all batch elements, so component ``c`` means the same "word" in every sequence.
* **Codes** ``C`` ``[batch, n, k]`` start from the constant ``1/k`` (``init="uniform"``: deterministic,
  no random op, ONNX-friendly) and take ``n_iter`` MU steps of the Frobenius loss ``||x − C D||²``:
  ``C ← C ∘ (x Dᵀ) / (C D Dᵀ + eps)`` (Lee & Seung), which keep ``C ≥ 0`` and never increase the loss.
* **Graph regularisation** (``graph_reg = λ > 0``, GNMF form of Cai et al. 2011): a symmetric 0/1 kNN
  graph ``S`` among the ``n`` items of each batch element, from the cosine similarity of ``x`` (top
  ``n_neighbors``, self excluded, built under ``no_grad``; masked and all-zero items get no edges),
  with degree ``Deg``; the update becomes
  ``C ← C ∘ (x Dᵀ + λ S C) / (C D Dᵀ + λ Deg C + eps)``.
* **Local dictionary** (``update_dictionary=True``, Hamburger's variant): each batch element also
  refines its own copy of ``D`` once per iteration, ``D_b ← D_b ∘ (Cᵀ x)/(Cᵀ C D_b + eps)``. Off by
  default: a bag of words needs one vocabulary shared by all sequences.
* **One-step gradient** (``one_step_grad=True``): iterations ``1 … n_iter − 1`` run under
  ``torch.no_grad()``; only the last one is in the autograd graph, so gradients reach ``D`` and ``x``
  through one MU step whatever ``n_iter`` is. ``one_step_grad=False`` back-propagates through all steps.
* **Masks**: ``forward(x, mask)`` with ``mask [batch, n]`` (bool) zeroes the codes of masked items
  and leaves them out of the graph, so padding items never change the others' codes.

All-zero inputs give all-zero codes (never NaN): the numerator is 0 and ``eps`` keeps the
denominator positive.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

INITS = ("uniform",)


class NMFLayer(nn.Module):
    """Non-negative codes ``[batch, n, k]`` of ``x [batch, n, d]`` by ``n_iter`` multiplicative updates.

    Args:
        in_features: ``d``.
        n_components: ``k``, the number of dictionary atoms (words).
        n_iter: MU steps per forward (≥ 1).
        learn_dictionary: the dictionary is a trained parameter (else a fixed buffer).
        one_step_grad: back-propagate through the last step only (Geng et al. 2021).
        graph_reg: ``λ`` of the kNN-graph (GNMF) term; 0 disables it.
        n_neighbors: kNN size of the graph (capped at ``n − 1``).
        eps: added to every MU denominator.
        init: code initialisation; ``"uniform"`` = the constant ``1/k``.
        update_dictionary: also refine a per-sample copy of the dictionary each step (Hamburger).
    """

    def __init__(
        self,
        in_features: int,
        n_components: int,
        n_iter: int = 10,
        learn_dictionary: bool = True,
        one_step_grad: bool = True,
        graph_reg: float = 0.0,
        n_neighbors: int = 5,
        eps: float = 1e-6,
        init: str = "uniform",
        update_dictionary: bool = False,
    ):
        super().__init__()
        if in_features < 1 or n_components < 1:
            raise ValueError(f"in_features and n_components must be positive, got {in_features}, {n_components}")
        if n_iter < 1:
            raise ValueError(f"n_iter must be at least 1, got {n_iter}")
        if graph_reg < 0:
            raise ValueError(f"graph_reg must be >= 0, got {graph_reg}")
        if n_neighbors < 1:
            raise ValueError(f"n_neighbors must be at least 1, got {n_neighbors}")
        if eps <= 0:
            raise ValueError(f"eps must be > 0, got {eps}")
        if init not in INITS:
            raise ValueError(f"unknown init {init!r}; choose from {INITS}")
        self.in_features, self.n_components = int(in_features), int(n_components)
        self.n_iter, self.one_step_grad = int(n_iter), bool(one_step_grad)
        self.graph_reg, self.n_neighbors = float(graph_reg), int(n_neighbors)
        self.eps, self.init, self.update_dictionary = float(eps), init, bool(update_dictionary)
        # softplus(raw) ~ U(0.1, 1): positive atoms of comparable norms
        atoms = torch.empty(self.n_components, self.in_features).uniform_(0.1, 1.0)
        raw = torch.log(torch.expm1(atoms))
        if learn_dictionary:
            self.raw_dictionary = nn.Parameter(raw)
        else:
            self.register_buffer("raw_dictionary", raw)

    # ------------------------------------------------------------------ pieces

    @property
    def dictionary(self) -> torch.Tensor:
        """The non-negative dictionary ``D`` ``[k, d]`` (softplus of the raw parameter)."""
        return F.softplus(self.raw_dictionary)

    @torch.no_grad()
    def set_dictionary(self, atoms: torch.Tensor) -> None:
        """Start from given atoms ``[k, d]`` (e.g. k-means centres or NMF components); values ≤ 0 become ``1e-4``."""
        atoms = torch.as_tensor(atoms, dtype=self.raw_dictionary.dtype)
        if atoms.shape != self.raw_dictionary.shape:
            raise ValueError(f"atoms must be [{self.n_components}, {self.in_features}], got {list(atoms.shape)}")
        self.raw_dictionary.copy_(torch.log(torch.expm1(atoms.clamp(min=1e-4))))

    @torch.no_grad()
    def knn_graph(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Symmetric 0/1 kNN graph ``[batch, n, n]`` of the items (cosine similarity, self excluded)."""
        b, n, _ = x.shape
        unit = x / x.norm(dim=-1, keepdim=True).clamp(min=self.eps)
        similarity = unit @ unit.transpose(1, 2)
        eye = torch.eye(n, dtype=torch.bool, device=x.device)
        similarity = similarity.masked_fill(eye, -2.0)
        # all-zero items have no direction: they get no neighbours (and so stay at zero codes)
        nonzero = x.abs().sum(-1) > 0
        mask = nonzero if mask is None else mask & nonzero
        similarity = similarity.masked_fill(~mask[:, None, :], -2.0)
        k = min(self.n_neighbors, n)
        index = similarity.topk(k, dim=-1).indices
        graph = torch.zeros_like(similarity).scatter(-1, index, 1.0)
        graph = graph.masked_fill(eye, 0.0)
        graph = graph * (mask[:, :, None] & mask[:, None, :]).to(graph.dtype)
        return torch.maximum(graph, graph.transpose(1, 2))

    def initial_codes(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """The deterministic starting codes ``[batch, n, k]``: ``1/k`` (zero for masked items)."""
        codes = torch.full_like(x[..., :1], 1.0 / self.n_components).expand(-1, -1, self.n_components)
        if mask is not None:
            codes = codes * mask[..., None].to(x.dtype)
        return codes

    def step(
        self, x: torch.Tensor, codes: torch.Tensor, dictionary: torch.Tensor, graph: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """One MU step: new ``(codes [b, n, k], dictionary)``; the dictionary is ``[k, d]`` or ``[b, k, d]``."""
        gram = dictionary @ dictionary.transpose(-1, -2)  # [(b,) k, k]
        numerator = x @ dictionary.transpose(-1, -2)  # [b, n, k]
        denominator = codes @ gram
        if graph is not None and self.graph_reg > 0:
            numerator = numerator + self.graph_reg * (graph @ codes)
            denominator = denominator + self.graph_reg * graph.sum(-1, keepdim=True) * codes
        codes = codes * numerator / (denominator + self.eps)
        if self.update_dictionary:
            if dictionary.dim() == 2:
                dictionary = dictionary.expand(x.shape[0], -1, -1)
            ct = codes.transpose(1, 2)  # [b, k, n]
            dictionary = dictionary * (ct @ x) / ((ct @ codes) @ dictionary + self.eps)
        return codes.clamp(min=0), dictionary

    def _prepare(self, x: torch.Tensor, mask: torch.Tensor | None):
        if x.dim() != 3 or x.shape[-1] != self.in_features:
            raise ValueError(f"NMFLayer expects x [batch, n, {self.in_features}], got {list(x.shape)}")
        x = x.clamp(min=0)
        if mask is not None:
            mask = mask.to(torch.bool)
            x = x * mask[..., None].to(x.dtype)
        graph = self.knn_graph(x, mask) if self.graph_reg > 0 else None
        return x, mask, graph

    # ------------------------------------------------------------------ forward

    def forward(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """Codes ``[batch, n, k]`` (≥ 0) of ``x [batch, n, d]``; ``mask [batch, n]`` marks real items.

        Always float32, also inside ``trainer.precision=bf16-mixed``: the multiplicative updates divide by sums
        of products that bfloat16's 8-bit mantissa would round (autocast is switched off here)."""
        with torch.autocast(x.device.type, enabled=False):
            return self._codes(x.float(), mask)

    def _codes(self, x: torch.Tensor, mask: torch.Tensor | None) -> torch.Tensor:
        x, mask, graph = self._prepare(x, mask)
        codes, dictionary = self.initial_codes(x, mask), self.dictionary
        if self.one_step_grad:
            with torch.no_grad():
                d = dictionary.detach()
                for _ in range(self.n_iter - 1):
                    codes, d = self.step(x.detach(), codes, d, graph)
            codes = codes.detach()
            if self.update_dictionary and d.dim() == 3:
                # the local copy's refinement is treated as a constant offset of the learned dictionary
                dictionary = dictionary + (d - dictionary).detach()
            codes, _ = self.step(x, codes, dictionary, graph)
            return codes
        for _ in range(self.n_iter):
            codes, dictionary = self.step(x, codes, dictionary, graph)
        return codes

    def reconstruction(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
        """``C D`` ``[batch, n, d]``: the layer's approximation of ``x`` (with the shared dictionary)."""
        return self(x, mask) @ self.dictionary

    @torch.no_grad()
    def reconstruction_errors(self, x: torch.Tensor, mask: torch.Tensor | None = None) -> list[float]:
        """``||x − C_t D||²_F`` after each step ``t = 0 … n_iter`` (shared dictionary; for checks and plots)."""
        x, mask, graph = self._prepare(x, mask)
        codes, dictionary = self.initial_codes(x, mask), self.dictionary
        errors = [float(((x - codes @ dictionary) ** 2).sum())]
        for _ in range(self.n_iter):
            codes, _ = self.step(x, codes, dictionary, graph)
            errors.append(float(((x - codes @ dictionary) ** 2).sum()))
        return errors

    def extra_repr(self) -> str:
        return (
            f"in_features={self.in_features}, n_components={self.n_components}, n_iter={self.n_iter}, "
            f"one_step_grad={self.one_step_grad}, graph_reg={self.graph_reg}, "
            f"update_dictionary={self.update_dictionary}"
        )
