"""The comparison runner (mocapkit.evaluation.compare): every cell, mean ± sd, CV selection, identical test sets for
learned and classical methods, errors that name the culprit, and a new benchmark plugged in without runner changes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from sklearn.base import BaseEstimator, ClassifierMixin

from mocapkit.evaluation.compare import ComparisonError, compose, run_comparison
from mocapkit.evaluation.compare.base import Benchmark, Split, indices_sha1


# ------------------------------------------------------------------------------------------ toy benchmarks
class ToyBenchmark(Benchmark):
    """Two Gaussian blobs per class in 2-D; ``easy`` = a random half tests (drawn with the seed), ``fixed`` = the
    last third tests whatever the seed."""

    title = "toy blobs"
    protocols = ("easy", "fixed")

    def __init__(self, n: int = 60, noise: float = 1.0):
        rng = np.random.default_rng(0)
        self.y = np.arange(n) % 3
        self.X = rng.normal(size=(3, 2))[self.y] * 3 + noise * rng.normal(size=(n, 2))

    def split(self, protocol, seed):
        n = len(self.y)
        if protocol == "easy":
            order = np.random.default_rng(seed).permutation(n)
            return Split(protocol, seed, np.sort(order[: n // 2]), np.sort(order[n // 2 :]))
        return Split(protocol, seed, np.arange(2 * n // 3), np.arange(2 * n // 3, n), {"note": "fixed"})

    def data(self, indices):
        return self.X[indices], self.y[indices]

    def headline(self, protocol):
        return ["accuracy"]


class ConstantScore(ClassifierMixin, BaseEstimator):
    """Predicts class 0 whatever ``a`` and ``b`` are: every parameter set gets the same CV score."""

    def __init__(self, a=1, b="x", random_state=None):
        self.a, self.b, self.random_state = a, b, random_state

    def fit(self, X, y):
        self.classes_ = np.unique(y)
        return self

    def predict(self, X):
        return np.zeros(len(X), dtype=int)


class ShrinkRefiner(BaseEstimator):
    """A refinement-style method (``fit(signals)`` / ``refine(signal)``): pulls a signal towards the training mean."""

    def __init__(self, weight: float = 0.5):
        self.weight = weight

    def fit(self, signals, y=None):
        self.mean_ = np.mean(signals, axis=0)
        return self

    def refine(self, signal):
        return (1 - self.weight) * signal + self.weight * self.mean_


class ToyRefinementBenchmark(Benchmark):
    """Noisy copies of one clean signal; the metric is the RMSE of the refined signal (lower is better)."""

    title = "toy refinement"
    protocols = ("noisy",)
    percent_metrics = ()

    def __init__(self):
        rng = np.random.default_rng(1)
        self.clean = np.sin(np.linspace(0, 6, 50))
        self.noisy = self.clean + 0.3 * rng.normal(size=(20, 50))

    def split(self, protocol, seed):
        return Split(protocol, seed, np.arange(10), np.arange(10, 20))

    def data(self, indices):
        return self.noisy[indices], None

    def evaluate_estimator(self, estimator, split):
        estimator.fit(self.noisy[split.train])
        errors = [np.sqrt(np.mean((estimator.refine(self.noisy[i]) - self.clean) ** 2)) for i in split.test]
        return {"metrics": {"rmse": float(np.mean(errors))}, "detail": {"per_sample": errors}}


def _config(tmp_path, methods, protocols=("easy", "fixed"), seeds=(0, 1, 2), benchmark="ToyBenchmark", **extra):
    return {
        "name": "toy",
        "out": str(tmp_path / "out"),
        "benchmark": {"_target_": f"tests.evaluation.test_compare.{benchmark}"},
        "protocols": list(protocols),
        "seeds": list(seeds),
        "methods": methods,
        **extra,
    }


KNN = {"_target_": "sklearn.neighbors.KNeighborsClassifier", "n_neighbors": 3}


# ------------------------------------------------------------------------------------------ the runner core
def test_every_cell_is_run_and_summarised_as_mean_and_sd(tmp_path):
    methods = {
        "knn": {"label": "k-NN", "estimator": KNN},
        "knn_cv": {
            "estimator": KNN,
            "select": {"cv": 3, "stages": [{"n_neighbors": [1, 5, 9]}, {"weights": ["uniform", "distance"]}]},
        },
        "knn_like_cv": {"estimator": KNN, "select": {"reuse": "knn_cv"}},
        "chance": {"estimator": {"_target_": "sklearn.dummy.DummyClassifier", "strategy": "uniform"}},
    }
    results = run_comparison(_config(tmp_path, methods))
    saved = json.loads((tmp_path / "out" / "results.json").read_text())
    assert {(c["method"], c["protocol"], c["seed"]) for c in saved["cells"]} == {
        (m, p, s) for m in methods for p in ("easy", "fixed") for s in (0, 1, 2)
    }
    assert len(saved["cells"]) == 4 * 2 * 3 and saved["machine"]["cpu_count"] >= 1
    import lightning
    import torch

    # the versions that shape learned numbers are recorded, in the json and in the report's first paragraph
    assert saved["machine"]["torch"] == torch.__version__ and saved["machine"]["numpy"] == np.__version__
    assert (
        f"torch {torch.__version__}, Lightning {lightning.__version__}, numpy {np.__version__}"
        in (tmp_path / "out" / "results.md").read_text()
    )
    for protocol in ("easy", "fixed"):
        for seed in (0, 1, 2):
            cells = [c for c in saved["cells"] if c["protocol"] == protocol and c["seed"] == seed]
            assert {c["test_sha1"] for c in cells} == {saved["splits"][protocol][str(seed)]["test_sha1"]}
        row = next(r for r in saved["summary"] if r["protocol"] == protocol and r["method"] == "chance")
        values = [
            c["metrics"]["accuracy"] for c in saved["cells"] if c["protocol"] == protocol and c["method"] == "chance"
        ]
        assert row["metrics"]["accuracy"]["values"] == values and row["n_seeds"] == 3
        assert row["metrics"]["accuracy"]["mean"] == pytest.approx(np.mean(values))
        assert row["metrics"]["accuracy"]["sd"] == pytest.approx(np.std(values, ddof=1))
    # the seed moves the "easy" split, not the "fixed" one; reseed gives every estimator the cell's seed
    assert len({saved["splits"]["easy"][s]["test_sha1"] for s in "012"}) == 3
    assert len({saved["splits"]["fixed"][s]["test_sha1"] for s in "012"}) == 1
    assert [c["estimator"] for c in saved["cells"] if c["method"] == "chance" and c["protocol"] == "fixed"] == [
        f"DummyClassifier(random_state={s}, strategy='uniform')" for s in (0, 1, 2)
    ]
    # selection: once per protocol, on the first seed's training side; the reusing method gets the same values
    assert set(saved["selection"]) == {"knn_cv"}
    for protocol in ("easy", "fixed"):
        chosen = saved["selection"]["knn_cv"][protocol]
        assert chosen["split_seed"] == 0 and len(chosen["tried"]) == 3 + 1  # the current weights is not rescored
        for c in saved["cells"]:
            if c["method"] in ("knn_cv", "knn_like_cv") and c["protocol"] == protocol:
                assert c["params"] == chosen["params"]
    table = (tmp_path / "out" / "results.md").read_text()
    chance = next(r for r in results["summary"] if r["protocol"] == "easy" and r["method"] == "chance")
    mean, sd = (100 * chance["metrics"]["accuracy"][k] for k in ("mean", "sd"))
    assert f"| chance | estimator | {mean:.2f} ± {sd:.2f} % | 3 |" in table
    assert "### easy" in table and "### fixed" in table and "| k-NN | estimator |" in table
    assert (tmp_path / "out" / "summary.png").stat().st_size > 1000


def test_selection_ties_keep_the_earlier_value(tmp_path):
    methods = {
        "const": {
            "estimator": {"_target_": "tests.evaluation.test_compare.ConstantScore"},
            "select": {"stages": [{"a": [1, 2, 3]}, {"b": ["y", "x"]}]},
        }
    }
    run_comparison(_config(tmp_path, methods, protocols=["fixed"], seeds=[4], only=["const"]))
    chosen = json.loads((tmp_path / "out" / "results.json").read_text())["selection"]["const"]["fixed"]
    assert chosen["params"] == {"a": 1, "b": "x"} and chosen["split_seed"] == 4
    assert [t["params"] for t in chosen["tried"]] == [
        {"a": 1, "b": "x"},
        {"a": 2, "b": "x"},
        {"a": 3, "b": "x"},
        {"a": 1, "b": "y"},
    ]


def test_a_refinement_style_benchmark_plugs_in_without_runner_changes(tmp_path):
    methods = {
        "shrink": {"estimator": {"_target_": "tests.evaluation.test_compare.ShrinkRefiner", "weight": 0.5}},
        "identity": {
            "estimator": {"_target_": "tests.evaluation.test_compare.ShrinkRefiner"},
            "params": {"weight": 0.0},
        },
    }
    results = run_comparison(
        _config(tmp_path, methods, protocols=["noisy"], seeds=[0], benchmark="ToyRefinementBenchmark")
    )
    rmse = {c["method"]: c["metrics"]["rmse"] for c in results["cells"]}
    assert rmse["shrink"] < rmse["identity"] == pytest.approx(0.3, abs=0.05)
    assert f"| shrink | estimator | {rmse['shrink']:.3f} ± 0.000 |" in (tmp_path / "out" / "results.md").read_text()


@pytest.mark.parametrize(
    "change, message",
    [
        ({"methods": {"knn": {"estimatr": KNN}}}, r"methods.knn: unknown key\(s\) \['estimatr'\]"),
        ({"methods": {"knn": {"learned": {"experiment": "x"}, "estimator": KNN}}}, "methods.knn: give exactly one"),
        ({"methods": {"knn": {"estimator": KNN, "select": {"reuse": "nope"}}}}, "select.reuse='nope'"),
        ({"only": ["knn", "svm"]}, r"only=\['svm'\]: unknown method key"),
        (
            {"benchmark": {"_target_": "tests.evaluation.test_compare.NoSuchBenchmark"}},
            "tests.evaluation.test_compare.NoSuchBenchmark",
        ),
        ({"benchmark": {"_target_": "tests.evaluation.test_compare.ConstantScore"}}, "is not a benchmark"),
        ({"protocols": ["easy", "loo"]}, r"protocols=\['easy', 'loo'\]: ToyBenchmark knows \['easy', 'fixed'\]"),
        ({"seed": [0]}, r"unknown compare config key\(s\) \['seed'\]"),
        (
            {"methods": {"knn": {"estimator": {"_target_": "sklearn.neighbors.NoSuchThing"}}}},
            "methods.knn.estimator: cannot build 'sklearn.neighbors.NoSuchThing'",
        ),
        ({"methods": {"knn": {"estimator": KNN, "params": {"n_neighbours": 2}}}}, "methods.knn: Invalid parameter"),
        (
            {"methods": {"net": {"learned": {"experiment": "x", "checkpoint": "worst"}}}},
            r"methods.net.learned.checkpoint='worst': one of \['best', 'last'\]",
        ),
    ],
)
def test_configuration_errors_name_the_culprit(tmp_path, change, message):
    cfg = {**_config(tmp_path, {"knn": {"estimator": KNN}}), **change}
    with pytest.raises(ComparisonError, match=message):
        run_comparison(cfg)


def test_compose_names_an_unknown_comparison_and_lists_the_known_ones():
    with pytest.raises(ComparisonError, match="comparison 'gaitt' not found: configs/compare/ holds .*gait"):
        compose(["gaitt"])
    cfg = compose(["gei_pca_lda", "seeds=[0,1]"])
    assert cfg.name == "gei_pca_lda" and list(cfg.seeds) == [0, 1] and list(cfg.methods) == ["gei_pca_lda"]
    assert cfg.out == "checkpoints/compare/gei_pca_lda"
    gait = compose(["compare=gait"])
    assert {k: m.get("learned", {}).get("experiment") for k, m in gait.methods.items()} == {
        "casiab_multitask": "casiab_multitask",
        "casiab_single_subject": "casiab_single_subject",
        "casiab_single_metric": "casiab_single_metric",
        "casiab_multitask_metric": "casiab_multitask",
        "gei_pca_lda": None,
    }


# ------------------------------------------------------------------------------------------ gait, end to end
@pytest.fixture(scope="module")
def gait_cache(tmp_path_factory):
    """`mocapkit synth casia-b --subjects 4 --frames 30` + `mocapkit prepare casia-b` (64×44 GEIs per cycle)."""
    from mocapkit.cli import main as cli

    root = tmp_path_factory.mktemp("casia")
    assert (
        cli(["synth", "casia-b", "--out", str(root / "silhouettes"), "--subjects", "4", "--frames", "30", "--quiet"])
        == 0
    )
    assert (
        cli(
            [
                "prepare",
                "casia-b",
                "--src",
                str(root / "silhouettes"),
                "--out",
                str(root / "gei"),
                "--skip-bad",
                "--quiet",
            ]
        )
        == 0
    )
    return root / "gei"


@pytest.mark.slow
def test_gait_learned_and_classical_methods_see_the_same_test_geis(gait_cache, tmp_path):
    """The single-task CNN (1 epoch) and GEI+PCA+LDA × both protocols × 2 seeds through `mocapkit compare gait`."""
    from mocapkit.cli import main as cli
    from mocapkit.datasets.casia_b.datamodule import GaitDataModule

    out = tmp_path / "cmp"
    assert (
        cli(
            [
                "compare",
                "gait",
                f"benchmark.root={gait_cache}",
                f"out={out}",
                "seeds=[0,1]",
                "only=[casiab_single_subject,gei_pca_lda]",
                "learned_overrides=['trainer.max_epochs=1','trainer.enable_progress_bar=false','data.batch_size=32']",
            ]
        )
        == 0
    )
    saved = json.loads((out / "results.json").read_text())
    cells = {(c["method"], c["protocol"], c["seed"]): c for c in saved["cells"]}
    assert set(cells) == {
        (m, p, s)
        for m in ("casiab_single_subject", "gei_pca_lda")
        for p in ("closed_set", "cross_subject")
        for s in (0, 1)
    }
    for protocol in ("closed_set", "cross_subject"):
        data = GaitDataModule(str(gait_cache), protocol=protocol)  # the CNN's own data module
        for seed in (0, 1):
            learned = cells[("casiab_single_subject", protocol, seed)]
            classical = cells[("gei_pca_lda", protocol, seed)]
            assert learned["kind"] == "learned" and classical["kind"] == "estimator"
            assert learned["test_sha1"] == classical["test_sha1"] == indices_sha1(data.test_idx)
            assert saved["splits"][protocol][str(seed)]["test_indices"] == data.test_idx.tolist()
            assert learned["run_dir"].endswith(f"casiab_single_subject_{protocol}_seed{seed}")
            assert (
                out
                / "runs"
                / "casiab_single_subject"
                / f"casiab_single_subject_{protocol}_seed{seed}"
                / "eval"
                / "metrics.json"
            ).is_file()
    assert 0.0 <= cells[("casiab_single_subject", "closed_set", 1)]["metrics"]["subject_accuracy"] <= 1.0
    assert set(cells[("gei_pca_lda", "cross_subject", 0)]["metrics"]) == {"rank1_nm", "rank1_bg", "rank1_cl"}
    text = (out / "results.md").read_text()
    row = next(line for line in text.splitlines() if line.startswith("| GEI+PCA+LDA | estimator |"))
    assert row.count("±") >= 3 and " | 2 | " in row  # mean ± sd over the 2 seeds
    assert "thesis: identify subject" in text and "CNN-LB" in text and "| single-task CNN | closed_set | 1 |" in text
    assert (out / "per_view.png").stat().st_size > 1000 and (out / "summary.png").stat().st_size > 1000


def test_cli_compare_reports_errors_by_name(capsys):
    from mocapkit.cli import main as cli

    assert cli(["compare", "no_such_comparison"]) == 2
    assert "comparison 'no_such_comparison' not found" in capsys.readouterr().err
    assert cli(["compare", "--help"]) == 0 and "mocapkit compare NAME" in capsys.readouterr().out
