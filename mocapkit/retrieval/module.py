"""Lightning module of the learned motion embeddings (:mod:`mocapkit.models.motion_encoder`) for retrieval.

Training batches come from :class:`~mocapkit.retrieval.datamodule.RetrievalDataModule` (two
augmented views of each clip, or of the clip and one of its DTW neighbours with ``data.positives=dtw_neighbours``,
and its label). Both views go through the encoder; the loss (``loss``) is

- ``supcon``: the supervised contrastive loss (Khosla et al., "Supervised contrastive learning", NeurIPS 2020,
  eq. 2, ``L_out``): every other view of the same class is a positive of an anchor;
- ``simclr``: NT-Xent (Chen et al., "A simple framework for contrastive learning of visual representations",
  ICML 2020): the other view of the same item is the only positive; labels are never used.

Both are :func:`~mocapkit.train.losses.contrastive_loss` (SimCLR is SupCon with each clip its own class), at ``temperature`` (0.1).

Validation and test are retrieval: the query clips' embeddings ranked against the database clips' by cosine
(the data module flags each clip; validation: the training groups' held-back clips against the training clips of
the *other* training groups, so checkpoint selection measures cross-performer retrieval as the test does; test:
the held-out groups against every training-group clip). Logged: ``<stage>/map`` (mean over queries of
scikit-learn's ``average_precision_score``), ``<stage>/p1`` (precision at 1), ``<stage>/loss`` (the supervised
contrastive loss of each query over the database clips it is ranked against, :func:`retrieval_loss`) and
``train/loss``. ``best.ckpt`` follows ``val/selection`` = ``val/map − 1e-4 · val/loss``: ``val/map``, with ties
broken by the lower loss. On HDM05, ``val/map`` reaches 1.0 within a few epochs and stays there (17 validation
clips of performers the network trains on), and the first epoch at 1.0 generalises worse to a new performer than
later ones (fold mm: mAP 0.92 against 0.98 at the last epoch): ties must not keep the first. A library without
labels (``data.dataset=folder``, files in one folder: every clip of one label) has nothing to rank by, and its
loss is lowest where the embedding has collapsed (every clip equally near): ``val/selection`` is then the epoch,
so ``best.ckpt`` is the last one. With ``data.positives=dtw_neighbours`` the validation queries also carry their
5 nearest database clips by DTW, and ``val/dtw_agreement`` (:func:`neighbour_agreement`) is the share of them the
embedding finds among its 5 nearest: ``module.selection=dtw_agreement`` selects by it, reading no label (with one
label, again the last epoch, which scored as well in the runs of docs/decisions.md#label-free-checkpoint-selection).
Every selection the data allows is logged as ``val/selection_by_<name>``.
:func:`evaluate_embedding` is the task's ``mocapkit eval`` (held-out groups; writes ``metrics.json``).
"""

from __future__ import annotations

import json
from pathlib import Path

import lightning as L
import numpy as np
import torch
from hydra.utils import instantiate

from mocapkit.train.losses import contrastive_loss
from mocapkit.train.optimization import (
    ConfiguredOptimization,
    StagedSteps,
    as_plain_dict,
)

LOSSES = ("supcon", "simclr")
SELECTIONS = ("map", "dtw_agreement")


def retrieval_scores(
    queries: np.ndarray,
    query_labels: np.ndarray,
    database: np.ndarray,
    database_labels: np.ndarray,
    query_groups: np.ndarray | None = None,
    database_groups: np.ndarray | None = None,
) -> dict:
    """``{"map", "p1", "n_queries"}`` of unit-norm ``queries`` ``[Q, D]`` ranked against ``database`` ``[N, D]`` by
    cosine. AP per query: ``sklearn.metrics.average_precision_score(db_labels == label, similarity)``. With groups,
    a query is ranked only against the database clips of *other* groups (cross-performer); queries without any
    relevant database clip are left out."""
    from sklearn.metrics import average_precision_score

    similarity = queries.astype(np.float64) @ database.astype(np.float64).T
    aps, hits = [], []
    for i in range(len(queries)):
        keep = np.ones(len(database), dtype=bool) if query_groups is None else database_groups != query_groups[i]
        relevant = database_labels[keep] == query_labels[i]
        if not relevant.any():
            continue
        scores = similarity[i, keep]
        aps.append(average_precision_score(relevant, scores))
        hits.append(float(relevant[np.argmax(scores)]))
    if not aps:
        return {"map": float("nan"), "p1": float("nan"), "n_queries": 0}
    return {"map": float(np.mean(aps)), "p1": float(np.mean(hits)), "n_queries": len(aps)}


def neighbour_agreement(
    queries: np.ndarray,
    database: np.ndarray,
    teacher: np.ndarray,
    query_groups: np.ndarray | None = None,
    database_groups: np.ndarray | None = None,
) -> float:
    """Mean over queries of the share of each query's ``teacher`` neighbours (database indices ``[Q, k]``, -1 for
    none) among its ``k`` nearest ``database`` clips by cosine of the unit-norm embeddings (with groups: among the
    other groups' clips, as :func:`retrieval_scores` ranks). No label is read; NaN without any teacher row."""
    similarity = queries.astype(np.float64) @ database.astype(np.float64).T
    if query_groups is not None:
        similarity[query_groups[:, None] == database_groups[None, :]] = -np.inf
    shares = []
    for i, row in enumerate(teacher):
        row = row[row >= 0]
        if len(row):
            nearest = np.argsort(-similarity[i], kind="stable")[: teacher.shape[1]]
            shares.append(len(np.intersect1d(nearest, row)) / len(row))
    return float(np.mean(shares)) if shares else float("nan")


def retrieval_loss(
    queries: torch.Tensor,
    query_labels: torch.Tensor,
    database: torch.Tensor,
    database_labels: torch.Tensor,
    temperature: float = 0.1,
    query_groups: torch.Tensor | None = None,
    database_groups: torch.Tensor | None = None,
) -> torch.Tensor:
    """The supervised contrastive loss of unit-norm ``queries`` over a ``database``: for each query, minus the mean
    log-softmax (over the database clips it is ranked against: those of other groups where groups are given) of its
    relevant clips, averaged over the queries that have one (0 when none has)."""
    logits = queries @ database.T / temperature
    if query_groups is not None:
        logits = logits.masked_fill(query_groups[:, None] == database_groups[None, :], float("-inf"))
    log_prob = logits - torch.logsumexp(logits, dim=1, keepdim=True)
    positives = (query_labels[:, None] == database_labels[None, :]) & torch.isfinite(logits)
    count = positives.sum(1)
    has = count > 0
    if not has.any():
        return queries.new_zeros(())
    return -(log_prob.masked_fill(~positives, 0.0).sum(1)[has] / count[has]).mean()


class MotionEmbeddingModule(ConfiguredOptimization, StagedSteps, L.LightningModule):
    """Trains a motion encoder (landmarks ``[B, T, 20, 3]`` → unit-norm embeddings ``[B, D]``) contrastively.

    Args:
        model: Hydra config of the network (:mod:`mocapkit.models.motion_encoder`).
        optimizer, scheduler: Hydra configs (``_partial_: true``), as the other modules.
        class_names: the data module's label space. source: how the training data was made (data set, label,
            groups, frames, fps, heading, landmark names), from the data module.
        loss: ``"supcon"`` or ``"simclr"``. temperature: of the softmax (0.1).
        selection: what ``best.ckpt`` follows (``val/selection``): ``"map"`` (``val/map``, ties by the lower
            ``val/loss``) or ``"dtw_agreement"`` (``val/dtw_agreement``, ties to the later epoch; no label read:
            needs ``data.positives=dtw_neighbours``); with one label either is the epoch.
    """

    def __init__(
        self,
        model: dict,
        optimizer: dict,
        scheduler: dict | None = None,
        class_names: list | None = None,
        source: dict | None = None,
        loss: str = "supcon",
        temperature: float = 0.1,
        selection: str = "map",
    ):
        super().__init__()
        if loss not in LOSSES:
            raise ValueError(f"module.loss={loss!r}: one of {list(LOSSES)}")
        if selection not in SELECTIONS:
            raise ValueError(f"module.selection={selection!r}: one of {list(SELECTIONS)}")
        if not float(temperature) > 0:
            raise ValueError(f"module.temperature={temperature}: must be positive")
        model, optimizer = as_plain_dict(model), as_plain_dict(optimizer)
        scheduler = as_plain_dict(scheduler) if scheduler is not None else None
        self.save_hyperparameters(
            {
                "model": model,
                "optimizer": optimizer,
                "scheduler": scheduler,
                "class_names": list(class_names or []),
                "source": as_plain_dict(source or {}),
                "loss": loss,
                "temperature": float(temperature),
                "selection": selection,
            }
        )
        self.model = instantiate(model)
        self._outputs: dict[str, list] = {}

    def forward(self, landmarks: torch.Tensor) -> torch.Tensor:
        return self.model(landmarks)

    def loss(self, batch: dict) -> torch.Tensor:
        """The configured contrastive loss of a training batch (both views)."""
        z = self.model(torch.cat((batch["landmarks"], batch["view2"])))
        if self.hparams.loss == "supcon":
            labels = batch["label"]
        else:
            labels = torch.arange(len(batch["landmarks"]), device=z.device)
        return contrastive_loss(z, labels.repeat(2), self.hparams.temperature)

    def _step(self, batch: dict, stage: str):
        if stage == "train":
            loss = self.loss(batch)
            self.log("train/loss", loss, on_step=True, on_epoch=True, prog_bar=True, batch_size=len(batch["label"]))
            return loss
        z = self.model(batch["landmarks"])
        self._outputs.setdefault(stage, []).append(
            # float32 whatever the training precision: embeddings are ranked (and ONNX exports them) in float32
            {
                "z": z.detach().float().cpu(),
                **{k: batch[k].detach().cpu() for k in ("label", "group", "query", "teacher") if k in batch},
            }
        )
        return None

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        embedding = self.model(batch["landmarks"]).float()
        return {"embedding": embedding, **{k: batch[k] for k in ("label", "group", "query")}}

    def _retrieval_epoch_end(self, stage: str) -> None:
        outputs = self._outputs.pop(stage, [])
        if not outputs:
            return
        out = {k: torch.cat([o[k] for o in outputs]).numpy() for k in outputs[0]}
        q, d = out["query"], ~out["query"]
        # validation: cross-performer (only the database clips of the other training groups) where there are some
        groups = stage == "val" and len(np.unique(out["group"][d])) > 1
        qg, dg = (out["group"][q], out["group"][d]) if groups else (None, None)
        scores = retrieval_scores(out["z"][q], out["label"][q], out["z"][d], out["label"][d], qg, dg)
        if scores["n_queries"] == 0:  # no query class in the database: nothing to rank
            scores = {"map": 0.0, "p1": 0.0}

        def tensor(a):
            return None if a is None else torch.from_numpy(a)

        loss = float(
            retrieval_loss(
                tensor(out["z"][q]),
                tensor(out["label"][q]),
                tensor(out["z"][d]),
                tensor(out["label"][d]),
                self.hparams.temperature,
                tensor(qg),
                tensor(dg),
            )
        )
        self.log(f"{stage}/map", scores["map"], prog_bar=True, sync_dist=True)
        self.log(f"{stage}/p1", scores["p1"], prog_bar=True, sync_dist=True)
        self.log(f"{stage}/loss", loss, sync_dist=True)
        if "teacher" in out:
            # the teacher rows index the whole validation set; the ranking indexes its database part
            teacher = out["teacher"][q]
            teacher = np.where(teacher >= 0, teacher - int(q.sum()), -1)
            agreement = neighbour_agreement(out["z"][q], out["z"][d], teacher, qg, dg)
            self.log(f"{stage}/dtw_agreement", agreement, prog_bar=True, sync_dist=True)
        if stage == "val":
            # every selection the data allows is logged (a second checkpoint callback can follow another one)
            one_label = len(np.unique(out["label"])) == 1
            by = {"map": float(self.current_epoch) if one_label else scores["map"] - 1e-4 * loss}
            if "teacher" in out:  # ties to the later epoch; with one label the epoch itself, as for map
                by["dtw_agreement"] = float(self.current_epoch) if one_label else agreement + 1e-6 * self.current_epoch
            for name, value in by.items():
                self.log(f"val/selection_by_{name}", value, sync_dist=True)
            if self.hparams.selection not in by:
                raise ValueError(
                    "module.selection=dtw_agreement needs the validation clips' DTW neighbours: "
                    "data.positives=dtw_neighbours"
                )
            self.log("val/selection", by[self.hparams.selection], sync_dist=True)

    def on_validation_epoch_end(self) -> None:
        self._retrieval_epoch_end("val")

    def on_test_epoch_end(self) -> None:
        self._retrieval_epoch_end("test")


def evaluate_embedding(module, datamodule, cfg, out_dir: Path) -> dict:
    """``mocapkit eval`` of an embedding run: the ``eval.part`` queries (``test``: the held-out groups' clips;
    ``val``: the validation clips) ranked against their database (module docstring); writes ``metrics.json``."""
    from mocapkit.evaluation.evaluate import predict_outputs
    from mocapkit.io_atomic import atomic_write_text

    part = cfg.eval.part
    loader = datamodule.test_dataloader() if part == "test" else datamodule.val_dataloader()
    out = predict_outputs(module, loader, cfg)
    q, d = out["query"], ~out["query"]
    names = module.hparams.class_names
    report = {
        "part": part,
        "loss": module.hparams.loss,
        **datamodule.describe(),
        **retrieval_scores(out["embedding"][q], out["label"][q], out["embedding"][d], out["label"][d]),
    }
    per_class = {}
    for c in np.unique(out["label"][q]):
        sel = q & (out["label"] == c)
        per_class[names[c] if c < len(names) else str(c)] = retrieval_scores(
            out["embedding"][sel], out["label"][sel], out["embedding"][d], out["label"][d]
        )
    report["per_class"] = per_class
    atomic_write_text(out_dir / "metrics.json", json.dumps(report, indent=2))
    print(
        f"[mocapkit] {cfg.get('experiment_name', 'embedding')} {part} ({report['split']}): "
        f"mAP {report['map']:.3f}, P@1 {report['p1']:.3f} over {report['n_queries']} queries"
    )
    print(f"[mocapkit] wrote {out_dir / 'metrics.json'}")
    return report


__all__ = ["LOSSES", "MotionEmbeddingModule", "evaluate_embedding", "retrieval_loss", "retrieval_scores"]
