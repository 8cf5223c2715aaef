"""``mocapkit gait-report``: train and evaluate the gait methods side by side under both CASIA-B protocols.

For each protocol (``closed_set``: the thesis's hold-out; ``cross_subject``: OpenGait's gallery/probe
split) and each experiment (the multi-task CNN ``casiab_multitask`` and the single-task CNN
``casiab_single_subject``), :func:`gait_report` trains a run (:func:`mocapkit.train.training.train`),
evaluates its ``best.ckpt`` (:func:`mocapkit.evaluation.evaluate.evaluate` → ``evaluate_gait``), and fits the
classical GEI+PCA+LDA baseline on the same split. It writes to ``out_dir``::

    runs/<experiment>/<protocol>-seed<seed>/   each run (checkpoints, config, eval/ with its own tables)
    report.md      side-by-side tables: closed set (views + conditions × methods and tasks), cross subject
                   (NM/BG/CL mean rank-1 × methods; per probe view), training time per run, and the
                   thesis / literature numbers beside them, labelled as real CASIA-B (a different data set)
    report.json    every run's full report
    per_view.png   closed-set subject accuracy and cross-subject NM rank-1 per probe view
"""
from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np

from mocapkit.classical.gei_pca_lda import run_gei_pca_lda
from mocapkit.datasets.formats.casia_b import CONDITIONS, VIEWS
from mocapkit.datasets.casia_b.splits import PROTOCOLS
from mocapkit.datasets.casia_b.cache import GEICache
from mocapkit.evaluation.gait import TABLE_6_2_ROWS, TASK_TITLES, THESIS_TABLE_6_2, plot_per_view_panels, table_6_2_cell
from mocapkit.train.config import ConfigError, compose_config

#: Display names of the experiments and of the baseline.
METHOD_NAMES = {"casiab_multitask": "multi-task CNN", "casiab_single_subject": "single-task CNN",
                "gei_pca_lda": "GEI+PCA+LDA"}
#: Published cross-view rank-1 (%) on real CASIA-B (NM, BG, CL), for orientation only: other data, other nets.
LITERATURE_RANK1: dict[str, tuple[float, float, float]] = {
    "CNN-LB, GEI (Wu et al. TPAMI'17, LT protocol)": (89.9, 72.4, 54.0),
    "GaitSet (OpenGait model zoo)": (95.8, 90.0, 75.4),
}
#: Thesis Table 6.3 (nm / bg / cl), a mostly-90° protocol that differs from the cross-view one (spec §8.5).
THESIS_TABLE_6_3_PCA_LDA = (90.5, 3.6, 3.6)


def _method_name(key: str) -> str:
    return METHOD_NAMES.get(key, key)


def _percent(value) -> str:
    return "–" if value is None or (isinstance(value, float) and np.isnan(value)) else f"{100 * value:.2f}"


def _elapsed(start: float) -> str:
    seconds = int(time.perf_counter() - start)
    return f"{seconds // 60}m{seconds % 60:02d}s"


def gait_report(data_root: str | Path, out_dir: str | Path, protocols=PROTOCOLS,
                experiments=("casiab_multitask", "casiab_single_subject"), overrides=(), seed: int = 0,
                include_pca_lda: bool = True) -> dict:
    """Train, evaluate and tabulate every (protocol, experiment) run plus the GEI+PCA+LDA baseline.

    Args:
        data_root: the GEI cache (``mocapkit prepare casia-b --out ...``).
        out_dir: the report folder (created); runs go to ``out_dir/runs``.
        protocols: ``closed_set`` and/or ``cross_subject``.
        experiments: Hydra experiments to train (``configs/experiment/<name>.yaml``, ``task: gait``).
        overrides: extra Hydra overrides for every run, e.g. ``["trainer.max_epochs=2"]``; the
            ``data.holdout_seed`` / ``data.num_train_subjects`` they set also apply to the baseline.
        seed: the run seed (``seed=``).
        include_pca_lda: also fit GEI+PCA+LDA under each protocol.

    Returns:
        ``{"data_root", "seed", "overrides", "protocols": {protocol: {method key: result}}}``; a CNN
        result is ``{"experiment", "run_dir", "train_seconds", "report"}`` (``report`` from
        ``evaluate_gait``), the baseline's is :func:`~mocapkit.classical.gei_pca_lda.run_gei_pca_lda`'s.
    """
    from mocapkit.evaluation.evaluate import evaluate
    from mocapkit.train.training import train

    data_root, out_dir = Path(data_root), Path(out_dir)
    unknown = [p for p in protocols if p not in PROTOCOLS]
    if unknown or not protocols:
        raise ConfigError(f"protocols={list(protocols)}: choose from {PROTOCOLS}")
    cache = GEICache(data_root)  # fails early, naming the folder, before any training
    out_dir.mkdir(parents=True, exist_ok=True)
    overrides = list(overrides)
    user_sets_run_name = any(o.lstrip("+").startswith("run_name=") for o in overrides)
    start = time.perf_counter()
    result: dict = {"data_root": str(data_root), "seed": seed, "overrides": overrides, "protocols": {}}
    jobs = [(p, e) for p in protocols for e in experiments]
    for protocol in protocols:
        methods: dict = {}
        result["protocols"][protocol] = methods
        base = [f"data.root={data_root}", f"data.protocol={protocol}", f"seed={seed}",
                f"output_root={out_dir / 'runs'}"]
        for experiment in experiments:
            k = jobs.index((protocol, experiment)) + 1
            print(f"[mocapkit] gait-report: run {k}/{len(jobs)}: {experiment} under {protocol} "
                  f"(elapsed {_elapsed(start)})", flush=True)
            run_name = [] if user_sets_run_name else [f"run_name={protocol}-seed{seed}"]
            cfg = compose_config([f"experiment={experiment}", *base, *run_name, *overrides])
            if cfg.get("task") != "gait":
                raise ConfigError(f"experiment={experiment} has task={cfg.get('task')!r}; gait-report needs task: gait")
            run_start = time.perf_counter()
            run_dir = train(cfg)
            train_seconds = time.perf_counter() - run_start
            report = evaluate(run_dir / "best.ckpt", overrides=[f"eval.out_dir={run_dir / 'eval'}"])
            methods[experiment] = {"experiment": experiment, "run_dir": str(run_dir),
                                   "train_seconds": round(train_seconds, 1),
                                   "max_epochs": int(cfg.trainer.max_epochs), "report": report}
            print(f"[mocapkit] gait-report: {experiment} under {protocol} trained in {train_seconds:.0f}s "
                  f"(elapsed {_elapsed(start)})", flush=True)
        if include_pca_lda:
            data_cfg = compose_config([f"experiment={experiments[0] if experiments else 'casiab_multitask'}",
                                       *base, *overrides]).data
            print(f"[mocapkit] gait-report: GEI+PCA+LDA under {protocol} (elapsed {_elapsed(start)})", flush=True)
            methods["gei_pca_lda"] = run_gei_pca_lda(
                cache, protocol, holdout_seed=int(data_cfg.holdout_seed),
                num_train_subjects=data_cfg.get("num_train_subjects") if protocol == "cross_subject" else None)
    result["elapsed_seconds"] = round(time.perf_counter() - start, 1)
    (out_dir / "report.json").write_text(json.dumps(result, indent=2, default=_json_default))
    (out_dir / "report.md").write_text(report_markdown(result))
    panels = per_view_panels(result)
    if panels:
        plot_per_view_panels(panels, out_dir / "per_view.png", f"{data_root.name}: per-view accuracy")
    print(report_markdown(result))
    for name in ("report.md", "report.json", "per_view.png"):
        if (out_dir / name).exists():
            print(f"[mocapkit] wrote {out_dir / name}")
    return result


def _json_default(value):
    if isinstance(value, (np.generic, np.ndarray)):
        return value.tolist()
    raise TypeError(f"report value of type {type(value).__name__} is not JSON serialisable")


# ------------------------------------------------------------------------------------------ tables
def _closed_set_of(method: dict) -> dict:
    """The closed-set report of a CNN result or of the baseline's result."""
    return method["report"]["closed_set"] if "closed_set" in method["report"] else method["report"]


def _cross_view_of(method: dict) -> dict:
    return method["report"]["cross_view"] if "cross_view" in method["report"] else method["report"]


def closed_set_table(methods: dict, level: str = "gei") -> str:
    """Rows 0°..180°, nm, bg, cl, average; columns every method's tasks, then thesis Table 6.2.

    ``level``: ``"gei"`` (per test GEI) or ``"sequence"`` (per test video, by vote over its cycles;
    equal to ``"gei"`` when the cache has one GEI per sequence).
    """
    columns = []  # (title, task entry)
    for key, method in methods.items():
        for task, entry in _closed_set_of(method)["tasks"].items():
            if level == "sequence":
                entry = entry.get("per_sequence", entry)
            columns.append((f"{_method_name(key)}: {TASK_TITLES[task].lower()}", entry))
    header = ["Probe"] + [title for title, _ in columns] + \
        [f"thesis: {TASK_TITLES[t].lower()}" for t in THESIS_TABLE_6_2]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for label, row in TABLE_6_2_ROWS:
        cells = [_percent(table_6_2_cell(entry, row)) for _, entry in columns]
        cells += [f"{THESIS_TABLE_6_2[t][row]:.2f}" for t in THESIS_TABLE_6_2]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def cross_subject_tables(methods: dict) -> str:
    """Mean rank-1 (identical view excluded) per probe condition × method, with literature references;
    then rank-1 per probe view for every method and condition."""
    names = [_method_name(k) for k in methods]
    header = ["Probe"] + names + [f"{n} (incl. identical view)" for n in names] + list(LITERATURE_RANK1) + \
        ["thesis Table 6.3 GEI+PCA+LDA (90° protocol)"]
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for c, condition in enumerate(CONDITIONS):
        cells = [_percent(_cross_view_of(m)["conditions"][condition]["mean"]) for m in methods.values()]
        cells += [_percent(_cross_view_of(m)["conditions"][condition]["mean_including_identical"])
                  for m in methods.values()]
        cells += [f"{ref[c]:.1f}" for ref in LITERATURE_RANK1.values()] + [f"{THESIS_TABLE_6_3_PCA_LDA[c]:.1f}"]
        lines.append(f"| {condition.upper()} | " + " | ".join(cells) + " |")
    lines += ["", "Rank-1 (%) per probe view (mean over the other 10 gallery views):", ""]
    header = ["Method", "Probe"] + [f"{v}°" for v in VIEWS] + ["mean", "missing cells"]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for key, method in methods.items():
        for condition, entry in _cross_view_of(method)["conditions"].items():
            cells = [_percent(entry["per_probe_view"].get(str(v))) for v in VIEWS]
            cells += [_percent(entry["mean"]), f"{len(entry['missing_cells'])}/{len(VIEWS) ** 2}"]
            lines.append(f"| {_method_name(key)} | {condition.upper()} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def report_markdown(result: dict) -> str:
    """The whole report as markdown (see the module docstring)."""
    protocols = result["protocols"]
    lines = [f"# Gait recognition report: {result['data_root']}", "",
             f"Seed {result['seed']}; overrides: {' '.join(result['overrides']) or '(none)'}; "
             f"total time {result.get('elapsed_seconds', 0):.0f} s.", "",
             "Thesis and literature columns are results on the **real CASIA-B** (124 subjects), a different data "
             "set from this cache unless the cache was prepared from CASIA-B itself; they are there for scale, "
             "not as a like-for-like comparison.", ""]
    if "closed_set" in protocols:
        methods = protocols["closed_set"]
        first = next(iter(methods.values()), None)
        lines += ["## Closed set (thesis Table 6.2 protocol)", "",
                  "Per subject and view one nm, one bg and one cl sequence are held out; accuracy (%) of "
                  "identifying the subject among all subjects (and predicting view / condition). Averages are over "
                  "test samples (the thesis's printed averages are inconsistent, spec §8.33).", "",
                  "### Per test GEI", "", closed_set_table(methods, "gei")]
        if first is not None and _closed_set_of(first).get("per") == "cycle":
            lines += ["### Per test sequence (vote: summed logits of its cycles; the thesis tests on videos)", "",
                      closed_set_table(methods, "sequence")]
    if "cross_subject" in protocols:
        lines += ["## Cross subject (OpenGait CASIA-B protocol)", "",
                  "Unseen test subjects; gallery nm-01..04, probes nm-05/06, bg-01/02, cl-01/02; rank-1 (%) per "
                  "(probe view, gallery view), identical view excluded, mean over probe views. CNN embeddings: the "
                  "shared FC-512 layer; GEI+PCA+LDA: its LDA space.", "",
                  cross_subject_tables(protocols["cross_subject"])]
    runs = [(p, k, m) for p, methods in protocols.items() for k, m in methods.items()]
    lines += ["## Runs", "", "| protocol | method | training time | epochs | run / fit |", "|---|---|---|---|---|"]
    for protocol, key, method in runs:
        if "train_seconds" in method:
            lines.append(f"| {protocol} | {_method_name(key)} | {method['train_seconds']:.0f} s "
                         f"| {method['max_epochs']} | {method['run_dir']} |")
        else:
            lines.append(f"| {protocol} | {_method_name(key)} | {method['fit_seconds']:.1f} s (fit) | – "
                         f"| PCA {method['n_pca']} → LDA {method['n_lda']} dims, 1-NN ({method['metric']}) |")
    return "\n".join(lines) + "\n"


def per_view_panels(result: dict) -> dict:
    """Plot data: closed-set subject accuracy per view and cross-subject NM rank-1 per probe view, per method."""
    panels = {}
    closed = result["protocols"].get("closed_set", {})
    if closed:
        panels["closed set: subject accuracy per view"] = {
            _method_name(k): _closed_set_of(m)["tasks"]["subject"]["per_view"] for k, m in closed.items()
            if "subject" in _closed_set_of(m)["tasks"]}
    cross = result["protocols"].get("cross_subject", {})
    if cross:
        panels["cross subject: NM rank-1 per probe view (identical view excluded)"] = {
            _method_name(k): _cross_view_of(m)["conditions"]["nm"]["per_probe_view"] for k, m in cross.items()}
    return {title: series for title, series in panels.items() if series}
