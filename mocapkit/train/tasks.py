"""What ``mocapkit train | eval | export`` do for each kind of task (the config's ``task`` key).

A task names three things, as dotted paths so that only the chosen task's code is imported:

``module``
    the LightningModule class; ``module.from_config(cfg, datamodule)`` builds it for training and
    ``module.load_from_checkpoint(path)`` restores it. Every module logs ``val/acc`` (its headline
    accuracy), which picks ``best.ckpt``.
``evaluate``
    ``evaluate(module, datamodule, cfg, out_dir) -> report dict``: predictions on the held-out part,
    metrics, tables and plots written under ``out_dir``.
``export``
    ``export(module, target, export_cfg) -> parity report``: the ONNX file and its onnxruntime check.

=========  ==================================================  ===============================
task       input → output                                      experiments
=========  ==================================================  ===============================
action     skeletons ``[B, M, T, J, 3]`` → action logits       ntu_*, msr3d_* (incl. the NMF layer)
gait       GEIs ``[B, 1, H, W]`` → subject / view / condition  casiab_multitask, casiab_single_subject
           logits and an embedding
=========  ==================================================  ===============================
"""
from __future__ import annotations

from dataclasses import dataclass

from hydra.utils import get_class, get_method

from mocapkit.train.config import ConfigError


@dataclass(frozen=True)
class Task:
    module: str
    evaluate: str
    export: str

    def module_class(self):
        return get_class(self.module)

    def evaluate_fn(self):
        return get_method(self.evaluate)

    def export_fn(self):
        return get_method(self.export)


TASKS: dict[str, Task] = {
    "action": Task(module="mocapkit.train.action_module.ActionRecognitionModule",
                   evaluate="mocapkit.evaluation.evaluate.evaluate_action",
                   export="mocapkit.deploy.export.export_action_module"),
    "gait": Task(module="mocapkit.train.gait_module.GaitRecognitionModule",
                 evaluate="mocapkit.evaluation.evaluate_gait.evaluate_gait",
                 export="mocapkit.deploy.gait_export.export_gait_module"),
}


def get_task(name: str) -> Task:
    """The task called ``name`` (the config's ``task`` key)."""
    if name not in TASKS:
        raise ConfigError(f"task={name!r}: unknown task; known: {', '.join(TASKS)}")
    return TASKS[name]
