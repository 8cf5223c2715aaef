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


def synthetic_hdm05_folder(tmp_path_factory, classes, actors=("bd", "mm"), clips_per_actor: int = 2,
                           max_frames: int = 160) -> Path:
    """A synthetic HDM05 folder laid out as the real cuts: ``<actor>/HDM_<actor>.asf`` and
    ``<actor>/HDM_<actor>_<class>_<nnn>_120.amc`` (the generator writes them flat)."""
    import shutil

    from mocapkit.datasets.synthetic.hdm05 import HDM05SynthConfig, synthesize_hdm05

    raw = tmp_path_factory.mktemp("synth")
    synthesize_hdm05(raw, HDM05SynthConfig(classes=tuple(classes), actors=tuple(actors),
                                           clips_per_actor=clips_per_actor, max_frames=max_frames), progress=False)
    root = tmp_path_factory.mktemp("hdm05")
    for amc in sorted(raw.glob("*.amc")):
        cls, actor, number = amc.stem.rsplit("_", 2)
        (root / actor).mkdir(exist_ok=True)
        shutil.copy(raw / f"HDM_{actor}.asf", root / actor / f"HDM_{actor}.asf")
        shutil.copy(amc, root / actor / f"HDM_{actor}_{cls}_{number}_120.amc")
    return root
