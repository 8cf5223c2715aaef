"""scripts/select_on_training_subjects.py: every fold trains on the other training subjects and scores the held-out
one; the benchmark's test subjects appear nowhere; runs already scored are reused."""
import importlib.util
import json
import subprocess
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "select_on_training_subjects.py"


def load_script():
    spec = importlib.util.spec_from_file_location("select_on_training_subjects", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_folds_hold_out_each_training_subject_and_reuse_scored_runs(tmp_path, monkeypatch):
    script = load_script()
    calls = []

    def fake_run(cmd, check, stdout, stderr):
        calls.append(cmd)
        args = dict(a.split("=", 1) for a in cmd if "=" in a)
        if cmd[3] == "eval":                       # write what `mocapkit eval` writes
            run_dir = Path(args["ckpt_path"]).parent
            held_out = int(run_dir.name.rsplit("_s", 1)[1])
            (run_dir / "eval").mkdir(parents=True)
            (run_dir / "eval" / "metrics.json").write_text(json.dumps({"top1": held_out / 10, "num_samples": 10}))
        return subprocess.CompletedProcess(cmd, 0)

    monkeypatch.setattr(script.subprocess, "run", fake_run)
    argv = ["--out", str(tmp_path), "--subjects", "1", "3", "5", "--candidate", "a=", "--candidate",
            "b=data.augment.scale=0.1 trainer.max_epochs=2"]
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
    assert "| b | `data.augment.scale=0.1 trainer.max_epochs=2` | 10.0 % | 30.0 % | 50.0 % | 30.0 % | 21 |" in \
        (tmp_path / "selection.md").read_text()
    calls.clear()
    script.main(argv)                              # every fold already scored: nothing runs again
    assert calls == []
    with pytest.raises(SystemExit, match="data.augment.scale=0.2"):   # the same name under other overrides
        script.main([*argv[:-1], "b=data.augment.scale=0.2 trainer.max_epochs=2"])


def test_candidate_needs_a_name():
    script = load_script()
    assert script.parse_candidate("x=a=1 b=2") == ("x", ["a=1", "b=2"])
    assert script.parse_candidate("x=") == ("x", [])
    with pytest.raises(Exception, match="NAME=OVERRIDES"):
        script.parse_candidate("no_equals_sign")
