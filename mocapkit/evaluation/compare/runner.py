"""The comparison runner: methods × protocols × seeds on one benchmark, one ``results.json`` / ``results.md``.

See :mod:`mocapkit.evaluation.compare` for the configuration schema and the benchmark interface.
:func:`main` composes ``configs/compare.yaml`` with ``compare=NAME`` (``configs/compare/NAME.yaml``) and
Hydra overrides; :func:`run_comparison` runs a composed config.
"""

from __future__ import annotations

import json
import math
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from omegaconf import DictConfig, OmegaConf

from mocapkit.evaluation.compare.base import (
    Benchmark,
    ComparisonError,
    Split,
    indices_sha1,
)

#: Keys of the compare config (``configs/compare.yaml``).
CONFIG_KEYS = ("name", "out", "benchmark", "protocols", "seeds", "methods", "only", "learned_overrides", "templates")
#: Keys of one method entry.
METHOD_KEYS = ("label", "learned", "estimator", "params", "select", "reseed")
LEARNED_KEYS = ("experiment", "overrides", "checkpoint", "eval_overrides")
#: Which checkpoint of a learned run is scored (``learned.checkpoint``; best: best validation accuracy).
CHECKPOINTS = ("best", "last")
SELECT_KEYS = ("stages", "cv", "reuse")


@dataclass
class Method:
    """One row of the method table (a ``methods.KEY`` entry of the config)."""

    key: str
    label: str
    kind: str  # "learned" | "estimator"
    spec: dict  # learned: {experiment, overrides}; estimator: the instantiate spec
    params: dict = field(default_factory=dict)  # estimator: set_params after instantiation (nested a__b names)
    select: dict | None = None  # estimator: {stages, cv} or {reuse: KEY}
    reseed: bool = True  # estimator: set every random_state to the cell's seed


def _elapsed(start: float) -> str:
    seconds = int(time.perf_counter() - start)
    return f"{seconds // 60}m{seconds % 60:02d}s"


def _json_default(value):
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    return repr(value)


def machine() -> dict:
    """Where the numbers were measured (platform, CPUs, versions, thread settings).

    Learned runs do not reproduce to the last sample across package versions (the same seeds moved 2–4 test clips
    in a fresh environment: docs/results/recognition.md#msr-action3d-cross-subject), so the versions that shape the
    numbers are recorded.
    """
    import lightning
    import numpy
    import sklearn
    import torch

    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpu_count": os.cpu_count(),
        "python": platform.python_version(),
        "torch": torch.__version__,
        "lightning": lightning.__version__,
        "numpy": numpy.__version__,
        "sklearn": sklearn.__version__,
        "torch_threads": torch.get_num_threads(),
        "omp_num_threads": os.environ.get("OMP_NUM_THREADS"),
        "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
    }


# ------------------------------------------------------------------------------------------ config
def compose(overrides: list[str]) -> DictConfig:
    """``configs/compare.yaml`` composed with ``overrides``; a first bare word ``NAME`` means ``compare=NAME``."""
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from mocapkit.train.config import CONFIG_DIR

    overrides = list(overrides)
    if overrides and "=" not in overrides[0]:
        overrides[0] = f"compare={overrides[0]}"
    available = sorted(p.stem for p in (CONFIG_DIR / "compare").glob("*.yaml"))
    chosen = [o.split("=", 1)[1] for o in overrides if o.startswith("compare=")]
    if chosen and chosen[-1] not in available:
        raise ComparisonError(f"comparison {chosen[-1]!r} not found: configs/compare/ holds {', '.join(available)}")
    try:
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
            return hydra_compose(config_name="compare", overrides=overrides)
    except Exception as exc:  # Hydra and OmegaConf errors name the override
        if type(exc).__module__.startswith(("hydra", "omegaconf")):
            raise ComparisonError(str(exc)) from exc
        raise


def parse_methods(methods: dict) -> dict[str, Method]:
    """Validate the ``methods`` table (a plain dict); unknown keys fail naming the method and the key."""
    if not isinstance(methods, dict) or not methods:
        raise ComparisonError(
            "methods: the comparison lists no methods (methods: {KEY: {learned: ...} | {estimator: ...}})"
        )
    parsed = {}
    for key, entry in methods.items():
        if not isinstance(entry, dict):
            raise ComparisonError(f"methods.{key}: expected a mapping with learned: or estimator:, got {entry!r}")
        unknown = sorted(set(entry) - set(METHOD_KEYS))
        if unknown:
            raise ComparisonError(f"methods.{key}: unknown key(s) {unknown}; a method takes {list(METHOD_KEYS)}")
        kinds = [k for k in ("learned", "estimator") if entry.get(k) is not None]
        if len(kinds) != 1:
            raise ComparisonError(
                f"methods.{key}: give exactly one of learned: {{experiment: NAME}} or "
                f"estimator: {{_target_: CLASS, ...}} (got {kinds or 'neither'})"
            )
        kind = kinds[0]
        spec = entry[kind]
        if kind == "learned":
            if not isinstance(spec, dict) or not spec.get("experiment"):
                raise ComparisonError(f"methods.{key}.learned: needs experiment: NAME (configs/experiment/NAME.yaml)")
            bad = sorted(set(spec) - set(LEARNED_KEYS))
            if bad:
                raise ComparisonError(f"methods.{key}.learned: unknown key(s) {bad}; it takes {list(LEARNED_KEYS)}")
            for name in ("overrides", "eval_overrides"):
                if not isinstance(spec.get(name) or [], list):
                    raise ComparisonError(
                        f"methods.{key}.learned.{name}: expected a list of Hydra overrides, got {spec[name]!r}"
                    )
            if spec.get("checkpoint", "best") not in CHECKPOINTS:
                raise ComparisonError(
                    f"methods.{key}.learned.checkpoint={spec['checkpoint']!r}: one of {list(CHECKPOINTS)}"
                )
            for other in ("params", "select"):
                if entry.get(other):
                    raise ComparisonError(
                        f"methods.{key}: {other} applies to estimators; give a learned method "
                        "Hydra overrides in learned.overrides"
                    )
        elif not isinstance(spec, dict) or "_target_" not in spec:
            raise ComparisonError(f"methods.{key}.estimator: needs _target_: the estimator class")
        select = entry.get("select")
        if select is not None:
            bad = sorted(set(select) - set(SELECT_KEYS))
            if bad:
                raise ComparisonError(f"methods.{key}.select: unknown key(s) {bad}; it takes {list(SELECT_KEYS)}")
            if not select.get("reuse") and not select.get("stages"):
                raise ComparisonError(f"methods.{key}.select: give stages: [{{PARAM: [values]}}, ...] or reuse: KEY")
            for stage in select.get("stages") or []:
                if not isinstance(stage, dict) or len(stage) != 1 or not isinstance(next(iter(stage.values())), list):
                    raise ComparisonError(
                        f"methods.{key}.select.stages: every stage is one {{PARAM: [values]}}, got {stage!r}"
                    )
        parsed[key] = Method(
            key=key,
            label=str(entry.get("label") or key),
            kind=kind,
            spec=spec,
            params=dict(entry.get("params") or {}),
            select=select,
            reseed=bool(entry.get("reseed", True)),
        )
    for method in parsed.values():
        reuse = (method.select or {}).get("reuse")
        if reuse is not None and (reuse not in parsed or not (parsed[reuse].select or {}).get("stages")):
            raise ComparisonError(
                f"methods.{method.key}.select.reuse={reuse!r}: not a method with select.stages "
                f"(methods: {', '.join(parsed)})"
            )
    return parsed


def instantiate_benchmark(spec) -> Benchmark:
    """The benchmark of ``benchmark: {_target_: ..., ...}``; an unknown class fails naming it."""
    from hydra.utils import instantiate

    if not isinstance(spec, dict) or "_target_" not in spec:
        raise ComparisonError(
            "benchmark: needs _target_: a Benchmark class, e.g. mocapkit.gait.benchmark.GaitBenchmark"
        )
    try:
        benchmark = instantiate(spec)
    except Exception as exc:
        raise ComparisonError(f"benchmark._target_={spec['_target_']!r}: cannot build it: {exc}") from exc
    if not all(hasattr(benchmark, name) for name in ("split", "data", "evaluate_estimator", "protocols")):
        raise ComparisonError(
            f"benchmark._target_={spec['_target_']!r} is not a benchmark (subclass "
            "mocapkit.evaluation.compare.base.Benchmark)"
        )
    return benchmark


# ------------------------------------------------------------------------------------------ runner
class Comparison:
    """One configured comparison: the benchmark, the method table, the cells run so far."""

    def __init__(self, cfg: DictConfig | dict):
        plain = OmegaConf.to_container(cfg, resolve=True) if isinstance(cfg, DictConfig) else dict(cfg)
        unknown = sorted(set(plain) - set(CONFIG_KEYS))
        if unknown:
            raise ComparisonError(f"unknown compare config key(s) {unknown}; known: {list(CONFIG_KEYS)}")
        if not plain.get("name"):
            raise ComparisonError(
                "no comparison chosen: run `mocapkit compare NAME` with NAME one of "
                "configs/compare/*.yaml (e.g. gait, gei_pca_lda, msr3d_nmf)"
            )
        self.config = plain
        self.name = str(plain["name"])
        self.out = Path(plain.get("out") or f"checkpoints/compare/{self.name}")
        self.methods = parse_methods(plain.get("methods") or {})
        only = plain.get("only")
        if only is not None:
            only = [only] if isinstance(only, str) else list(only)
            missing = [k for k in only if k not in self.methods]
            if missing:
                raise ComparisonError(f"only={missing}: unknown method key(s); methods: {', '.join(self.methods)}")
        self.run_keys = [k for k in self.methods if only is None or k in only]
        self.seeds = [int(s) for s in (plain.get("seeds") or [])]
        if not self.seeds:
            raise ComparisonError("seeds: give at least one seed, e.g. seeds=[0]")
        self.learned_overrides = [str(o) for o in plain.get("learned_overrides") or []]
        self.benchmark = instantiate_benchmark(plain.get("benchmark"))
        self.protocols = list(plain.get("protocols") or [])
        bad = [p for p in self.protocols if p not in self.benchmark.protocols]
        if bad or not self.protocols:
            raise ComparisonError(
                f"protocols={self.protocols}: {type(self.benchmark).__name__} knows {list(self.benchmark.protocols)}"
            )
        self._splits: dict[tuple[str, int], Split] = {}
        #: trained runs by their training overrides (less run_name): learned methods that differ only in
        #: ``eval_overrides`` or ``checkpoint`` are scored on one run → (run_dir, training seconds, config, the
        #: overrides it was trained with)
        self._trained: dict[tuple[str, ...], tuple[Path, float, DictConfig, list[str]]] = {}
        self.selection: dict[str, dict[str, dict]] = {}
        self.cells: list[dict] = []

    # -------------------------------------------------------------- pieces
    def split(self, protocol: str, seed: int) -> Split:
        if (protocol, seed) not in self._splits:
            self._splits[(protocol, seed)] = self.benchmark.split(protocol, seed)
        return self._splits[(protocol, seed)]

    def make_estimator(self, method: Method, seed: int, extra: dict | None = None):
        """A fresh estimator of ``method``: instantiated, ``params`` and ``extra`` set, random states = ``seed``."""
        from hydra.utils import instantiate

        try:
            estimator = instantiate(method.spec)
        except Exception as exc:
            raise ComparisonError(
                f"methods.{method.key}.estimator: cannot build {method.spec.get('_target_')!r}: {exc}"
            ) from exc
        for params in (method.params, extra or {}):
            if params:
                try:
                    estimator.set_params(**params)
                except ValueError as exc:
                    raise ComparisonError(f"methods.{method.key}: {exc}") from exc
        if method.reseed and hasattr(estimator, "get_params"):
            names = [k for k in estimator.get_params(deep=True) if k == "random_state" or k.endswith("__random_state")]
            estimator.set_params(**{k: seed for k in names})
        return estimator

    def selected(self, method: Method, protocol: str) -> dict:
        """Parameters chosen by ``method.select`` under ``protocol`` (memoised; ``{}`` without selection).

        Coordinate search by cross-validation on the **training side** of the first seed's split
        (:meth:`~mocapkit.evaluation.compare.base.Benchmark.cross_validate`), with that seed for the folds and
        the estimators: the stages in order, each trying its values at the best
        parameters so far; a value replaces the best only when its mean CV score is strictly higher (ties keep
        the earlier one), and a parameter set already scored is not scored again.
        """
        if not method.select:
            return {}
        reuse = method.select.get("reuse")
        if reuse:
            return self.selected(self.methods[reuse], protocol)
        memo = self.selection.setdefault(method.key, {})
        if protocol in memo:
            return memo[protocol]["params"]
        seed = self.seeds[0]
        split = self.split(protocol, seed)
        folds = int(method.select.get("cv", 3))
        stages = [next(iter(stage.items())) for stage in method.select["stages"]]
        current = self.make_estimator(method, seed).get_params(deep=True)
        best = {name: current[name] for name, _ in stages if name in current}
        absent = [name for name, _ in stages if name not in current]
        if absent:
            raise ComparisonError(
                f"methods.{method.key}.select: {absent} are not parameters of the estimator (nested names: step__param)"
            )
        best_score, tried, start = -math.inf, [], time.perf_counter()
        for name, values in stages:
            for value in values:
                candidate = {**best, name: value}
                if any(t["params"] == candidate for t in tried):
                    continue
                estimator = self.make_estimator(method, seed, candidate)
                score = self.benchmark.cross_validate(estimator, split.train, folds, seed)
                tried.append({"params": candidate, "cv_score": score})
                print(f"[compare] select {method.key} | {protocol}: {candidate} → CV {score:.4f}", flush=True)
                if score > best_score:
                    best, best_score = candidate, score
        memo[protocol] = {
            "params": best,
            "cv_score": best_score,
            "split_seed": seed,
            "folds": folds,
            "tried": tried,
            "time_s": round(time.perf_counter() - start, 2),
        }
        return best

    def run_estimator(self, method: Method, split: Split) -> dict:
        chosen = self.selected(method, split.protocol)
        estimator = self.make_estimator(method, split.seed, chosen)
        start = time.perf_counter()
        scores = self.benchmark.evaluate_estimator(estimator, split)
        return {
            **scores,
            "time_s": time.perf_counter() - start,
            "params": {**method.params, **chosen},
            "estimator": repr(estimator),
            "n_test": len(split.test),
            "test_sha1": indices_sha1(split.test),
        }

    def run_learned(self, method: Method, split: Split) -> dict:
        """Train ``method`` on ``split`` (or reuse the run of an earlier method with the same training
        overrides) and score its checkpoint with ``eval_overrides``."""
        from mocapkit.evaluation.evaluate import evaluate
        from mocapkit.train.config import compose_config
        from mocapkit.train.training import train

        experiment = method.spec["experiment"]
        training = [
            f"experiment={experiment}",
            *self.benchmark.learned_overrides(split.protocol, split.seed),
            f"seed={split.seed}",
            f"output_root={self.out / 'runs'}",
            *[str(o) for o in method.spec.get("overrides") or []],
            *self.learned_overrides,
        ]
        overrides = [*training, f"run_name={method.key}_{split.protocol}_seed{split.seed}"]
        start = time.perf_counter()
        shared = tuple(training) in self._trained
        if not shared:
            cfg = compose_config(overrides)
            self.benchmark.check_learned_config(cfg, method.key)
            run_dir = Path(train(cfg))
            self._trained[tuple(training)] = (run_dir, time.perf_counter() - start, cfg, overrides)
        run_dir, train_seconds, cfg, overrides = self._trained[tuple(training)]
        checkpoint = run_dir / f"{method.spec.get('checkpoint', 'best')}.ckpt"
        eval_overrides = [str(o) for o in method.spec.get("eval_overrides") or []]
        eval_dir = run_dir / (f"eval_{method.key}" if shared or eval_overrides else "eval")
        report = evaluate(checkpoint, [f"eval.out_dir={eval_dir}", *eval_overrides])
        test_idx = self.benchmark.learned_test_indices(run_dir)
        if indices_sha1(test_idx) != indices_sha1(split.test):
            raise ComparisonError(
                f"methods.{method.key} under {split.protocol}, seed {split.seed}: the run's data "
                f"module tested {len(test_idx)} samples, the benchmark's split {len(split.test)} "
                f"different ones; the benchmark's learned_overrides must reproduce its split"
            )
        scores = self.benchmark.evaluate_learned(report, run_dir, split)
        trainer = cfg.get("trainer") or {}
        return {
            **scores,
            "time_s": time.perf_counter() - start,
            "train_seconds": train_seconds,
            "experiment": experiment,
            "run_dir": str(run_dir),
            "shared_run": shared,
            "checkpoint": checkpoint.name,
            "overrides": overrides,
            "eval_overrides": eval_overrides,
            "max_epochs": trainer.get("max_epochs"),
            "n_test": len(test_idx),
            "test_sha1": indices_sha1(test_idx),
        }

    # -------------------------------------------------------------- the table
    def run(self) -> dict:
        """Run every cell (progress: one line per cell), write the outputs, return the results dict."""
        self.out.mkdir(parents=True, exist_ok=True)
        start, self.started = time.perf_counter(), time.strftime("%Y-%m-%d %H:%M:%S")
        jobs = [(p, s, k) for p in self.protocols for s in self.seeds for k in self.run_keys]
        print(
            f"[compare] {self.name}: {len(self.run_keys)} methods × {len(self.protocols)} protocols × "
            f"{len(self.seeds)} seeds = {len(jobs)} cells → {self.out}",
            flush=True,
        )
        for n, (protocol, seed, key) in enumerate(jobs, 1):
            method = self.methods[key]
            split = self.split(protocol, seed)
            if method.kind == "learned":
                print(
                    f"[compare] cell {n}/{len(jobs)} {key} | {protocol} | seed {seed}: learned run of "
                    f"{method.spec['experiment']} (elapsed {_elapsed(start)})",
                    flush=True,
                )
                cell = self.run_learned(method, split)
            else:
                cell = self.run_estimator(method, split)
            cell = {
                "method": key,
                "label": method.label,
                "kind": method.kind,
                "protocol": protocol,
                "seed": seed,
                **cell,
            }
            self.cells.append(cell)
            headline = (self.benchmark.headline(protocol) or sorted(cell["metrics"]))[:1]
            shown = ", ".join(f"{m} {self.benchmark.format_metric(m, cell['metrics'].get(m))}" for m in headline)
            print(
                f"[compare] cell {n}/{len(jobs)} {key} | {protocol} | seed {seed}: {shown} "
                f"({cell['time_s']:.1f} s; elapsed {_elapsed(start)})",
                flush=True,
            )
            self.write_json(time.perf_counter() - start)  # partial results survive a failure
        results = self.write_json(time.perf_counter() - start)
        from mocapkit.evaluation.compare.report import write_reports

        written = write_reports(results, self.benchmark, self.out)
        for path in [self.out / "results.json", *written]:
            print(f"[compare] wrote {path}")
        return results

    def results(self, elapsed: float) -> dict:
        from mocapkit.evaluation.compare.report import summarise

        splits = {p: {str(s): self.split(p, s).describe() for s in self.seeds} for p in self.protocols}
        return {
            "name": self.name,
            "benchmark": {
                "target": self.config["benchmark"]["_target_"],
                "title": self.benchmark.title,
                **self.benchmark.describe(),
            },
            "protocols": self.protocols,
            "seeds": self.seeds,
            "methods": {k: {"label": m.label, "kind": m.kind} for k, m in self.methods.items() if k in self.run_keys},
            "started": getattr(self, "started", None),
            "elapsed_s": round(elapsed, 1),
            "machine": machine(),
            "config": self.config,
            "splits": splits,
            "selection": self.selection,
            "summary": summarise(self.cells, self.run_keys, self.protocols),
            "cells": self.cells,
        }

    def write_json(self, elapsed: float) -> dict:
        results = self.results(elapsed)
        path = self.out / "results.json"
        path.write_text(json.dumps(results, indent=1, default=_json_default))
        return results


def run_comparison(cfg: DictConfig | dict) -> dict:
    """Run a composed compare config (see :mod:`mocapkit.evaluation.compare`); return the ``results.json`` dict."""
    return Comparison(cfg).run()


def main(overrides: list[str]) -> dict:
    """``mocapkit compare NAME [overrides ...]``: compose ``configs/compare.yaml`` with ``compare=NAME`` and run it."""
    return run_comparison(compose(overrides))
