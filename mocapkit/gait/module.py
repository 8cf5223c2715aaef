"""Lightning module for gait recognition from GEIs: the joint multi-task loss of thesis §6.1.

The loss is ``Σ_task weight_task · CE(logits_task, label_task)`` over the tasks the model has
(subject, view, condition; equal weights by default; the thesis gives no weights). Batches come from
:class:`~mocapkit.datasets.casia_b.datamodule.GaitDataModule`. Samples whose subject label is -1
(test subjects of the cross-subject protocol, outside the label space) add nothing to the subject
loss or accuracy. The network, optimiser and schedule are Hydra configs stored in the checkpoint's
hyper-parameters, so ``GaitRecognitionModule.load_from_checkpoint(path)`` rebuilds the exact model.

With ``metric_weight > 0`` the loss adds ``metric_weight ·`` the supervised contrastive loss
(:func:`~mocapkit.train.losses.contrastive_loss`, temperature ``temperature``) of the unit-normalised shared
embedding over the labelled subjects of the batch: the embedding that cross-subject evaluation ranks unseen people
by is then trained to put one person's GEIs together, not only to feed the classifier (OpenGait's GEI networks
train a metric loss for this reason). Batches with several GEIs per subject make it bite: the data module's
``subjects_per_batch``.

Logged: ``{stage}/loss`` (the joint loss), ``{stage}/{task}_loss``, ``{stage}/metric_loss`` (with a metric
term), ``{stage}/acc`` (subject accuracy, the checkpoint monitor; the first task's accuracy for a model without a
subject head), ``{stage}/view_acc`` and ``{stage}/condition_acc`` when those tasks exist.
The accuracies are ``torchmetrics`` metric objects (``ignore_index=-1``), one per stage and name,
logged as objects: Lightning accumulates them over the epoch, synchronises them across processes
(DDP) and resets them, so ``val/acc`` is the accuracy over the whole validation set. Losses are
logged with ``sync_dist=True``.
"""

from __future__ import annotations

import lightning as L
import torch
import torch.nn.functional as F
from hydra.utils import instantiate
from torch import nn
from torchmetrics.classification import MulticlassAccuracy

from mocapkit.train.losses import contrastive_loss
from mocapkit.train.optimization import (
    ConfiguredOptimization,
    StagedSteps,
    as_plain_dict,
)

#: The batch key holding each task's labels.
TASK_LABELS = {"subject": "subjects", "view": "views", "condition": "conditions"}
#: Batch keys copied into every ``predict_step`` output.
PREDICT_KEYS = ("subjects", "subject_ids", "views", "conditions", "sequences", "indices")
#: Stages with their own accuracy metrics (each is accumulated, synchronised and reset per epoch).
STAGES = ("train", "val", "test")


class GaitRecognitionModule(ConfiguredOptimization, StagedSteps, L.LightningModule):
    """Joint cross-entropy training of a multi-task gait network (GEIs ``[B, 1, H, W]`` → ``{task: logits}``).

    Args:
        model: Hydra config of the network; ``num_subjects``, ``num_views``, ``num_conditions`` and
            ``input_size`` are passed at instantiation. The network returns a dict with a logits tensor
            per task in ``model.tasks`` and ``"embedding"``.
        optimizer: Hydra config of a ``torch.optim`` optimiser with ``_partial_: true``.
        num_subjects, num_views, num_conditions: classes of the subject, view and condition tasks.
        scheduler: Hydra config of a ``torch.optim.lr_scheduler`` with ``_partial_: true``, or None.
        task_weights: task → loss weight (default 1 for every task of the model); weights of tasks the
            model lacks are ignored.
        subject_names: the subject label space for reports and ONNX metadata (e.g. ``["001", ...]``).
        label_smoothing: cross-entropy label smoothing (all tasks).
        input_size: ``(H, W)`` of the GEIs.
        metric_weight: weight of the supervised contrastive term on the embedding (0: off, the thesis's loss).
        temperature: its temperature.
    """

    def __init__(
        self,
        model: dict,
        optimizer: dict,
        num_subjects: int,
        num_views: int,
        num_conditions: int,
        scheduler: dict | None = None,
        task_weights: dict | None = None,
        subject_names: list[str] | None = None,
        label_smoothing: float = 0.0,
        input_size: tuple[int, int] | list[int] = (124, 124),
        metric_weight: float = 0.0,
        temperature: float = 0.1,
    ):
        super().__init__()
        model, optimizer = as_plain_dict(model), as_plain_dict(optimizer)
        scheduler = as_plain_dict(scheduler) if scheduler else None
        task_weights = as_plain_dict(task_weights) if task_weights is not None else None
        unknown = sorted(set(task_weights or {}) - set(TASK_LABELS))
        if unknown:
            raise ValueError(f"task_weights: unknown tasks {unknown}; tasks are {list(TASK_LABELS)}")
        self.save_hyperparameters(
            {
                "model": model,
                "optimizer": optimizer,
                "scheduler": scheduler,
                "num_subjects": num_subjects,
                "num_views": num_views,
                "num_conditions": num_conditions,
                "task_weights": task_weights,
                "subject_names": list(subject_names) if subject_names is not None else None,
                "label_smoothing": label_smoothing,
                "input_size": list(input_size),
                "metric_weight": float(metric_weight),
                "temperature": float(temperature),
            }
        )
        if metric_weight < 0 or temperature <= 0:
            raise ValueError(
                f"module.metric_weight must be >= 0 and module.temperature > 0, got {metric_weight} and {temperature}"
            )
        self.model = instantiate(
            model,
            num_subjects=num_subjects,
            num_views=num_views,
            num_conditions=num_conditions,
            input_size=list(input_size),
        )
        self.tasks: tuple[str, ...] = tuple(self.model.tasks)
        self.task_weights = {t: float((task_weights or {}).get(t, 1.0)) for t in self.tasks}
        #: the task whose accuracy is logged as ``acc`` (the checkpoint monitor): subject when the model has it
        self.primary_task = "subject" if "subject" in self.tasks else self.tasks[0]
        #: logged accuracy name → its task: ``acc`` (the primary task), ``view_acc``, ``condition_acc``
        self.metric_tasks: dict[str, str] = {name: task for task, name in self._accuracy_names()}
        classes = {"subject": num_subjects, "view": num_views, "condition": num_conditions}
        #: ``<stage>_<name>`` → top-1 accuracy over the epoch (micro; samples labelled -1 are left out).
        #: (Not keyed by stage alone: ``train`` is taken by ``nn.Module.train``.)
        self.accuracy = nn.ModuleDict(
            {
                f"{stage}_{name}": MulticlassAccuracy(int(classes[task]), average="micro", ignore_index=-1)
                for stage in STAGES
                for name, task in self.metric_tasks.items()
            }
        )

    def _accuracy_names(self) -> list[tuple[str, str]]:
        """``(task, logged name)`` pairs: ``acc`` for the primary task, ``<task>_acc`` for view and condition."""
        pairs = []
        for task in self.tasks:
            names = ["acc"] if task == "subject" else [f"{task}_acc"] + (["acc"] if task == self.primary_task else [])
            pairs += [(task, name) for name in names]
        return pairs

    def forward(self, geis: torch.Tensor) -> dict[str, torch.Tensor]:
        return self.model(geis)

    def task_losses(self, outputs: dict[str, torch.Tensor], batch: dict) -> dict[str, torch.Tensor]:
        """Cross-entropy per task; the subject loss skips samples labelled -1 (absent when all are); with
        ``metric_weight``, ``"metric"``: the contrastive loss of the labelled subjects' embeddings."""
        losses = {}
        if self.hparams.metric_weight > 0:
            known = batch["subjects"] >= 0
            if bool(known.any()):
                embedding = F.normalize(outputs["embedding"][known], dim=1)
                losses["metric"] = contrastive_loss(embedding, batch["subjects"][known], self.hparams.temperature)
        for task in self.tasks:
            labels = batch[TASK_LABELS[task]]
            known = labels >= 0
            if not bool(known.any()):
                continue
            losses[task] = F.cross_entropy(
                outputs[task][known], labels[known], label_smoothing=self.hparams.label_smoothing
            )
        return losses

    def joint_loss(self, losses: dict[str, torch.Tensor]) -> torch.Tensor:
        """``Σ weight_task · loss_task`` over the tasks present in ``losses`` (the metric term: ``metric_weight``)."""
        weights = {**self.task_weights, "metric": self.hparams.metric_weight}
        return sum(weights[task] * loss for task, loss in losses.items())

    def _step(self, batch: dict, stage: str) -> torch.Tensor | None:
        outputs = self(batch["geis"])
        losses = self.task_losses(outputs, batch)
        if not losses:  # nothing labelled, e.g. a cross-subject test batch of a subject-only model
            return None
        loss = self.joint_loss(losses)
        on_step, size = stage == "train", len(batch["geis"])
        self.log(f"{stage}/loss", loss, on_step=on_step, on_epoch=True, prog_bar=True, batch_size=size, sync_dist=True)
        for task, task_loss in losses.items():
            self.log(f"{stage}/{task}_loss", task_loss, on_step=False, on_epoch=True, batch_size=size, sync_dist=True)
        for name, task in self.metric_tasks.items():
            if task not in losses:  # no labelled sample of this task in the batch
                continue
            metric = self.accuracy[f"{stage}_{name}"]
            metric.update(outputs[task].detach(), batch[TASK_LABELS[task]])
            self.log(f"{stage}/{name}", metric, on_step=False, on_epoch=True, prog_bar=name == "acc")
        return loss

    def training_step(self, batch: dict, batch_idx: int) -> torch.Tensor:
        loss = self._step(batch, "train")
        if loss is None:
            raise ValueError("a training batch has no labelled sample: training needs subject labels ≥ 0")
        return loss

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        """``{"embedding": [B, 512], "<task>_logits": ..., and the batch's subjects, subject_ids, views,
        conditions, sequences, indices}`` — what the gait evaluation consumes."""
        outputs = self(batch["geis"])
        result = {"embedding": outputs["embedding"]}
        result.update({f"{task}_logits": outputs[task] for task in self.tasks})
        result.update({key: batch[key] for key in PREDICT_KEYS})
        return result
