"""Fuzz suite (bounded): mutated copies of the real sample files, read in an isolated worker.

For every reader, ``CASES_PER_FORMAT`` seeded mutations of the real samples in ``../shared/samples``
(truncation, bit flips, NaN/Inf and odd numbers, huge counts, line ends, encodings, C3D header and
parameter damage, PNG chunk damage) plus special files (a directory, a FIFO, ``/dev/zero``...).
Each file is read in a worker process with a per-file timeout and an address-space cap
(``mocapkit/testing/fuzzing.py``), so a crash, hang or memory blow-up is a failure instead of taking pytest
down. Every outcome must be ``ok`` (finite observed values) or ``clean_error`` (a documented error
whose message names the file). The failure message lists every failing case.

The longer run is ``bench/bench_fuzz.py``.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from mocapkit.testing import fuzzing
from tests.shared_data import SHARED

SAMPLES = SHARED / "samples"
CASES_PER_FORMAT = int(os.environ.get("MOCAPKIT_FUZZ_CASES", "30"))
SEED = int(os.environ.get("MOCAPKIT_FUZZ_SEED", "14"))
TIMEOUT_S = 10.0
MEM_LIMIT = 2 << 30

# seeds: the smaller samples (the suite must stay under 90 s on one core)
MAX_SEED_BYTES = 800_000
SAMPLE_FORMATS = ("ntu", "amc", "bvh", "c3d", "msr")


def _seeds(fmt: str):
    files = [p for p in fuzzing.sample_files(SAMPLES, fmt) if p.stat().st_size <= MAX_SEED_BYTES]
    return files


@pytest.fixture(scope="module")
def fuzz_outcomes(tmp_path_factory):
    """Every format's cases, run in one batch (one worker start for all of them); ``{fmt: [Outcome]}``."""
    root = tmp_path_factory.mktemp("fuzz")
    cases = []
    for fmt in SAMPLE_FORMATS:
        seeds = _seeds(fmt)
        if not seeds:
            continue
        cases += fuzzing.make_cases(fmt, seeds, root, CASES_PER_FORMAT, seed=SEED)
        companion = fuzzing._asf_for(seeds[0]) if fmt == "amc" else None
        cases += fuzzing.make_special_cases(fmt, root, companion)
    pytest.importorskip("PIL")
    frames = fuzzing.make_silhouette_seeds(root / "png-seeds")
    cases += fuzzing.make_cases("png", frames, root, CASES_PER_FORMAT, seed=SEED)
    cases += fuzzing.make_special_cases("png", root)
    outcomes = fuzzing.run_cases(cases, timeout=TIMEOUT_S, mem_limit=MEM_LIMIT)
    by_fmt: dict[str, list] = {}
    for o in outcomes:
        by_fmt.setdefault(o.case.fmt, []).append(o)
    print("\n" + fuzzing.table(outcomes))
    return by_fmt


@pytest.mark.parametrize("fmt", SAMPLE_FORMATS + ("png",))
def test_fuzzed_files_read_or_fail_cleanly(fmt, fuzz_outcomes):
    if fmt != "png" and not _seeds(fmt):
        pytest.skip(f"real data not found at {SAMPLES / fuzzing.FORMATS[fmt]['glob']}")
    outcomes = fuzz_outcomes[fmt]
    assert len(outcomes) == CASES_PER_FORMAT + len(fuzzing.SPECIALS)
    bad = fuzzing.failures(outcomes)
    assert not bad, fuzzing.describe_failures(outcomes)


def test_mutators_are_seeded_and_change_the_file(tmp_path):
    """Same seed, same bytes; every mutated text differs from its seed (or is a documented no-op)."""
    src = tmp_path / "a01_s01_e01_skeleton3D.txt"
    src.write_bytes(b"".join(b"0.1 0.2 2.5 1\r\n" for _ in range(40)))
    a = fuzzing.make_cases("msr", [src], tmp_path / "a", 20, seed=3)
    b = fuzzing.make_cases("msr", [src], tmp_path / "b", 20, seed=3)
    assert [c.mutation for c in a] == [c.mutation for c in b]
    for ca, cb in zip(a, b):
        assert Path(ca.path).read_bytes() == Path(cb.path).read_bytes()
    changed = sum(Path(c.path).read_bytes() != src.read_bytes() for c in a)
    assert changed >= 18


def test_runner_classifies_crash_hang_memory_and_raw(tmp_path, monkeypatch):
    """The runner's own outcome classes, on a fake reader kind that misbehaves on purpose."""
    cases = [
        fuzzing.Case("ok", "msr", "none", str(tmp_path / "x"), "fake:ok", names=[str(tmp_path / "x")]),
        fuzzing.Case("segv", "msr", "none", str(tmp_path / "x"), "fake:segv"),
        fuzzing.Case("hang", "msr", "none", str(tmp_path / "x"), "fake:hang"),
        fuzzing.Case("mem", "msr", "none", str(tmp_path / "x"), "fake:memory"),
        fuzzing.Case("raw", "msr", "none", str(tmp_path / "x"), "fake:raw"),
        fuzzing.Case("inf", "msr", "none", str(tmp_path / "x"), "fake:inf"),
        fuzzing.Case("clean", "msr", "none", str(tmp_path / "x"), "fake:clean", names=[str(tmp_path / "x")]),
        fuzzing.Case("after", "msr", "none", str(tmp_path / "x"), "fake:ok"),
    ]
    got = {o.case.id: o for o in fuzzing.run_cases(cases, timeout=3.0, mem_limit=1 << 30)}
    assert {k: o.outcome for k, o in got.items()} == {
        "ok": "ok",
        "segv": "crash",
        "hang": "hang",
        "mem": "memory",
        "raw": "raw_exception",
        "inf": "non_finite",
        "clean": "clean_error",
        "after": "ok",
    }
    assert got["segv"].exc_type == "SIGSEGV"
    assert got["raw"].exc_type == "IndexError"
    assert got["clean"].names_file
