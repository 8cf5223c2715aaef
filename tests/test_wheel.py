"""The built wheel works on its own: configs inside, console script, commands run from any folder.

The wheel is built from a copy of the checkout (``pip wheel --no-deps --no-build-isolation``) and installed
(``--no-deps``) into a fresh virtual environment outside the checkout, whose dependencies come from the
project's environment through a ``.pth`` line: a folder named in a ``.pth`` file joins ``sys.path`` but its own
``.pth`` files are not run, so the editable install's import hook stays out and ``import mocapkit`` finds the
wheel's copy. The commands run in an empty folder, so nothing resolves against the checkout.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import numpy as np
import pytest
import yaml

from mocapkit.datasets.formats.c3d import read_c3d, write_c3d
from mocapkit.motion.container import Motion

pytestmark = pytest.mark.slow

REPO = Path(__file__).resolve().parents[1]
#: Top-level folders of the checkout a build does not need (environments, outputs, caches).
NOT_BUILT = {".venv", ".git", "build", "dist", "checkpoints", "data", "outputs", ".demo", "docs", "tests", "bench"}


def _copy_ignore(folder: str, names: list[str]) -> list[str]:
    top = Path(folder) == REPO
    return [n for n in names if (top and n in NOT_BUILT) or n == "__pycache__" or n.endswith((".egg-info", "_cache"))]


def _run(command: list, cwd: Path, env: dict, timeout: int = 120) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [str(c) for c in command], cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout, check=False
    )
    assert proc.returncode == 0, f"{command}: exit {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc


@pytest.fixture(scope="module")
def installed(tmp_path_factory) -> tuple[Path, Path, dict]:
    """``(bin folder of the fresh environment, an empty working folder, the environment variables)``."""
    root = tmp_path_factory.mktemp("wheel")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "MOCAPKIT_CONFIG_DIR", "PYTHONHOME")}
    # build from a copy: an in-tree build would leave build/ and egg-info in the checkout (and stale files in build/)
    source = root / "src"
    shutil.copytree(REPO, source, ignore=_copy_ignore)
    _run(
        [sys.executable, "-m", "pip", "wheel", source, "--no-deps", "--no-build-isolation", "-q", "-w", root / "dist"],
        root,
        env,
        timeout=300,
    )
    (wheel,) = (root / "dist").glob("mocapkit-*.whl")

    venv = root / "venv"
    _run([sys.executable, "-m", "venv", "--without-pip", venv], root, env)
    python = venv / "bin" / "python"
    # installed before the .pth line exists, so pip sees no mocapkit (the editable one) in this environment
    _run([sys.executable, "-m", "pip", "--python", python, "install", "--no-deps", "-q", wheel], root, env, timeout=300)
    site = Path(
        _run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"], root, env).stdout.strip()
    )
    (site / "project_dependencies.pth").write_text(sysconfig.get_path("purelib") + "\n")

    work = root / "work"
    work.mkdir()
    where = _run(
        [python, "-c", "import mocapkit, mocapkit.train.config as c; print(mocapkit.__file__); print(c.CONFIG_DIR)"],
        work,
        env,
    ).stdout.split()
    assert Path(where[0]).is_relative_to(site), where  # the wheel's copy, not the checkout's
    assert Path(where[1]) == site / "mocapkit" / "configs", where
    assert (site / "mocapkit" / "datasets" / "mocap" / "data" / "hdm05_classes.tsv").is_file()
    return venv / "bin", work, env


def test_train_prints_its_config(installed):
    bin_dir, work, env = installed
    cfg = yaml.safe_load(_run([bin_dir / "mocapkit", "train", "--cfg", "job"], work, env).stdout)
    assert {"model", "data", "trainer", "task", "optimizer"} <= set(cfg), sorted(cfg)
    assert cfg["trainer"]["_target_"] == "lightning.Trainer" and "max_steps" in cfg["trainer"]


def test_methods_lists_the_registry(installed):
    bin_dir, work, env = installed
    table = _run([bin_dir / "mocapkit", "methods"], work, env).stdout
    assert "refinement" in table and "linear" in table and "recognition" in table


def test_refine_fills_the_gaps_of_a_file(installed):
    bin_dir, work, env = installed
    # a BVH holds no gaps (write_bvh refuses NaN): the gaps are written to a C3D, which marks them invalid
    t = np.linspace(0.0, 1.0, 60, dtype=np.float32)
    positions = np.stack([np.stack([t + j, np.sin(3 * t) + j, 0.1 * j + t**2], axis=1) + 1.0 for j in range(4)], axis=1)
    gappy = positions.copy()
    gappy[20:30, 1] = np.nan
    gappy[40:44, 3] = np.nan
    write_c3d(work / "gaps.c3d", Motion(positions=gappy, joint_names=("A", "B", "C", "D"), fps=60.0))
    _run([bin_dir / "mocapkit", "refine", "gaps.c3d", "filled.c3d", "--method", "linear"], work, env)
    before, after = read_c3d(work / "gaps.c3d"), read_c3d(work / "filled.c3d")
    assert before.missing.sum() == 14 and not after.missing.any()
    np.testing.assert_allclose(after.positions[~before.missing], before.positions[~before.missing], atol=1e-4)
