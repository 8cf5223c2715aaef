"""Tests of the product scripts under ``scripts/`` and of the benchmarks' own modes (neither is a package:
:func:`load_script` imports one by its path)."""

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def load_script(relative: str):
    """The script ``ROOT / relative`` (e.g. ``"scripts/results/retrieval_within.py"``) imported as a module."""
    path = ROOT / relative
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
