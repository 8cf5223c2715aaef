"""Where the real third-party data lives for tests, and the skip marker when it is absent.

The files are never committed: they sit in ``../shared`` beside the checkout
(``$MOCAPKIT_SHARED`` overrides it), and tests that need them are skipped without it.
"""
import os
from pathlib import Path

import pytest

SHARED = Path(os.environ.get("MOCAPKIT_SHARED", Path(__file__).resolve().parents[2] / "shared"))


def needs(path: Path):
    """``@needs(path)``: skip the test when ``path`` does not exist."""
    return pytest.mark.skipif(not path.exists(), reason=f"real data not found at {path}")


NTU_SAMPLES = SHARED / "samples" / "ntu_skeleton"
