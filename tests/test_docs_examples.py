"""The worked examples of docs/extending.md run as the page shows them.

Each example is code a contributor saves into the package (``mocapkit/refinement/moving_average.py``, ...) and a
config file saved into ``configs/``. The test does the same without touching the checkout: the config files go
into a copy of ``configs/`` named by ``MOCAPKIT_CONFIG_DIR``, and the code into a temporary folder appended to the
package's ``__path__``, so ``import mocapkit.refinement.moving_average`` finds it where the page says to save it.
Each example then runs in a fresh Python process, as a user would run it.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "docs" / "examples"


@pytest.fixture
def workspace(tmp_path: Path) -> Path:
    """A copy of configs/ and empty package folders in ``tmp_path``; the examples' files are added by each test."""
    shutil.copytree(ROOT / "configs", tmp_path / "configs")
    for package in ("refinement", "datasets", "recognition"):
        (tmp_path / "packages" / package).mkdir(parents=True)
    return tmp_path


def _add(workspace: Path, package: str, *files: str) -> None:
    """Save example files as the page says: ``package`` is the folder under mocapkit/ they go into."""
    for name in files:
        source = EXAMPLES / name
        target = workspace / "packages" / package / source.name
        (shutil.copytree if source.is_dir() else shutil.copy)(source, target)


def _run(workspace: Path, code: str, timeout: int = 600) -> subprocess.CompletedProcess:
    """Run ``code`` in a fresh interpreter in ``workspace``, with the saved configs and package files in place."""
    prelude = textwrap.dedent(f"""
        import mocapkit.datasets, mocapkit.recognition, mocapkit.refinement
        for package in (mocapkit.datasets, mocapkit.recognition, mocapkit.refinement):
            package.__path__.append({str(workspace / "packages")!r} + "/" + package.__name__.split(".")[-1])
    """)
    env = {**os.environ, "MOCAPKIT_CONFIG_DIR": str(workspace / "configs"), "OMP_NUM_THREADS": "1"}
    result = subprocess.run(
        [sys.executable, "-c", prelude + code], cwd=workspace, env=env, capture_output=True, text=True, timeout=timeout
    )
    assert result.returncode == 0, f"stdout:\n{result.stdout[-3000:]}\nstderr:\n{result.stderr[-3000:]}"
    return result


def _run_example(workspace: Path, script: str) -> subprocess.CompletedProcess:
    return _run(workspace, f"import runpy; runpy.run_path({str(EXAMPLES / script)!r}, run_name='__main__')")


def _takes(workspace: Path) -> None:
    """data/takes: synthetic HDM05-like takes named <action>_<performer>_<take>.amc, 3 performers, 2 actions."""
    from mocapkit.datasets.synthetic.hdm05 import HDM05SynthConfig, synthesize_hdm05

    synthesize_hdm05(
        workspace / "data" / "takes",
        HDM05SynthConfig(
            classes=("walk2StepsLstart", "jumpingJack1Reps"),
            actors=("bd", "bk", "dg"),
            clips_per_actor=2,
            max_frames=90,
        ),
        progress=False,
    )


def test_add_a_method(workspace):
    shutil.copy(EXAMPLES / "refinement" / "moving-average.yaml", workspace / "configs" / "refinement" / "method")
    _add(workspace, "refinement", "refinement/moving_average.py")
    out = _run_example(workspace, "refinement/use_moving_average.py")
    assert "MovingAverageRefiner" in out.stdout
    # the registry lists it with the first comment line of its file
    listed = _run(workspace, "from mocapkit.train.registry import methods_table; print(methods_table('refinement'))")
    assert "moving-average" in listed.stdout and "mean of the observed samples" in listed.stdout
    # and the page's command line, on a C3D take with a 6-frame gap
    out = _run(
        workspace,
        textwrap.dedent("""
        import sys
        import numpy as np
        from mocapkit.cli import main
        from mocapkit.datasets.formats.motion_io import write_motion
        from mocapkit.motion.container import Motion

        t = np.linspace(0.0, 1.0, 120)
        hand = np.stack([np.sin(2 * np.pi * t), 1.0 + 0.1 * t, 0.5 + 0.0 * t], axis=-1)
        positions = np.stack([hand + 0.5, hand], axis=1)
        positions[40:46, 1] = np.nan
        write_motion("take.c3d", Motion(positions=positions, joint_names=("root", "hand"), fps=120.0))
        sys.exit(main(["refine", "take.c3d", "out.c3d", "--method", "moving-average", "--set", "half_window=3"]))
    """),
    )
    assert "MovingAverageRefiner" in out.stdout and "filled 6 of 6 missing samples" in out.stdout


def test_a_method_without_its_file_is_unknown(workspace):
    """Without the config file the name is not a method: the example's config is what registers it."""
    _add(workspace, "refinement", "refinement/moving_average.py")
    result = subprocess.run(
        [
            sys.executable,
            "-c",
            "from mocapkit.train.registry import build_method; build_method('refinement', 'moving-average')",
        ],
        cwd=workspace,
        capture_output=True,
        text=True,
        env={**os.environ, "MOCAPKIT_CONFIG_DIR": str(workspace / "configs")},
    )
    assert result.returncode != 0 and "unknown refinement method 'moving-average'" in result.stderr


def test_add_a_data_set(workspace):
    shutil.copy(EXAMPLES / "datasets" / "takes.yaml", workspace / "configs" / "data")
    _add(workspace, "datasets", "datasets/takes")
    _takes(workspace)
    out = _run_example(workspace, "datasets/use_takes.py")
    assert "'test_subjects': ['dg']" in out.stdout
    # the page's training and evaluation commands, one epoch
    _run(
        workspace,
        textwrap.dedent("""
        import sys
        from mocapkit.cli import main
        rc = main(["train", "experiment=hdm05_gcn", "data=takes", "data.root=data/takes", "data.test_performers=[dg]",
                   "trainer.max_epochs=1", "output_root=runs", "run_name=takes"])
        sys.exit(rc or main(["eval", "ckpt_path=runs/hdm05_gcn/takes/last.ckpt"]))
    """),
    )
    metrics = json.loads((workspace / "runs" / "hdm05_gcn" / "takes" / "eval" / "metrics.json").read_text())
    assert metrics["test_subjects"] == ["dg"] and metrics["sample_counts"]["test"] == 4


def test_add_a_benchmark(workspace):
    shutil.copy(EXAMPLES / "datasets" / "takes.yaml", workspace / "configs" / "data")
    shutil.copy(EXAMPLES / "benchmark" / "takes_recognition.yaml", workspace / "configs" / "compare")
    _add(workspace, "datasets", "datasets/takes")
    _add(workspace, "recognition", "benchmark/benchmark_takes.py")
    _takes(workspace)
    _run(
        workspace,
        "import sys; from mocapkit.cli import main; "
        "sys.exit(main(['compare', 'takes_recognition', 'benchmark.root=data/takes']))",
    )
    results = json.loads((workspace / "checkpoints" / "compare" / "takes_recognition" / "results.json").read_text())
    cells = {(c["method"], c["protocol"]): c for c in results["cells"]}
    assert set(cells) == {(m, f"test_{p}") for m in ("pooled_logreg", "majority") for p in ("bd", "bk", "dg")}
    assert all(c["n_test"] == 4 for c in cells.values())  # each performer's 4 takes
    mean = {
        m: sum(c["metrics"]["accuracy"] for (k, _), c in cells.items() if k == m) / 3
        for m in ("pooled_logreg", "majority")
    }
    assert mean["pooled_logreg"] > mean["majority"]  # the baseline learns something chance does not
