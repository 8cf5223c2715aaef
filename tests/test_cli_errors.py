"""Every CLI error is one line, and outputs stay under output_root.

An error is ``mocapkit: error: MESSAGE`` naming the file, key or value and what was expected, then the
hint line about ``--debug``; exit code 2; no traceback unless ``mocapkit --debug`` or ``MOCAPKIT_DEBUG=1``.
"""

import json
import shutil
import zipfile
from pathlib import Path

import pytest
import torch

from mocapkit.cli import main
from mocapkit.train.config import ConfigError
from tests.shared_data import TINY_NTU_SYNTH


def one_line_error(capsys, rc: int, *expected: str) -> str:
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert rc == 2, err
    assert lines and lines[0].startswith("mocapkit: error: "), err
    assert len(lines) == 2 and "--debug" in lines[1], err  # one line, and the hint
    assert "Traceback" not in err
    for text in expected:
        assert text in lines[0], (text, err)
    return lines[0]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    root = tmp_path_factory.mktemp("clierr")
    assert main(["synth", "ntu", "--out", str(root / "synth"), *TINY_NTU_SYNTH]) == 0
    assert main(["prepare", "ntu", "--src", str(root / "synth"), "--out", str(root / "cache"), "--quiet"]) == 0
    return root


@pytest.fixture(scope="module")
def run_dir(workspace):
    assert (
        main(
            [
                "train",
                "experiment=ntu_energy_vgg",
                f"data.root={workspace / 'cache'}",
                f"output_root={workspace / 'runs'}",
                "run_name=r",
                "trainer.max_epochs=1",
                "trainer.enable_progress_bar=false",
                "data.batch_size=8",
                "model.energy.size=32",
                "data.val_by_subject=false",
            ]
        )
        == 0
    )
    return workspace / "runs" / "ntu_energy_vgg" / "r"


# --------------------------------------------------------------------------- config values


@pytest.mark.parametrize(
    "override, key",
    [
        ("trainer.max_epochs=abc", "trainer.max_epochs"),
        ("data.batch_size=many", "data.batch_size"),
        ("trainer.enable_progress_bar=maybe", "trainer.enable_progress_bar"),
        ("optimizer.lr=fast", "optimizer.lr"),
    ],
)
def test_a_value_of_the_wrong_type_is_named(tmp_path, capsys, override, key):
    rc = main(["train", f"data.root={tmp_path}", f"output_root={tmp_path / 'runs'}", override])
    one_line_error(capsys, rc, key, override.split("=")[1])
    rc = main(
        [
            "train",
            "-m",
            f"data.root={tmp_path}",
            f"output_root={tmp_path / 'runs'}",
            f"{key}=1,{override.split('=')[1]}" if "enable" not in key else f"{key}=true,maybe",
        ]
    )
    one_line_error(capsys, rc, key)
    assert not (tmp_path / "runs").exists()


def test_an_unknown_key_is_one_line(tmp_path, capsys):
    one_line_error(capsys, main(["train", f"data.root={tmp_path}", "data.no_such_key=1"]), "data.no_such_key")


# --------------------------------------------------------------------------- outputs stay under output_root


@pytest.mark.parametrize(
    "override",
    [
        "run_name=../../x",
        "run_name=/tmp/mocapkit-absolute-run",
        "run_name=a/b",
        "experiment_name=../../../x",
        "run_name=..",
        "run_name=''",
    ],
)
def test_run_and_experiment_names_are_one_folder_name(tmp_path, capsys, override):
    root = tmp_path / "root" / "out"
    rc = main(["train", f"data.root={tmp_path}", f"output_root={root}", override])
    one_line_error(capsys, rc, override.split("=")[0], "single folder name")
    assert not (tmp_path / "root").exists()
    assert not Path("/tmp/mocapkit-absolute-run").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_sweep_value_is_checked_before_any_folder_is_created(tmp_path, capsys):
    root = tmp_path / "out"
    rc = main(["train", "-m", f"data.root={tmp_path}", f"output_root={root}", "run_name=ok,../../escape"])
    one_line_error(capsys, rc, "run_name", "../../escape")
    assert not root.exists() and not (tmp_path / "escape").exists()


def test_a_run_dir_outside_output_root_is_refused(tmp_path, capsys):
    rc = main(["train", f"data.root={tmp_path}", f"output_root={tmp_path / 'out'}", f"run_dir={tmp_path / 'else'}"])
    one_line_error(capsys, rc, "run_dir", "output_root")
    assert not (tmp_path / "else").exists()


def test_an_unwritable_output_folder_is_one_line(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    rc = main(["train", f"data.root={tmp_path}", f"output_root={blocker / 'runs'}"])
    one_line_error(capsys, rc, str(blocker), "not a folder")


# --------------------------------------------------------------------------- damaged checkpoints


def damaged(kind: str, path: Path) -> None:
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "text":
        path.write_text("this is not a checkpoint\n")
    elif kind == "zip":
        with zipfile.ZipFile(path, "w") as z:
            z.writestr("hello.txt", "a zip, but not a checkpoint")
    elif kind == "truncated":
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 3])
    elif kind == "list":
        torch.save([1, 2, 3], path)
    elif kind == "folder":
        path.unlink()
        path.mkdir()


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["empty", "text", "zip", "truncated", "list", "folder"])
@pytest.mark.parametrize("cmd", ["eval", "export", "resume"])
def test_a_damaged_checkpoint_is_one_line(run_dir, tmp_path, capsys, kind, cmd):
    run = tmp_path / "run"
    shutil.copytree(run_dir, run)
    name = "last.ckpt" if cmd == "resume" else "best.ckpt"
    damaged(kind, run / name)
    argv = {
        "eval": ["eval", f"ckpt_path={run / name}"],
        "export": ["export", f"ckpt_path={run / name}", f"out={tmp_path / 'm.onnx'}"],
        "resume": ["train", f"resume={run / name}", "trainer.max_epochs=2"],
    }[cmd]
    one_line_error(capsys, main(argv), str(run / name))
    assert not (tmp_path / "m.onnx").exists()


@pytest.mark.slow
def test_a_checkpoint_outside_a_run_folder_is_one_line(run_dir, tmp_path, capsys):
    shutil.copy(run_dir / "best.ckpt", tmp_path / "best.ckpt")
    one_line_error(capsys, main(["eval", f"ckpt_path={tmp_path / 'best.ckpt'}"]), str(tmp_path), "run folder")


@pytest.mark.slow
def test_export_out_a_folder_is_one_line(run_dir, tmp_path, capsys):
    rc = main(["export", f"ckpt_path={run_dir / 'best.ckpt'}", f"out={tmp_path}"])
    one_line_error(capsys, rc, f"out={tmp_path}", "folder")


@pytest.mark.slow
def test_eval_out_dir_under_a_file_is_one_line(run_dir, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(run_dir, run)
    (tmp_path / "file").write_text("x")
    rc = main(
        [
            "eval",
            f"ckpt_path={run / 'best.ckpt'}",
            f"eval.out_dir={tmp_path / 'file' / 'eval'}",
            "trainer.enable_progress_bar=false",
        ]
    )
    one_line_error(capsys, rc, str(tmp_path / "file"))


# --------------------------------------------------------------------------- predict


def tiny_onnx(path: Path) -> Path:
    """A 3-class "skeleton classifier" (mean of x, y, z) written with onnx.helper: no export needed."""
    import onnx
    from onnx import TensorProto, helper

    node = helper.make_node("ReduceMean", ["skeletons"], ["logits"], axes=[1, 2, 3], keepdims=0)
    graph = helper.make_graph(
        [node],
        "tiny",
        [helper.make_tensor_value_info("skeletons", TensorProto.FLOAT, ["b", "m", "t", 25, 3])],
        [helper.make_tensor_value_info("logits", TensorProto.FLOAT, ["b", 3])],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    for key, value in {"class_names": json.dumps(["a", "b", "c"]), "layout": "ntu25"}.items():
        entry = model.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.save(model, str(path))
    return path


def test_predict_works_on_a_tiny_model(workspace, tmp_path, capsys):
    model = tiny_onnx(tmp_path / "tiny.onnx")
    skeleton = sorted((workspace / "synth").glob("*.skeleton"))[0]
    assert main(["predict", "--onnx", str(model), "--top", "1", str(skeleton)]) == 0
    assert skeleton.name in capsys.readouterr().out


@pytest.mark.parametrize("kind", ["text", "empty", "missing"])
def test_predict_on_a_non_onnx_file_is_one_line(workspace, tmp_path, capsys, kind):
    model = tmp_path / "model.onnx"
    if kind == "text":
        model.write_text("not a model")
    elif kind == "empty":
        model.write_bytes(b"")
    skeleton = sorted((workspace / "synth").glob("*.skeleton"))[0]
    one_line_error(capsys, main(["predict", "--onnx", str(model), str(skeleton)]), str(model))


def test_predict_on_a_nan_skeleton_is_one_line(workspace, tmp_path, capsys):
    model = tiny_onnx(tmp_path / "tiny.onnx")
    source = sorted((workspace / "synth").glob("*.skeleton"))[0]
    lines = source.read_text().splitlines()
    # the first joint line of the first body of the first frame: x y z ... → nan
    joint = next(i for i, line in enumerate(lines) if len(line.split()) == 12)
    fields = lines[joint].split()
    fields[0] = "nan"
    lines[joint] = " ".join(fields)
    bad = tmp_path / source.name
    bad.write_text("\n".join(lines) + "\n")
    one_line_error(capsys, main(["predict", "--onnx", str(model), str(bad)]), str(bad))


# --------------------------------------------------------------------------- --debug


def test_debug_flag_and_variable_show_the_traceback(tmp_path, capsys, monkeypatch):
    missing = tmp_path / "nowhere.ckpt"
    assert main(["eval", f"ckpt_path={missing}"]) == 2
    capsys.readouterr()
    with pytest.raises(ConfigError, match="nowhere.ckpt"):
        main(["--debug", "eval", f"ckpt_path={missing}"])
    monkeypatch.setenv("MOCAPKIT_DEBUG", "1")
    with pytest.raises(ConfigError):
        main(["eval", f"ckpt_path={missing}"])
    monkeypatch.setenv("MOCAPKIT_DEBUG", "0")
    assert main(["eval", f"ckpt_path={missing}"]) == 2


def test_an_unexpected_error_is_still_one_line(monkeypatch, capsys):
    import mocapkit.cli as cli

    def boom(_):
        raise AssertionError("an internal invariant")

    monkeypatch.setattr(cli, "cmd_eval", boom)
    one_line_error(capsys, cli.main(["eval", "ckpt_path=x"]), "AssertionError", "an internal invariant")
