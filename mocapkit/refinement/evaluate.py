"""``mocapkit eval ckpt_path=RUN/best.ckpt`` for a learned refiner run: the refinement benchmark's table.

The run's checkpoint joins the classical refiners of ``configs/compare/<eval.compare>.yaml`` (default
``refine_<data.dataset>``) as the method ``learned``, on the run's data folder with the run's **held-out groups**
as the folds: the same protocols, corruption seeds, test clips and metrics as ``mocapkit compare``
(:class:`~mocapkit.refinement.benchmark.RefinementBenchmark`); data-driven classical methods are fitted
on the other groups, which are the groups the run trained on (the learned refiner's ``fit`` checks that).
Writes ``results.json``, ``results.md`` and the plots to ``<run>/eval`` (or ``eval.out_dir``).
"""

from __future__ import annotations

from pathlib import Path

from omegaconf import DictConfig

from mocapkit.train.config import ConfigError


def evaluate_refinement(module, datamodule, cfg: DictConfig, out_dir: Path) -> dict:
    """Run the comparison with the run's checkpoint as method ``learned``; return a summary for the report."""
    from mocapkit.evaluation.compare.runner import compose, run_comparison

    if not cfg.get("ckpt_path"):
        raise ConfigError("evaluate_refinement: ckpt_path is not set")
    name = cfg.eval.get("compare") or f"refine_{cfg.data.dataset}"
    groups = datamodule.groups["test"]
    if not groups:
        raise ConfigError("the run holds out no group (data.test_groups): nothing to evaluate on")
    label = f"learned ({cfg.get('experiment_name', 'refiner')})"
    overrides = [
        name,
        f"benchmark.root={cfg.data.root}",
        f"benchmark.held_out=[{','.join(groups)}]",
        f"out={out_dir}",
        (
            f"+methods.learned={{label: '{label}', reseed: false, estimator: {{_target_: "
            f"mocapkit.refinement.learned.LearnedRefiner, checkpoint: '{Path(cfg.ckpt_path)}'}}}}"
        ),
        *[str(o) for o in cfg.eval.get("overrides") or []],
    ]
    results = run_comparison(compose(overrides))
    summary = results["summary"]
    return {"comparison": name, "held_out": groups, "out_dir": str(out_dir), "summary": summary}
