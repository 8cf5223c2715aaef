"""scripts/selection/select_on_training_subjects.py: every fold trains on the other training subjects and scores the held-out
one; the benchmark's test subjects appear nowhere; runs already scored are reused."""

import json
import subprocess
from pathlib import Path

import pytest

from tests.scripts import load_script

SCRIPT = "scripts/selection/select_on_training_subjects.py"


def test_folds_hold_out_each_training_subject_and_reuse_scored_runs(tmp_path, monkeypatch):
    script = load_script(SCRIPT)
    calls = []

    def fake_run(cmd, check, stdout, stderr):
        calls.append(cmd)
        args = dict(a.split("=", 1) for a in cmd if "=" in a)
        if cmd[3] == "eval":  # write what `mocapkit eval` writes
            run_dir = Path(args["ckpt_path"]).parent
            held_out = int(run_dir.name.rsplit("_s", 1)[1])
            (run_dir / "eval").mkdir(parents=True)
            (run_dir / "eval" / "metrics.json").write_text(json.dumps({"top1": held_out / 10, "num_samples": 10}))
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(script.subprocess, "run", fake_run)
    argv = [
        "--out",
        str(tmp_path),
        "--subjects",
        "1",
        "3",
        "5",
        "--candidate",
        "a=",
        "--candidate",
        "b=data.augment.scale=0.1 trainer.max_epochs=2",
    ]
    script.main(argv)
    trains = [c for c in calls if c[3] == "train"]
    assert len(trains) == 6 and len([c for c in calls if c[3] == "eval"]) == 6
    for cmd in trains:
        args = dict(a.split("=", 1) for a in cmd if "=" in a)
        held_out = int(args["data.test_subjects"].strip("[]"))
        train = [int(s) for s in args["data.train_subjects"].strip("[]").split(",")]
        assert held_out not in train and sorted(train + [held_out]) == [1, 3, 5]
        assert ("data.augment.scale" in args) == args["run_name"].startswith("b_")
    table = json.loads((tmp_path / "selection.json").read_text())["candidates"]
    assert table["a"]["per_subject"]["5"]["top1"] == pytest.approx(0.5)
    assert table["b"]["mean_top1"] == pytest.approx(0.3) and table["b"]["wrong"] == 9 + 7 + 5
    assert (
        "| b | `data.augment.scale=0.1 trainer.max_epochs=2` | 10.0 % | 30.0 % | 50.0 % | 30.0 % | 21 |"
        in (tmp_path / "selection.md").read_text()
    )
    calls.clear()
    script.main(argv)  # every fold already scored: nothing runs again
    assert calls == []
    with pytest.raises(SystemExit, match="data.augment.scale=0.2"):  # the same name under other overrides
        script.main([*argv[:-1], "b=data.augment.scale=0.2 trainer.max_epochs=2"])


def test_outer_folds_never_see_their_test_performer_and_pick_the_fewest_wrong(tmp_path, monkeypatch):
    """--outer: one selection per held-out performer, on the other performers only; several seeds are summed; a
    candidate naming another experiment trains it; auto scores best.ckpt only where the run wrote one."""
    script = load_script(SCRIPT)
    calls = []
    wrong = {"recipe": {"bd": 1, "bk": 3, "dg": 0, "mm": 1}, "ens": {"bd": 0, "bk": 1, "dg": 2, "mm": 0}}

    def fake_run(cmd, check, stdout, stderr):
        calls.append(cmd)
        args = dict(a.split("=", 1) for a in cmd if "=" in a)
        if cmd[3] == "train":
            run_dir = Path(args["output_root"]) / args["experiment"] / args["run_name"]
            run_dir.mkdir(parents=True)
            if "data.val_fraction" not in args:  # the recipe validates: it writes best.ckpt
                (run_dir / "best.ckpt").write_text("")
        else:
            run_dir = Path(args["ckpt_path"]).parent
            name, held_out = run_dir.name.split("_seed")[0], run_dir.name.rsplit("_s", 1)[1]
            (run_dir / "eval").mkdir()
            top1 = 1 - wrong[name][held_out] / 20
            (run_dir / "eval" / "metrics.json").write_text(json.dumps({"top1": top1, "num_samples": 20}))
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(script.subprocess, "run", fake_run)
    script.main(
        [
            "--out",
            str(tmp_path),
            "--outer",
            "--subjects",
            "bd",
            "bk",
            "dg",
            "mm",
            "--seeds",
            "0",
            "1",
            "--split-keys",
            "data.train_actors",
            "data.test_actors",
            "--checkpoint",
            "auto",
            "--experiment",
            "hdm05_gcn",
            "--candidate",
            "recipe=",
            "--candidate",
            "ens=experiment=other data.val_fraction=0",
            "--common",
            "trainer.accelerator=cpu",
        ]
    )
    trains = [dict(a.split("=", 1) for a in c if "=" in a) for c in calls if c[3] == "train"]
    assert len(trains) == 4 * 3 * 2 * 2  # outer folds × inner folds × candidates × seeds
    for args in trains:
        outer = Path(args["output_root"]).name.removeprefix("outer_")
        train, held_out = args["data.train_actors"].strip("[]").split(","), args["data.test_actors"].strip("[]")
        assert outer not in train and outer != held_out and held_out not in train and len(train) == 2
        assert args["trainer.accelerator"] == "cpu"
        assert args["experiment"] == ("other" if args["run_name"].startswith("ens") else "hdm05_gcn")
    scored = [Path(dict(a.split("=", 1) for a in c if "=" in a)["ckpt_path"]).name for c in calls if c[3] == "eval"]
    assert scored.count("best.ckpt") == scored.count("last.ckpt") == 24
    for outer, chosen, wrong_counts in [("bd", "ens", (8, 6)), ("dg", "ens", (10, 2)), ("mm", "ens", (8, 6))]:
        selection = json.loads((tmp_path / f"outer_{outer}" / "selection.json").read_text())
        assert selection["subjects"] == [s for s in ["bd", "bk", "dg", "mm"] if s != outer]
        assert (selection["candidates"]["recipe"]["wrong"], selection["candidates"]["ens"]["wrong"]) == wrong_counts
        assert selection["chosen"] == chosen
    tie = json.loads((tmp_path / "outer_bk" / "selection.json").read_text())  # 4 against 4: the first listed
    assert tie["candidates"]["recipe"]["wrong"] == tie["candidates"]["ens"]["wrong"] and tie["chosen"] == "recipe"


def test_candidate_needs_a_name():
    script = load_script(SCRIPT)
    assert script.parse_candidate("x=a=1 b=2") == ("x", ["a=1", "b=2"])
    assert script.parse_candidate("x=") == ("x", [])
    with pytest.raises(Exception, match="NAME=OVERRIDES"):
        script.parse_candidate("no_equals_sign")
