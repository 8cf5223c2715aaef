"""Loading a checkpoint or opening a run folder never runs code.

A real tiny run is trained once; each test copies its folder and plants a payload — a Hydra ``_target_``
that would create, empty or overwrite a "victim" file — in the checkpoint's ``hyper_parameters`` or in the
run's ``.hydra/config.yaml``. ``eval``, ``export`` and ``train resume=`` must refuse it with exit code 2 and
one line naming the file and the key, and the victim must be untouched. ``predict`` loads ONNX only (and
never imports torch); ``refine`` builds only MotionRefiner classes.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from omegaconf import OmegaConf

from mocapkit.cli import main
from tests.shared_data import tiny_energy_vgg_run

pytestmark = pytest.mark.slow

ORIGINAL = "precious contents\n"


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    root = tmp_path_factory.mktemp("security")
    tiny_energy_vgg_run(root)
    return root


@pytest.fixture(scope="module")
def run_dir(workspace):
    return workspace / "runs" / "ntu_energy_vgg" / "r"


def copy_run(run_dir: Path, tmp_path: Path) -> Path:
    copy = tmp_path / "run"
    shutil.copytree(run_dir, copy)
    return copy


def plant_in_checkpoints(run: Path, mutate) -> None:
    for name in ("best.ckpt", "last.ckpt"):
        state = torch.load(run / name, map_location="cpu", weights_only=True)
        mutate(state["hyper_parameters"])
        torch.save(state, run / name)


def plant_in_config(run: Path, key: str, node: dict) -> None:
    path = run / ".hydra" / "config.yaml"
    cfg = OmegaConf.load(path)
    OmegaConf.update(cfg, key, node, merge=False, force_add=True)
    OmegaConf.save(cfg, path)


# --------------------------------------------------------------------------- the payloads


def touch_model(victim):  # (a) pathlib.Path.touch as "the model": would create the file
    return (
        "ckpt",
        "hyper_parameters.model",
        lambda hp: hp.update(model={"_target_": "pathlib.Path.touch", "self": str(victim)}),
    )


def open_model(victim):  # (b) builtins.open(victim, "w") as "the model": would empty the file
    return (
        "ckpt",
        "hyper_parameters.model",
        lambda hp: hp.update(model={"_target_": "builtins.open", "_args_": [str(victim), "w"]}),
    )


def mocapkit_writer_model(victim):  # (d) a mocapkit function that writes files, as "the model"
    return (
        "ckpt",
        "hyper_parameters.model",
        lambda hp: hp.update(
            model={"_target_": "mocapkit.datasets.formats.motion_io.write_motion", "path": str(victim)}
        ),
    )


def nested_in_optimizer(victim):  # an allowed optimizer whose argument is a payload (recursive instantiate)
    return (
        "ckpt",
        "hyper_parameters.optimizer.lr",
        lambda hp: hp.update(
            optimizer={
                "_target_": "torch.optim.SGD",
                "_partial_": True,
                "lr": {"_target_": "builtins.open", "_args_": [str(victim), "w"]},
            }
        ),
    )


def partial_numpy(victim):  # _partial_ on a non-allowed target
    return (
        "ckpt",
        "hyper_parameters.scheduler",
        lambda hp: hp.update(scheduler={"_target_": "numpy.save", "_partial_": True, "file": str(victim), "arr": [1]}),
    )


def lightning_instantiator(victim):  # Lightning's own instantiator keys
    return (
        "ckpt",
        "hyper_parameters._instantiator",
        lambda hp: hp.update(_instantiator="lightning.pytorch.cli.instantiate_module", _class_path="shutil.copyfile"),
    )


def copy_as_data(victim, source):  # (c) the run config's data module is shutil.copyfile(source, victim)
    return "config", "data._target_", ("data", {"_target_": "shutil.copyfile", "src": str(source), "dst": str(victim)})


def copy_as_evaluator(victim, source):  # (c) the evaluator is shutil.copyfile
    return (
        "config",
        "eval.evaluator._target_",
        ("eval.evaluator", {"_target_": "shutil.copyfile", "_partial_": True, "src": str(source), "dst": str(victim)}),
    )


def mocapkit_writer_as_model_config(victim, source):  # (d) in the config's model node
    return (
        "config",
        "model._target_",
        ("model", {"_target_": "mocapkit.datasets.formats.motion_io.write_motion", "path": str(victim)}),
    )


CKPT_PAYLOADS = [
    touch_model,
    open_model,
    mocapkit_writer_model,
    nested_in_optimizer,
    partial_numpy,
    lightning_instantiator,
]
CONFIG_PAYLOADS = [copy_as_data, copy_as_evaluator, mocapkit_writer_as_model_config]
COMMANDS = ["eval", "export", "resume"]


def command(name: str, run: Path, tmp_path: Path) -> list[str]:
    if name == "eval":
        return ["eval", f"ckpt_path={run / 'best.ckpt'}", "trainer.enable_progress_bar=false"]
    if name == "export":
        return ["export", f"ckpt_path={run / 'best.ckpt'}", f"out={tmp_path / 'model.onnx'}"]
    return ["train", f"resume={run / 'last.ckpt'}", "trainer.max_epochs=2", "trainer.enable_progress_bar=false"]


def assert_refused(capsys, rc: int, files: list[str], key: str) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert lines[0].startswith("mocapkit: error: ") and len(lines) == 2, err  # one line (+ the --debug hint)
    assert any(f in lines[0] for f in files), (files, err)
    assert key in lines[0], (key, err)
    assert "Traceback" not in err
    return lines[0]


@pytest.mark.parametrize("cmd", COMMANDS)
@pytest.mark.parametrize("payload", CKPT_PAYLOADS, ids=lambda p: p.__name__)
def test_checkpoint_payloads_are_refused(run_dir, tmp_path, capsys, cmd, payload):
    run = copy_run(run_dir, tmp_path)
    victim = tmp_path / "victim.txt"
    new_victim = tmp_path / "created.txt"
    victim.write_text(ORIGINAL)
    target = new_victim if payload in (touch_model, mocapkit_writer_model, partial_numpy) else victim
    _, key, mutate = payload(target)
    plant_in_checkpoints(run, mutate)
    before = (run / "last.ckpt").read_bytes()
    rc = main(command(cmd, run, tmp_path))
    ckpt = run / ("last.ckpt" if cmd == "resume" else "best.ckpt")
    assert_refused(capsys, rc, [str(ckpt)], key)
    assert victim.read_text() == ORIGINAL
    assert not new_victim.exists()
    assert not (tmp_path / "model.onnx").exists()
    assert (run / "last.ckpt").read_bytes() == before  # resume did not start
    assert not (run / "eval").exists()


@pytest.mark.parametrize("cmd", COMMANDS)
@pytest.mark.parametrize("payload", CONFIG_PAYLOADS, ids=lambda p: p.__name__)
def test_run_config_payloads_are_refused(run_dir, tmp_path, capsys, cmd, payload):
    run = copy_run(run_dir, tmp_path)
    victim, source = tmp_path / "victim.txt", tmp_path / "source.txt"
    victim.write_text(ORIGINAL)
    source.write_text("attacker's contents\n")
    _, key, (node_key, node) = payload(victim, source)
    plant_in_config(run, node_key, node)
    rc = main(command(cmd, run, tmp_path))
    assert_refused(capsys, rc, [str(run / ".hydra" / "config.yaml")], key.removesuffix("._target_"))
    assert victim.read_text() == ORIGINAL
    assert not (tmp_path / "model.onnx").exists()
    assert not (run / "eval").exists()


def test_a_module_target_outside_mocapkit_train_is_refused(run_dir, tmp_path, capsys):
    run = copy_run(run_dir, tmp_path)
    victim = tmp_path / "created.txt"
    plant_in_config(run, "module", {"_target_": "pathlib.Path.touch", "self": str(victim)})
    assert_refused(capsys, main(command("eval", run, tmp_path)), [str(run / ".hydra" / "config.yaml")], "module")
    assert not victim.exists()


def test_an_override_cannot_bring_a_payload(run_dir, tmp_path, capsys):
    run = copy_run(run_dir, tmp_path)
    victim = tmp_path / "created.txt"
    rc = main(
        [
            "eval",
            f"ckpt_path={run / 'best.ckpt'}",
            "eval.evaluator._target_=pathlib.Path.touch",
            f"+eval.evaluator.self={victim}",
        ]
    )
    assert_refused(capsys, rc, [str(run)], "eval.evaluator")
    assert not victim.exists()


def test_the_untouched_run_still_evaluates(run_dir, tmp_path, capsys):
    run = copy_run(run_dir, tmp_path)
    assert main(["eval", f"ckpt_path={run / 'best.ckpt'}", "trainer.enable_progress_bar=false"]) == 0
    assert json.loads((run / "eval" / "metrics.json").read_text())["num_samples"] > 0


# --------------------------------------------------------------------------- predict: ONNX only, no torch

PREDICT_PROBE = """
import sys
from mocapkit.cli import main
rc = main(sys.argv[1:])
print("TORCH_IMPORTED" if "torch" in sys.modules else "NO_TORCH", rc)
"""


def _predict(*argv) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-c", PREDICT_PROBE, "predict", *map(str, argv)],
        capture_output=True,
        text=True,
        cwd=Path(__file__).resolve().parents[1],
        timeout=120,
    )


def test_predict_refuses_a_checkpoint_and_never_imports_torch(run_dir, workspace, tmp_path):
    fake = tmp_path / "model.onnx"
    shutil.copy(run_dir / "best.ckpt", fake)  # a pickle-based checkpoint named like an ONNX file
    skeleton = sorted((workspace / "synth").glob("*.skeleton"))[0]
    result = _predict("--onnx", fake, skeleton)
    assert "NO_TORCH 2" in result.stdout, result.stdout + result.stderr
    err = result.stderr.strip().splitlines()
    assert err[0].startswith("mocapkit: error: ") and str(fake) in err[0] and len(err) == 2, result.stderr


# --------------------------------------------------------------------------- refine: registry entries configs/refinement/method/*.yaml only


@pytest.mark.parametrize(
    "setting",
    [
        "refiner._target_=builtins.open",
        "_target_=builtins.open",
        "+refiner._target_=builtins.open",
        "++_target_=builtins.open",
        "++refiner._target_=pathlib.Path.touch",
        "+x._target_=builtins.open",
        "+x={_target_: shutil.copyfile, src: a, dst: b}",
    ],
)
def test_refine_refuses_a_target_override(tmp_path, capsys, setting):
    from mocapkit.train.config import ConfigError
    from mocapkit.train.registry import build_method

    with pytest.raises(ConfigError, match="_target_"):
        build_method("refinement", "linear", [setting])
    src = tmp_path / "in.npz"
    rc = main(["refine", str(src), str(tmp_path / "out.npz"), "--method", "linear", "--set", setting])
    err = capsys.readouterr().err
    assert rc == 2 and err.startswith("mocapkit: error: ") and "_target_" in err.splitlines()[0], err
    assert not (tmp_path / "out.npz").exists()
