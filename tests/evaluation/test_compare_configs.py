"""Every `mocapkit compare NAME` config composes, its method table parses, and every estimator builds (with its
params set) — no data read, nothing fitted. The estimators come from the method registry
(configs/<task>/method/NAME.yaml, through the defaults list into ``templates``), never repeated inline."""

from __future__ import annotations

import re

import pytest
from hydra.utils import instantiate
from omegaconf import OmegaConf

from mocapkit.evaluation.compare.runner import compose, parse_methods
from mocapkit.train.config import CONFIG_DIR
from mocapkit.train.registry import TASKS, describe, method_config

COMPARISONS = sorted(p.stem for p in (CONFIG_DIR / "compare").glob("*.yaml"))


@pytest.mark.parametrize("name", COMPARISONS)
def test_every_comparison_composes_and_builds_its_estimators(name):
    cfg = compose([name])
    assert cfg.name == name
    plain = OmegaConf.to_container(cfg, resolve=True)
    methods = parse_methods(plain["methods"])
    assert methods
    for key, method in methods.items():
        if method.kind != "estimator":
            continue
        estimator = instantiate(method.spec)
        if method.params:
            estimator.set_params(**method.params)
        assert hasattr(estimator, "get_params"), key


def test_comparisons_do_not_repeat_registry_entries():
    """An inline ``_target_`` in configs/compare/ may name a registered class only where the entry has a required
    parameter the comparison gives (the trained checkpoints of LearnedRefiner, EmbeddingRetrieval)."""
    complete = {}
    for row in describe():
        node = OmegaConf.to_container(method_config(row.task, row.name))
        if "_target_" in node and "???" not in node.values():
            complete[node["_target_"]] = f"{row.task}/{row.name}"
    assert set(TASKS) >= {row.task for row in describe()}
    for path in sorted((CONFIG_DIR / "compare").glob("*.yaml")):
        for target in re.findall(r"_target_:\s*([\w.]+)", path.read_text()):
            assert target not in complete, f"{path.name} repeats {target}: use the registry's {complete[target]}"
