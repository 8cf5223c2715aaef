"""``mocapkit train`` takes Hydra's whole command line, and every ``lightning.Trainer`` argument is a trainer key.

Hydra's flags work with their value as a separate word (``--cfg job``, ``-p trainer``) anywhere on the line;
``--help`` is Hydra's (the config groups and their options). The trainer node's schema is Lightning's signature
(mocapkit/train/trainer_schema.py), so ``trainer.max_steps=5`` needs no ``+`` and a misspelt key fails naming
it. Runs saved before the schema (a trainer node with only the keys they set) still load for eval, export and
resume, and take the other trainer keys there too.
"""

import inspect
import shutil
from pathlib import Path

import lightning
import pytest
import yaml
from omegaconf import OmegaConf

from mocapkit.cli import main
from mocapkit.train.config import CONFIG_DIR, ConfigError, compose_config
from mocapkit.train.trainer_schema import SET_ELSEWHERE, trainer_keys
from mocapkit.train.training import build_trainer
from tests.shared_data import tiny_energy_vgg_run


def printed(capsys, argv: list[str]) -> str:
    rc = main(argv)
    out, err = capsys.readouterr()
    assert rc == 0, err
    return out


def error_line(capsys, argv: list[str]) -> str:
    rc = main(argv)
    lines = capsys.readouterr().err.strip().splitlines()
    assert rc == 2 and lines and lines[0].startswith("mocapkit: error: "), lines
    return lines[0]


# --------------------------------------------------------------------------- Hydra's flags


@pytest.mark.parametrize(
    "flags",
    [
        ["--cfg", "job"],
        ["-c", "job"],
        ["--cfg=job"],
        ["trainer.max_steps=7", "--cfg", "job"],
        ["--cfg", "job", "--resolve", "data.root=/somewhere"],
    ],
)
def test_cfg_job_prints_the_composed_config(capsys, flags):
    cfg = yaml.safe_load(printed(capsys, ["train", *flags]))
    assert {"data", "model", "task", "optimizer", "scheduler", "trainer", "callbacks", "logger"} <= set(cfg)
    assert cfg["trainer"]["max_epochs"] == 30 and cfg["trainer"]["max_steps"] == (
        7 if "trainer.max_steps=7" in flags else -1
    )
    if "--resolve" in flags:
        assert cfg["scheduler"]["T_max"] == 30 and cfg["data"]["root"] == "/somewhere"  # interpolations resolved
    else:
        assert cfg["scheduler"]["T_max"] == "${trainer.max_epochs}"


def test_cfg_all_hydra_and_package(capsys):
    everything = yaml.safe_load(printed(capsys, ["train", "--cfg", "all"]))
    assert "hydra" in everything and "trainer" in everything
    hydra = yaml.safe_load(printed(capsys, ["train", "--cfg", "hydra"]))
    assert set(hydra) == {"hydra"} and hydra["hydra"]["run"]["dir"] == "${run_dir}"
    for package in (["--package", "trainer"], ["-p", "trainer"]):
        trainer = yaml.safe_load(printed(capsys, ["train", "--cfg", "job", *package, "trainer.limit_val_batches=0.5"]))
        assert trainer["_target_"] == "lightning.Trainer" and trainer["limit_val_batches"] == 0.5


def test_help_lists_the_config_groups(capsys):
    text = printed(capsys, ["train", "--help"])
    assert "mocapkit train --cfg job" in text  # the header
    groups = text.split("== Configuration groups ==")[1].split("== Config ==")[0]
    options = dict(line.split(": ", 1) for line in groups.splitlines() if ": " in line)
    for group in ("data", "model", "task", "experiment", "optimizer", "scheduler", "trainer", "callbacks", "logger"):
        expected = sorted(p.stem for p in (CONFIG_DIR / group).glob("*.yaml"))
        assert options[group].split(", ") == expected, group
    assert "trainer.max_steps" in text  # the footer


@pytest.mark.parametrize(
    "argv, words",
    [(["--cfg", "jobb"], ["--cfg", "jobb"]), (["--no-such-flag"], ["--no-such-flag"]), (["--cfg"], ["--cfg"])],
)
def test_a_bad_flag_is_one_line(capsys, argv, words):
    line = error_line(capsys, ["train", *argv])
    assert all(word in line for word in words), line


# --------------------------------------------------------------------------- the trainer keys


def test_documented_trainer_keys_compose_without_plus():
    cfg = compose_config(
        [
            "trainer.max_steps=5",
            "trainer.limit_val_batches=0.5",
            "trainer.max_time=00:00:01:00",
            "trainer.devices=auto",
            "trainer.sync_batchnorm=true",
        ]
    )
    assert cfg.trainer.max_steps == 5 and cfg.trainer.limit_val_batches == 0.5
    assert cfg.trainer.max_time == "00:00:01:00" and cfg.trainer.devices == "auto" and cfg.trainer.sync_batchnorm
    # build_trainer, as `mocapkit train` does: it resolves precision=auto (the default) before Lightning sees it
    trainer = build_trainer(cfg.trainer, logger=False, enable_progress_bar=False, enable_checkpointing=False)
    assert isinstance(trainer, lightning.Trainer)
    assert trainer.max_steps == 5 and trainer.limit_val_batches == 0.5
    # fast_dev_run takes a number of batches as well as true / false (its default)
    assert compose_config(["trainer.fast_dev_run=2"]).trainer.fast_dev_run == 2


def test_the_schema_is_lightnings_signature_with_the_projects_values():
    signature = inspect.signature(lightning.Trainer.__init__).parameters
    assert set(trainer_keys()) == {"_target_", *signature} - {"self", *SET_ELSEWHERE}
    node = compose_config(config_name="trainer/default").trainer
    ours = yaml.safe_load((CONFIG_DIR / "trainer" / "default.yaml").read_text())
    for key in trainer_keys():
        expected = ours[key] if key in ours else signature[key].default
        assert node[key] == expected, key


@pytest.mark.parametrize(
    "override, words",
    [
        ("trainer.max_stepz=5", ["trainer.max_stepz", "max_steps"]),
        ("+trainer.no_such_argument=1", ["no_such_argument"]),
        ("trainer.logger=false", ["trainer.logger", "logger group"]),
        ("trainer.max_steps=abc", ["trainer.max_steps", "abc", "integer"]),
        ("trainer.min_epochs=abc", ["trainer.min_epochs", "abc"]),
    ],
)
def test_a_bad_trainer_key_or_value_is_named(capsys, override, words):
    with pytest.raises(ConfigError, match=words[0].replace("+", r"\+")):
        compose_config([override])
    line = error_line(capsys, ["train", "data.root=x", override])
    assert all(word in line for word in words), line


# --------------------------------------------------------------------------- runs saved before the schema


@pytest.fixture(scope="module")
def old_run(tmp_path_factory) -> Path:
    """A tiny run whose saved config has the trainer node runs had before the schema: only the keys they set."""
    root = tmp_path_factory.mktemp("oldrun")
    tiny_energy_vgg_run(root)
    run = root / "runs" / "ntu_energy_vgg" / "r"
    saved = run / ".hydra" / "config.yaml"
    cfg = OmegaConf.load(saved)
    assert "max_steps" in cfg.trainer  # a new run keeps every trainer key
    cfg.trainer = {
        "_target_": "lightning.Trainer",
        "max_epochs": 1,
        "accelerator": "auto",
        "devices": 1,
        "strategy": "auto",
        "num_nodes": 1,
        "precision": "32-true",
        "log_every_n_steps": 10,
        "gradient_clip_val": None,
        "enable_progress_bar": False,
        "check_val_every_n_epoch": 1,
    }
    OmegaConf.save(cfg, saved)
    return run


@pytest.mark.slow
def test_an_old_run_still_evaluates_exports_and_resumes(old_run, tmp_path, capsys):
    run = tmp_path / "run"
    shutil.copytree(old_run, run)
    assert main(["eval", f"ckpt_path={run / 'best.ckpt'}", "trainer.enable_progress_bar=false"]) == 0
    assert main(["export", f"ckpt_path={run / 'best.ckpt'}", f"out={tmp_path / 'model.onnx'}"]) == 0
    assert (tmp_path / "model.onnx").is_file()
    capsys.readouterr()
    # a trainer key the old run did not save is taken on resume too (added to its config)
    resumed = yaml.safe_load(
        printed(
            capsys,
            [
                "train",
                f"resume={run / 'last.ckpt'}",
                "trainer.max_epochs=2",
                "trainer.limit_train_batches=1",
                "--cfg",
                "job",
            ],
        )
    )
    assert resumed["trainer"]["max_epochs"] == 2 and resumed["trainer"]["limit_train_batches"] == 1
    assert main(["train", f"resume={run / 'last.ckpt'}", "trainer.max_epochs=2", "trainer.limit_train_batches=1"]) == 0
    saved = OmegaConf.load(run / ".hydra" / "config.yaml")
    assert saved.trainer.max_epochs == 2 and saved.trainer.limit_train_batches == 1
    line = error_line(capsys, ["train", f"resume={run / 'last.ckpt'}", "trainer.max_stepz=3"])
    assert "max_stepz" in line and "max_steps" in line
    line = error_line(capsys, ["train", f"resume={run / 'last.ckpt'}", "-m"])
    assert "resume=" in line and "--multirun" in line
