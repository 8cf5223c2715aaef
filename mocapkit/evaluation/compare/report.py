"""``results.md`` and the summary plot of a comparison: mean ± sd over seeds per method × protocol.

The benchmark adds its own detail sections (:meth:`Benchmark.markdown`) and plots (:meth:`Benchmark.plots`).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from mocapkit.evaluation.compare.base import Benchmark


def _finite(values) -> list[float]:
    return [float(v) for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]


def summarise(cells: list[dict], methods: list[str], protocols: list[str]) -> list[dict]:
    """One row per (protocol, method) with cells: ``{"protocol", "method", "label", "kind", "n_seeds", "seeds",
    "time_s", "metrics": {name: {"mean", "sd", "n", "values"}}}``; ``sd`` with ``ddof=1`` (0 for one seed)."""
    rows = []
    for protocol in protocols:
        for method in methods:
            chosen = [c for c in cells if c["protocol"] == protocol and c["method"] == method]
            if not chosen:
                continue
            names = list(dict.fromkeys(name for c in chosen for name in c["metrics"]))
            metrics = {}
            for name in names:
                values = _finite(c["metrics"].get(name) for c in chosen)
                if not values:
                    metrics[name] = {"mean": None, "sd": None, "n": 0, "values": []}
                    continue
                sd = float(np.std(values, ddof=1)) if len(values) > 1 else 0.0
                metrics[name] = {"mean": float(np.mean(values)), "sd": sd, "n": len(values), "values": values}
            rows.append(
                {
                    "protocol": protocol,
                    "method": method,
                    "label": chosen[0]["label"],
                    "kind": chosen[0]["kind"],
                    "n_seeds": len(chosen),
                    "seeds": [c["seed"] for c in chosen],
                    "time_s": float(np.mean([c["time_s"] for c in chosen])),
                    "metrics": metrics,
                }
            )
    return rows


def headline_metrics(benchmark: Benchmark, protocol: str, rows: list[dict]) -> list[str]:
    """The benchmark's headline metrics of ``protocol`` that some row has (all metrics, sorted, without any)."""
    present = list(dict.fromkeys(name for r in rows for name in r["metrics"]))
    wanted = benchmark.headline(protocol)
    return [m for m in wanted if m in present] if wanted else sorted(present)


def summary_markdown(results: dict, benchmark: Benchmark) -> str:
    """The per-protocol tables: rows = methods, columns = headline metrics as mean ± sd over seeds."""
    lines = []
    for protocol in results["protocols"]:
        rows = [r for r in results["summary"] if r["protocol"] == protocol]
        if not rows:
            continue
        metrics = headline_metrics(benchmark, protocol, rows)
        header = ["method", "kind", *metrics, "seeds", "time per cell (s)"]
        lines += [f"### {protocol}", "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
        for r in rows:
            cells = [
                benchmark.format_metric(m, r["metrics"].get(m, {}).get("mean"), r["metrics"].get(m, {}).get("sd"))
                for m in metrics
            ]
            lines.append(
                f"| {r['label']} | {r['kind']} | " + " | ".join(cells) + f" | {r['n_seeds']} | {r['time_s']:.1f} |"
            )
        lines.append("")
    return "\n".join(lines)


def cells_markdown(results: dict, benchmark: Benchmark) -> str:
    """Every cell: its first headline metric, time, test-set fingerprint and its run folder or parameters."""
    lines = [
        "| method | protocol | seed | headline | test samples (sha1) | time (s) | run / parameters |",
        "|---|---|---|---|---|---|---|",
    ]
    for c in results["cells"]:
        first = (benchmark.headline(c["protocol"]) or sorted(c["metrics"]))[:1]
        shown = ", ".join(f"{m} {benchmark.format_metric(m, c['metrics'].get(m))}" for m in first)
        where = c.get("run_dir") or (", ".join(f"{k}={v}" for k, v in (c.get("params") or {}).items()) or "defaults")
        lines.append(
            f"| {c['label']} | {c['protocol']} | {c['seed']} | {shown} | {c['n_test']} "
            f"({c['test_sha1'][:10]}) | {c['time_s']:.1f} | {where} |"
        )
    return "\n".join(lines) + "\n"


def versions(host: dict) -> str:
    """``"torch 2.14.1, Lightning 2.6.6, numpy 2.4.6, scikit-learn 1.9.1"`` from a results file's ``machine``
    (the packages it recorded; results of earlier versions recorded torch and scikit-learn only)."""
    names = (("torch", "torch"), ("lightning", "Lightning"), ("numpy", "numpy"), ("sklearn", "scikit-learn"))
    return ", ".join(f"{label} {host[key]}" for key, label in names if host.get(key))


def results_markdown(results: dict, benchmark: Benchmark) -> str:
    """The whole ``results.md``."""
    host = results["machine"]
    lines = [
        f"# Comparison `{results['name']}`: {results['benchmark']['title']}",
        "",
        (
            f"Benchmark `{results['benchmark']['target']}`; protocols {', '.join(results['protocols'])}; seeds "
            f"{results['seeds']}; {len(results['cells'])} cells in {results['elapsed_s'] / 60:.1f} min on "
            f"{host['processor']} ({host['cpu_count']} CPUs, OMP_NUM_THREADS={host['omp_num_threads']}; "
            f"{versions(host)}). "
            "Every method of a (protocol, seed) cell is scored on the same test samples with the same metric "
            "code (the sha1 column below); learned methods are trained with `mocapkit train` and scored with "
            "`mocapkit eval`, estimators are fitted on the whole training side."
        ),
        "",
        "## Summary: mean ± sd over seeds",
        "",
        summary_markdown(results, benchmark),
    ]
    if results.get("selection"):
        lines += [
            "## Hyper-parameter selection",
            "",
            f"Coordinate search by {benchmark.selection_cv} on the training side of the first seed's split only.",
            "",
            "| method | protocol | chosen | CV score | tried |",
            "|---|---|---|---|---|",
        ]
        for method, per_protocol in results["selection"].items():
            for protocol, entry in per_protocol.items():
                chosen = ", ".join(f"{k}={v}" for k, v in entry["params"].items())
                lines.append(f"| {method} | {protocol} | {chosen} | {entry['cv_score']:.4f} | {len(entry['tried'])} |")
        lines.append("")
    extra = benchmark.markdown(results)
    if extra:
        lines += [extra, ""]
    lines += ["## Cells", "", cells_markdown(results, benchmark)]
    return "\n".join(lines)


def plot_summary(results: dict, benchmark: Benchmark, path: Path) -> Path | None:
    """Bars of each method's first headline metric (mean ± sd over seeds), one bar per protocol."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = results["summary"]
    if not rows:
        return None
    labels = list(dict.fromkeys(r["label"] for r in rows))
    protocols = results["protocols"]
    width = 0.8 / max(len(protocols), 1)
    fig, ax = plt.subplots(figsize=(max(5.0, 0.9 * len(labels) + 2), 4.2))
    metric_names = []
    for p, protocol in enumerate(protocols):
        metric = (headline_metrics(benchmark, protocol, [r for r in rows if r["protocol"] == protocol]) or [None])[0]
        if metric is None:
            continue
        metric_names.append(metric)
        by_label = {r["label"]: r["metrics"].get(metric, {}) for r in rows if r["protocol"] == protocol}
        xs = [i for i, label in enumerate(labels) if by_label.get(label, {}).get("mean") is not None]
        ax.bar(
            [x + p * width for x in xs],
            [by_label[labels[x]]["mean"] for x in xs],
            width,
            yerr=[by_label[labels[x]]["sd"] for x in xs],
            capsize=3,
            label=f"{protocol}: {metric}",
        )
    ax.set_xticks(
        [i + width * (len(protocols) - 1) / 2 for i in range(len(labels))], labels, fontsize=8, rotation=25, ha="right"
    )
    ax.set_ylabel(" / ".join(dict.fromkeys(metric_names)))
    ax.set_title(f"{results['name']}: mean ± sd over seeds {results['seeds']}")
    ax.legend(fontsize=8, frameon=False)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def write_reports(results: dict, benchmark: Benchmark, out: Path) -> list[Path]:
    """Write ``results.md``, ``summary.png`` and the benchmark's plots into ``out``; their paths."""
    out = Path(out)
    (out / "results.md").write_text(results_markdown(results, benchmark), encoding="utf-8")
    written = [out / "results.md"]
    summary_png = plot_summary(results, benchmark, out / "summary.png")
    written += [summary_png] if summary_png else []
    written += list(benchmark.plots(results, out))
    return written
