"""evaluate_gait with a module whose answers are known, the gait comparison's side-by-side tables, and
`mocapkit gait-report` (an alias of `mocapkit compare gait`) end to end."""

from __future__ import annotations

import json

import lightning as L
import pytest
import torch
import torch.nn.functional as F
from omegaconf import OmegaConf

from mocapkit.datasets.formats.casia_b import VIEWS
from mocapkit.gait.benchmark import GaitBenchmark, closed_set_table, cross_subject_tables, per_view_panels
from mocapkit.gait.evaluate import evaluate_gait
from mocapkit.gait.gei_pca_lda import GEIPCALDA
from tests.gait.test_gei_pca_lda import make_tiny_gei_cache

CFG = OmegaConf.create({"trainer": {"accelerator": "cpu", "enable_progress_bar": False}, "experiment_name": "oracle"})


class OracleGaitModule(L.LightningModule):
    """Answers from the batch's labels: the subject is always right except at 90°, the view always,
    the condition never; the embedding is the one-hot subject ID (every rank-1 match is right)."""

    def __init__(self, num_subjects: int):
        super().__init__()
        self.num_subjects = num_subjects

    def predict_step(self, batch: dict, batch_idx: int) -> dict:
        subjects = batch["subjects"].clamp(min=0)
        wrong_at_90 = torch.where(batch["views"] == VIEWS.index(90), (subjects + 1) % self.num_subjects, subjects)
        return {
            "embedding": F.one_hot(batch["subject_ids"], 32).float(),
            "subject_logits": F.one_hot(wrong_at_90, self.num_subjects).float(),
            "view_logits": F.one_hot(batch["views"], 11).float(),
            "condition_logits": F.one_hot((batch["conditions"] + 1) % 3, 3).float(),
            **{k: batch[k] for k in ("subjects", "subject_ids", "views", "conditions", "sequences", "indices")},
        }


@pytest.fixture(scope="module")
def tiny_cache(tmp_path_factory):
    return make_tiny_gei_cache(tmp_path_factory.mktemp("gei") / "cache", num_subjects=6, height=24, width=16)


def _datamodule(cache, protocol):
    from mocapkit.datasets.casia_b.datamodule import GaitDataModule

    return GaitDataModule(str(cache.root), protocol=protocol, val_fraction=0.1, eval_batch_size=64)


def test_evaluate_gait_closed_set_writes_the_table(tiny_cache, tmp_path):
    datamodule = _datamodule(tiny_cache, "closed_set")
    report = evaluate_gait(OracleGaitModule(datamodule.num_subjects), datamodule, CFG, tmp_path, ckpt_path="x.ckpt")
    closed = report["closed_set"]
    assert report["checkpoint"] == "x.ckpt" and report["protocol"] == "closed_set"
    assert report["tasks"] == ["subject", "view", "condition"]
    assert closed["num_geis"] == datamodule.sample_counts()["test"] == 6 * 11 * 3
    subject = closed["tasks"]["subject"]
    assert subject["per_view"]["90"] == 0.0 and subject["per_view"]["0"] == 1.0
    assert subject["accuracy"] == pytest.approx(10 / 11)
    assert closed["tasks"]["view"]["accuracy"] == 1.0 and closed["tasks"]["condition"]["accuracy"] == 0.0
    saved = json.loads((tmp_path / "metrics.json").read_text())
    assert saved["closed_set"] == closed and saved["test_subjects"] == [1, 2, 3, 4, 5, 6]
    assert "| 90° | 0.00 | 100.00 | 0.00 |" in (tmp_path / "summary.md").read_text()
    assert (tmp_path / "per_view.png").stat().st_size > 1000


def test_evaluate_gait_cross_subject_ranks_embeddings(tiny_cache, tmp_path):
    datamodule = _datamodule(tiny_cache, "cross_subject")
    report = evaluate_gait(OracleGaitModule(datamodule.num_subjects), datamodule, CFG, tmp_path)
    assert "checkpoint" not in report and report["test_subjects"] == [5, 6]
    cross = report["cross_view"]
    assert cross["metric"] == "euc" and cross["aggregate"] == "sequence"
    assert all(cross["conditions"][c]["mean"] == 1.0 for c in ("nm", "bg", "cl"))
    assert cross["conditions"]["nm"]["num_probes"] == 2 * 2 * 11
    unseen = report["view_condition_on_test_subjects"]
    assert set(unseen["tasks"]) == {"view", "condition"} and unseen["tasks"]["view"]["accuracy"] == 1.0
    summary = (tmp_path / "summary.md").read_text()
    assert "| NM | " + " | ".join(["100.00"] * 11) + " | 100.00 | 100.00 | 0/121 |" in summary


def test_report_tables_side_by_side(tiny_cache, tmp_path):
    closed_dm, cross_dm = _datamodule(tiny_cache, "closed_set"), _datamodule(tiny_cache, "cross_subject")
    benchmark = GaitBenchmark(str(tiny_cache.root))
    oracle_closed = evaluate_gait(OracleGaitModule(closed_dm.num_subjects), closed_dm, CFG, tmp_path / "a")
    oracle_cross = evaluate_gait(OracleGaitModule(cross_dm.num_subjects), cross_dm, CFG, tmp_path / "b")
    pca_closed = benchmark.evaluate_estimator(GEIPCALDA(), benchmark.split("closed_set", 0))["detail"]
    pca_cross = benchmark.evaluate_estimator(GEIPCALDA(), benchmark.split("cross_subject", 0))["detail"]
    text = closed_set_table({"multi-task CNN": oracle_closed["closed_set"], "GEI+PCA+LDA": pca_closed["closed_set"]})
    header = next(line for line in text.splitlines() if line.startswith("| Probe | multi-task CNN: identify subject"))
    assert header.split(" | ")[1:5] == [
        "multi-task CNN: identify subject",
        "multi-task CNN: predict view",
        "multi-task CNN: predict condition",
        "GEI+PCA+LDA: identify subject",
    ]
    assert "| 90° | 0.00 | 100.00 | 0.00 | " in text and "| 95.80 | 99.63 | 97.11 |" in text
    text = cross_subject_tables({"multi-task CNN": oracle_cross["cross_view"], "GEI+PCA+LDA": pca_cross["cross_view"]})
    assert "| NM | 100.00 | " in text and "| 89.9 | 95.8 | 90.5 |" in text
    cells = [
        {"protocol": "closed_set", "label": "multi-task CNN", "detail": oracle_closed},
        {"protocol": "closed_set", "label": "GEI+PCA+LDA", "detail": pca_closed},
        {"protocol": "cross_subject", "label": "multi-task CNN", "detail": oracle_cross},
    ]
    panels = per_view_panels({"protocols": ["closed_set", "cross_subject"], "cells": cells})
    assert list(panels["closed set: subject accuracy per view"]) == ["multi-task CNN", "GEI+PCA+LDA"]
    assert panels["closed set: subject accuracy per view"]["multi-task CNN"]["90"] == 0.0
    assert list(panels["cross subject: NM rank-1 per probe view (identical view excluded)"]) == ["multi-task CNN"]


@pytest.mark.slow
def test_gait_report_end_to_end(tmp_path):
    """`mocapkit gait-report` = `compare gait`: the multi-task CNN (1 epoch) and GEI+PCA+LDA under both protocols on
    a tiny 64×44 cache (OpenGait's size, the smallest Table 6.1's trunk takes), with the old options."""
    from mocapkit.cli import main as cli

    cache = make_tiny_gei_cache(tmp_path / "cache", num_subjects=4, height=64, width=44)
    out = tmp_path / "report"
    assert (
        cli(
            [
                "gait-report",
                "--data",
                str(cache.root),
                "--out",
                str(out),
                "--seed",
                "1",
                "--experiments",
                "casiab_multitask",
                "--",
                "trainer.max_epochs=1",
                "trainer.enable_progress_bar=false",
                "trainer.accelerator=cpu",
                "data.batch_size=16",
                "data.holdout_seed=2",
            ]
        )
        == 0
    )
    result = json.loads((out / "results.json").read_text())
    assert result["seeds"] == [1] and result["benchmark"]["holdout_seed"] == 2  # the split follows the override
    for protocol in ("closed_set", "cross_subject"):
        cells = {c["method"]: c for c in result["cells"] if c["protocol"] == protocol}
        assert list(cells) == ["casiab_multitask", "gei_pca_lda"]
        assert len({c["test_sha1"] for c in cells.values()}) == 1
    multi = next(c for c in result["cells"] if c["method"] == "casiab_multitask" and c["protocol"] == "closed_set")
    assert set(multi["detail"]["closed_set"]["tasks"]) == {"subject", "view", "condition"}
    assert multi["detail"]["checkpoint"].endswith("best.ckpt") and multi["max_epochs"] == 1
    assert "data.holdout_seed=2" in multi["overrides"]
    cross = next(c for c in result["cells"] if c["method"] == "casiab_multitask" and c["protocol"] == "cross_subject")
    nm = cross["detail"]["cross_view"]["conditions"]["nm"]
    assert nm["missing_cells"] == [] and 0.0 <= nm["mean"] <= 1.0
    text = (out / "results.md").read_text()
    assert "### closed_set" in text and "### cross_subject" in text and "multi-task CNN: predict view" in text
    assert "Closed set (thesis Table 6.2 protocol)" in text and "Cross subject (OpenGait protocol)" in text
    assert (out / "per_view.png").stat().st_size > 1000
    assert (out / "runs" / "casiab_multitask" / "casiab_multitask_closed_set_seed1" / "eval" / "metrics.json").is_file()
    # --no-pca-lda and --protocols / --experiments select cells
    assert (
        cli(
            [
                "gait-report",
                "--data",
                str(cache.root),
                "--out",
                str(tmp_path / "small"),
                "trainer.max_epochs=1",
                "--no-pca-lda",
                "--protocols",
                "closed_set",
                "--experiments",
                "casiab_single_subject",
            ]
        )
        == 0
    )
    small = json.loads((tmp_path / "small" / "results.json").read_text())
    assert [(c["method"], c["protocol"]) for c in small["cells"]] == [("casiab_single_subject", "closed_set")]
    assert list(small["cells"][0]["detail"]["closed_set"]["tasks"]) == ["subject"]
