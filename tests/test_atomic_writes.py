"""Atomic, durable writes: a kill at any moment leaves the previous good file.

The helper (:mod:`mocapkit.io_atomic`) writes a temporary sibling in the destination folder, fsyncs it and
renames it; checkpoints go through it (:class:`mocapkit.train.checkpoint_io.AtomicCheckpointIO`). The kill
tests run with ``TMPDIR`` on another filesystem (``/dev/shm`` where it exists), where Lightning's own save
degrades into a copy in place.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from mocapkit.io_atomic import (
    atomic_open,
    atomic_path,
    atomic_write_bytes,
    atomic_write_text,
    temp_path_for,
)
from tests.shared_data import TINY_NTU_SYNTH

REPO = Path(__file__).resolve().parents[1]


def other_filesystem_tmpdir(tmp_path: Path) -> dict:
    """``TMPDIR`` on a filesystem other than ``tmp_path``'s (``/dev/shm``), when there is one."""
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    shm = Path("/dev/shm")
    if shm.is_dir() and os.access(shm, os.W_OK) and os.stat(shm).st_dev != os.stat(tmp_path).st_dev:
        env["TMPDIR"] = str(shm)
    return env


def wait_for(path: Path, proc: subprocess.Popen, timeout: float) -> None:
    deadline = time.time() + timeout
    while not path.exists():
        if proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"the writer ended (rc {proc.returncode}) before the kill point:\n{out}\n{err}")
        if time.time() > deadline:
            proc.kill()
            raise AssertionError("the writer never reached the kill point")
        time.sleep(0.1)


# --------------------------------------------------------------------------- the helper


def test_write_replaces_and_leaves_no_temporary(tmp_path):
    dest = tmp_path / "report.json"
    atomic_write_text(dest, "old")
    atomic_write_text(dest, "new")
    assert dest.read_text() == "new"
    atomic_write_bytes(dest, b"\x00\x01")
    assert dest.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["report.json"]


def test_the_temporary_file_is_in_the_destination_folder_and_fsynced(tmp_path, monkeypatch):
    dest = tmp_path / "sub" / "last.ckpt"
    dest.parent.mkdir()
    replaced, synced = [], []
    real_replace, real_fsync = os.replace, os.fsync
    monkeypatch.setattr(os, "replace", lambda a, b: (replaced.append((Path(a), Path(b))), real_replace(a, b)))
    monkeypatch.setattr(os, "fsync", lambda fd: (synced.append(fd), real_fsync(fd)))
    atomic_write_bytes(dest, b"data")
    assert replaced == [(temp_path_for(dest), dest)]
    assert temp_path_for(dest).parent == dest.parent and temp_path_for(dest).name == f"last.ckpt.tmp-{os.getpid()}"
    assert len(synced) >= 2  # the file and its folder


def test_an_error_inside_the_block_keeps_the_previous_file(tmp_path):
    dest = tmp_path / "index.json"
    dest.write_text("previous")
    with pytest.raises(RuntimeError):
        with atomic_open(dest, "w") as f:
            f.write("half")
            raise RuntimeError("boom")
    with pytest.raises(RuntimeError):
        with atomic_path(dest) as tmp:
            tmp.write_text("half")
            raise RuntimeError("boom")
    assert dest.read_text() == "previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.json"]


def test_a_folder_or_a_missing_folder_is_refused(tmp_path):
    with pytest.raises(IsADirectoryError, match=str(tmp_path)):
        atomic_write_text(tmp_path, "x")
    with pytest.raises(FileNotFoundError, match="nowhere"):
        atomic_write_text(tmp_path / "nowhere" / "f.txt", "x")
    assert not (tmp_path / "nowhere").exists()


def test_save_run_config_is_atomic(tmp_path, monkeypatch):
    from omegaconf import OmegaConf

    from mocapkit.train.config import save_run_config

    save_run_config(OmegaConf.create({"a": 1}), tmp_path)
    monkeypatch.setattr(os, "replace", lambda a, b: (_ for _ in ()).throw(OSError("disk full")))
    with pytest.raises(OSError):
        save_run_config(OmegaConf.create({"a": 2}), tmp_path)
    assert OmegaConf.load(tmp_path / "config.yaml").a == 1
    assert not list(tmp_path.glob("*.tmp-*"))


KILLED_WRITER = """
import os, sys, time
from pathlib import Path
from mocapkit.io_atomic import atomic_open
dest, marker = Path(sys.argv[1]), Path(sys.argv[2])
with atomic_open(dest, "wb") as f:
    f.write(b"N" * 1_000_000)
    f.flush()
    marker.touch()
    time.sleep(600)
"""


def test_a_killed_write_leaves_the_previous_file(tmp_path):
    dest, marker = tmp_path / "cache.bin", tmp_path / "writing"
    dest.write_bytes(b"previous good file")
    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED_WRITER, str(dest), str(marker)],
        cwd=REPO,
        env=other_filesystem_tmpdir(tmp_path),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    wait_for(marker, proc, 60)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    assert dest.read_bytes() == b"previous good file"


# --------------------------------------------------------------------------- checkpoints: a training killed mid-save

KILLED_TRAINING = """
import io, os, sys, time
from pathlib import Path
import torch

marker = Path(sys.argv[1])
real_save = torch.save
saves = {"last": 0}

def save_then_hang(obj, f, *args, **kwargs):
    name = str(getattr(f, "name", ""))
    if "last.ckpt" in name:
        saves["last"] += 1
        if saves["last"] == 2:  # the second last.ckpt: write half of it, then hang until killed
            buffer = io.BytesIO()
            real_save(obj, buffer, *args, **kwargs)
            data = buffer.getvalue()
            f.write(data[: len(data) // 2])
            f.flush()
            os.fsync(f.fileno())
            marker.write_text(name)
            time.sleep(600)
    return real_save(obj, f, *args, **kwargs)

torch.save = save_then_hang
from mocapkit.cli import main
sys.exit(main(sys.argv[2:]))
"""


@pytest.mark.slow
def test_a_training_killed_while_writing_last_ckpt_keeps_the_previous_one(tmp_path):
    import torch

    from mocapkit.cli import main
    from mocapkit.train.checkpoints import load_checkpoint

    assert main(["synth", "ntu", "--out", str(tmp_path / "synth"), *TINY_NTU_SYNTH]) == 0
    assert main(["prepare", "ntu", "--src", str(tmp_path / "synth"), "--out", str(tmp_path / "cache"), "--quiet"]) == 0
    run = tmp_path / "runs" / "ntu_energy_vgg" / "k"
    marker = tmp_path / "writing"
    argv = [
        "train",
        "experiment=ntu_energy_vgg",
        f"data.root={tmp_path / 'cache'}",
        f"output_root={tmp_path / 'runs'}",
        "run_name=k",
        "trainer.max_epochs=3",
        "trainer.enable_progress_bar=false",
        "data.batch_size=8",
        "model.energy.size=32",
        "data.val_by_subject=false",
    ]
    env = other_filesystem_tmpdir(tmp_path)
    proc = subprocess.Popen(
        [sys.executable, "-c", KILLED_TRAINING, str(marker), *argv],
        cwd=REPO,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    wait_for(marker, proc, 300)
    assert Path(marker.read_text()).parent == run  # the partial file is in the run folder ...
    assert Path(marker.read_text()).name.startswith("last.ckpt.tmp-")  # ... beside last.ckpt, not in TMPDIR
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    state = load_checkpoint(run / "last.ckpt")  # weights_only=True, vetted
    assert state["epoch"] == 0  # the previous, complete checkpoint
    assert torch.load(run / "best.ckpt", weights_only=True)["state_dict"]
    # and the run can be continued from it
    assert main(["train", f"resume={run / 'last.ckpt'}", "trainer.max_epochs=2"]) == 0
    assert load_checkpoint(run / "last.ckpt")["epoch"] == 1
