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


def synthetic_hdm05_folder(
    tmp_path_factory, classes, actors=("bd", "mm"), clips_per_actor: int = 2, max_frames: int = 160
) -> Path:
    """A synthetic HDM05 folder laid out as the real cuts: ``<actor>/HDM_<actor>.asf`` and
    ``<actor>/HDM_<actor>_<class>_<nnn>_120.amc`` (the generator writes them flat)."""
    import shutil

    from mocapkit.datasets.synthetic.hdm05 import HDM05SynthConfig, synthesize_hdm05

    raw = tmp_path_factory.mktemp("synth")
    synthesize_hdm05(
        raw,
        HDM05SynthConfig(
            classes=tuple(classes), actors=tuple(actors), clips_per_actor=clips_per_actor, max_frames=max_frames
        ),
        progress=False,
    )
    root = tmp_path_factory.mktemp("hdm05")
    for amc in sorted(raw.glob("*.amc")):
        cls, actor, number = amc.stem.rsplit("_", 2)
        (root / actor).mkdir(exist_ok=True)
        shutil.copy(raw / f"HDM_{actor}.asf", root / actor / f"HDM_{actor}.asf")
        shutil.copy(amc, root / actor / f"HDM_{actor}_{cls}_{number}_120.amc")
    return root


#: ``mocapkit synth ntu`` options of a tiny NTU-format set: 3 classes, 4 subjects, one setup, camera and take.
TINY_NTU_SYNTH = "--classes 3 --subjects 4 --setups 1 --replications 1 --cameras 1 --seed 5 --quiet".split()


def tiny_energy_vgg_run(root: Path, *overrides: str) -> Path:
    """Synthesise and prepare the tiny NTU-format set under ``root``, train the energy-image CNN for one epoch on it
    (32-pixel images; ``overrides`` on top) and return the run folder ``root/runs/ntu_energy_vgg/r``."""
    from mocapkit.cli import main

    assert main(["synth", "ntu", "--out", str(root / "synth"), *TINY_NTU_SYNTH]) == 0
    assert main(["prepare", "ntu", "--src", str(root / "synth"), "--out", str(root / "cache"), "--quiet"]) == 0
    train = [
        "train",
        "experiment=ntu_energy_vgg",
        f"data.root={root / 'cache'}",
        f"output_root={root / 'runs'}",
        "run_name=r",
        "trainer.max_epochs=1",
        "trainer.enable_progress_bar=false",
        "data.batch_size=8",
        "model.energy.size=32",
        "data.val_by_subject=false",
        *overrides,
    ]
    assert main(train) == 0
    return root / "runs" / "ntu_energy_vgg" / "r"


def tiny_bigru_refiner(motions, folder: Path, window: int, windows_per_epoch: int) -> tuple[Path, Path]:
    """``(best.ckpt, model.onnx)`` of a BiGRU refiner trained for one short epoch on ``motions`` (8 hidden units),
    written to ``folder``; its last layer re-drawn so that its corrections are visible."""
    import lightning
    import torch

    from mocapkit.deploy.refiner_export import export_refiner
    from mocapkit.refinement.learned import train_on_motions

    torch.set_num_threads(1)
    module = train_on_motions(
        "refine_bigru",
        motions,
        [
            "model.hidden=8",
            "model.layers=1",
            f"data.window={window}",
            f"data.windows_per_epoch={windows_per_epoch}",
            "data.batch_size=16",
            "trainer.max_epochs=1",
            "data.eval_windows_per_clip=1",
        ],
    )
    with torch.no_grad():  # one short epoch leaves the last layer near its zero start: make the corrections visible
        torch.nn.init.normal_(module.model.out.weight, std=0.05, generator=torch.Generator().manual_seed(0))
    ckpt = folder / "best.ckpt"
    checkpoint = {
        "state_dict": module.state_dict(),
        "hyper_parameters": dict(module.hparams),
        "pytorch-lightning_version": lightning.__version__,
    }
    torch.save(checkpoint, ckpt)
    onnx = folder / "model.onnx"
    export_refiner(module.model, onnx, dict(module.hparams.skeleton), trace_shape=(2, 4), check_shape=(2, 40))
    return ckpt, onnx
