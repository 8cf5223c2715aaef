"""One comparison runner: a table of methods × protocols × seeds on one benchmark, the same splits and metrics.

``mocapkit compare NAME [Hydra overrides ...]`` composes ``configs/compare.yaml`` with ``configs/compare/NAME.yaml``
(:func:`main`), runs every cell and writes into ``out``::

    results.json   every cell (metrics, detail report, test-set fingerprint, time, run folder or parameters),
                   the splits (test indices per protocol and seed), the selection, the resolved config, the machine
    results.md     mean ± sd over seeds per method × protocol, the benchmark's detail tables, every cell
    summary.png    the first headline metric per method and protocol (mean ± sd); plus the benchmark's plots
    runs/          the learned runs: runs/<experiment_name>/<method>_<protocol>_seed<seed>/ (checkpoints, eval/)

Configuration schema (``configs/compare.yaml``; a comparison file sets the keys)::

    name: gait                         # names the output folder (out: checkpoints/compare/${name})
    benchmark: {_target_: mocapkit.gait.benchmark.GaitBenchmark, root: ..., ...}
    protocols: [closed_set, cross_subject]
    seeds: [0, 1, 2]
    methods:                           # KEY → one of:
      cnn:   {label: ..., learned: {experiment: casiab_multitask, overrides: [trainer.max_epochs=80],
                                    checkpoint: best,    # best (best val/acc) | last (the last epoch)
                                    eval_overrides: []}} # for `mocapkit eval` only, e.g. ['eval.views={...}']
      pca:   {label: ..., estimator: {_target_: mocapkit.gait.gei_pca_lda.GEIPCALDA, n_pca: null},
              params: {...},           # set_params after instantiation (nested names: step__param)
              select: {stages: [{bow__clusterer__n_components: [100, 200]}, ...], cv: 3}   # or {reuse: KEY}
              reseed: true}            # set every (nested) random_state to the cell's seed (default)
    only: null                         # run only these method keys
    learned_overrides: []              # Hydra overrides for every learned run, e.g. ['trainer.max_epochs=2']
    templates: {}                      # estimator specs that methods interpolate: estimator: ${templates.X}

A **learned** method is trained with :func:`mocapkit.train.training.train` on
``experiment=<NAME>`` + the benchmark's :meth:`~Benchmark.learned_overrides` + ``seed``, ``output_root``,
``run_name`` + its ``overrides`` + ``learned_overrides``, and its ``best.ckpt`` (or ``last.ckpt`` with
``checkpoint: last``, e.g. for runs without a validation part) is scored with
:func:`mocapkit.evaluation.evaluate.evaluate` and its ``eval_overrides``. Learned methods whose training overrides
are equal (they differ only in ``checkpoint`` or ``eval_overrides``) share one run per cell: the first trains
it, the others score it (``shared_run`` in results.json), so "the same model with test-time augmentation" costs no
second training. The runner rebuilds the run's data module and fails unless it
tested exactly the benchmark's test samples. An **estimator** is instantiated fresh per cell, fitted on the
training side and scored by the benchmark's :meth:`~Benchmark.evaluate_estimator`, with the same metric code.
``select`` chooses hyper-parameters by cross-validation on the first seed's training side (see
:meth:`~mocapkit.evaluation.compare.runner.Comparison.selected`).

Benchmark interface (:class:`~mocapkit.evaluation.compare.base.Benchmark`; a new benchmark — refinement,
retrieval — is a subclass named by ``benchmark._target_``, with no change to the runner)::

    protocols: tuple[str, ...]                     the protocol names
    split(protocol, seed) -> Split                 train / test sample indices (int64, sorted) + info
    data(indices) -> (X, y)                        what estimators fit / predict on ([n] samples)
    evaluate_estimator(estimator, split) -> {"metrics": {name: float}, "detail": ...}
                                                   default: fit(X, y), accuracy of predict on the test side;
                                                   e.g. a refinement benchmark calls fit(motions) / refine(motion)
    learned_overrides(protocol, seed) -> [str]     (learned methods) Hydra overrides selecting data and split
    evaluate_learned(report, run_dir, split) -> {"metrics", "detail"}   (learned methods)
    headline(protocol) -> [metric]; markdown(results) -> str; plots(results, out) -> [Path]   (presentation)

The benchmarks live in their tasks: ``mocapkit.<task>.benchmark*`` (for example
:class:`~mocapkit.gait.benchmark.GaitBenchmark` for ``configs/compare/gait.yaml`` and
:class:`~mocapkit.recognition.benchmark_msr.MSRActionBenchmark` for ``msr3d_recognition.yaml`` and ``msr3d_nmf.yaml``).
"""

from __future__ import annotations

from mocapkit.evaluation.compare.base import (
    Benchmark,
    ComparisonError,
    Split,
    indices_sha1,
)
from mocapkit.evaluation.compare.runner import Comparison, compose, main, run_comparison

__all__ = [
    "Benchmark",
    "Comparison",
    "ComparisonError",
    "Split",
    "cli_main",
    "compose",
    "indices_sha1",
    "main",
    "run_comparison",
]

USAGE = """usage: mocapkit compare NAME [key=value ...]

Run configs/compare/NAME.yaml: every method x protocol x seed cell on the same splits, written to
results.json, results.md and PNG plots in `out` (default checkpoints/compare/NAME).

  mocapkit compare gei_pca_lda benchmark.root=data/casia_b16_gei
  mocapkit compare gait benchmark.root=GEI seeds=[0,1,2] "learned_overrides=['trainer.max_epochs=80']"
  mocapkit compare msr3d_nmf only=[kmeans_w30,nmc_w30] protocols=[cross_subject] seeds=[0]

Keys: name, out, benchmark (_target_ + parameters), protocols, seeds, methods, only, learned_overrides.
"""


def cli_main(argv: list[str]) -> None:
    """``mocapkit compare ...`` (the CLI hands over its arguments unparsed, as Hydra overrides)."""
    if not argv or argv[0] in ("-h", "--help"):
        print(USAGE)
        return
    main(argv)
