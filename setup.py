"""Ship the Hydra configs inside the wheel.

The configs stay in one place, ``configs/`` at the repository root (they are not Python modules); a built
wheel carries a copy as ``mocapkit/configs/``, where :data:`mocapkit.train.config.CONFIG_DIR` finds it once
installed. An editable install (``pip install -e .``) copies nothing: it reads the checkout's ``configs/``.
Everything else about the package is in pyproject.toml.
"""

import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

CONFIGS = Path(__file__).resolve().parent / "configs"


class BuildPyWithConfigs(build_py):
    """``build_py``, then ``configs/`` copied to ``<build>/mocapkit/configs/`` (not for an editable install)."""

    def run(self):
        super().run()
        if self.editable_mode:
            return
        if not CONFIGS.is_dir():
            raise FileNotFoundError(f"{CONFIGS}: the Hydra configs the wheel ships are missing")
        target = Path(self.build_lib) / "mocapkit" / "configs"
        shutil.rmtree(target, ignore_errors=True)  # no config deleted since an earlier build ships again
        self.copy_tree(str(CONFIGS), str(target))


setup(cmdclass={"build_py": BuildPyWithConfigs})
