"""The method registry (mocapkit.train.registry): names, defaults, the --set grammar and its errors, the safety
check of every _target_, and `mocapkit methods`."""

from __future__ import annotations

import pytest

from mocapkit.cli import main
from mocapkit.train import registry
from mocapkit.train.errors import ConfigError
from mocapkit.train.registry import (
    TASKS,
    build_method,
    default_method,
    describe,
    method_config,
    method_names,
)
from mocapkit.train.safety import UnsafeConfigError


def test_every_task_registers_methods_with_a_description():
    rows = describe()
    assert {row.task for row in rows} == set(TASKS)
    for row in rows:
        assert row.description and not row.description.startswith("#"), row
        assert row.target != "?", row
    learned = {(row.task, row.name) for row in rows if row.learned}
    assert {
        ("refinement", "learned"),
        ("refinement", "onnx"),
        ("retrieval", "embedding"),
        ("synthesis", "cvae"),
        ("kinect", "bigru"),
        ("recognition", "ntu_gcn"),
    } <= learned
    assert not learned & {
        ("refinement", "linear"),
        ("retrieval", "dtw_positions"),
        ("synthesis", "slfm"),
        ("kinect", "gp"),
        ("recognition", "pooled_logreg"),
        ("gait", "gei_pca_lda"),
    }


def test_defaults_are_registered_names():
    assert default_method("retrieval") == "dtw_world_frame"
    assert default_method("synthesis") == "slfm" and default_method("kinect") == "bigru_steady"
    assert default_method("refinement") == "linear" and default_method("gait") is None
    for task in TASKS:
        assert default_method(task) in (None, *method_names(task))


def test_set_is_hydra_grammar_on_the_node():
    assert build_method("refinement", "linear", ["extrapolate=hold"]).extrapolate == "hold"
    assert build_method("refinement", "lrmf", ["outlier_threshold=null"]).outlier_threshold is None
    assert build_method("retrieval", "dtw_positions", ["features=[positions,relational]"]).features == [
        "positions",
        "relational",
    ]
    assert build_method("kinect", "bigru", ["network={hidden: 16}"]).network == {"hidden": 16}
    assert build_method("synthesis", "perlin", ["footskate_cleanup=false"]).footskate_cleanup is False
    assert method_config("kinect", "gp", ["~w_temporal"]).get("w_temporal") is None  # back to the class default


@pytest.mark.parametrize(
    "setting, message",
    [
        ("w_banana=1", "has no parameter 'w_banana'; its parameters: w_spatial"),
        ("_target_=builtins.open", "has no parameter '_target_'"),
        ("+extra=1", "has no parameter 'extra'"),
        ("n_inducing=abc", "expected an integer"),
        ("w_spatial", "expected KEY=VALUE"),
        ("gp_input=[", "override 'gp_input=\\['"),
    ],
)
def test_set_errors_name_the_key(setting, message):
    with pytest.raises(ConfigError, match=message.replace("+", r"\+")):
        build_method("kinect", "gp", [setting])


def test_unknown_names_list_the_known_ones():
    with pytest.raises(
        ConfigError, match="unknown retrieval method 'nope'; known: amfs, dtw_large, dtw_mutual_proximity"
    ):
        build_method("retrieval", "nope")
    with pytest.raises(ConfigError, match="unknown task 'dance'"):
        method_names("dance")


def test_required_parameters_and_training_runs_are_refused_by_name():
    with pytest.raises(ConfigError, match="needs checkpoint"):
        build_method("refinement", "learned")
    with pytest.raises(ConfigError, match="mocapkit train experiment=ntu_gcn"):
        build_method("recognition", "ntu_gcn")


def test_a_method_file_may_only_name_its_task_classes(tmp_path, monkeypatch):
    folder = tmp_path / "refinement" / "method"
    folder.mkdir(parents=True)
    (folder / "evil.yaml").write_text("# touches a file\n_target_: pathlib.Path.touch\nself: /tmp/x\n")
    (folder / "wrong_task.yaml").write_text(
        "# a kinect class\n_target_: mocapkit.kinect.reconstruction.DoubleExponentialSmoother\n"
    )
    monkeypatch.setattr(registry, "CONFIG_DIR", tmp_path)
    for name in ("evil", "wrong_task"):
        with pytest.raises(UnsafeConfigError, match="expected a mocapkit MotionRefiner class"):
            build_method("refinement", name)


def test_methods_command_prints_the_table(capsys):
    assert main(["methods", "kinect"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split() == ["task", "name", "learned", "description"]
    rows = {line.split()[1]: line.split() for line in lines[1:-1]}
    assert set(rows) == set(method_names("kinect"))
    assert rows["bigru_steady"][:4] == ["kinect", "bigru_steady", "*", "yes"]  # the default, marked; trains a network
    assert rows["gp"][:3] == ["kinect", "gp", "no"]  # needs no trained network
    assert main(["methods", "dance"]) == 2
    assert "unknown task 'dance'" in capsys.readouterr().err
