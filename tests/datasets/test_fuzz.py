"""Fuzz suite (bounded): mutated copies of the real sample files, read in an isolated worker.

For every reader, ``CASES_PER_FORMAT`` seeded mutations of the real samples in ``../shared/samples``
(truncation, bit flips, NaN/Inf and odd numbers, huge counts, line ends, encodings, C3D header and
parameter damage, PNG chunk damage) plus special files (a directory, a FIFO, ``/dev/zero``...).
Each file is read in a worker process with a per-file timeout and an address-space cap
(``mocapkit/testing/fuzzing.py``), so a crash, hang or memory blow-up is a failure instead of taking pytest
down. Every outcome must be ``ok`` (finite observed values) or ``clean_error`` (a documented error
whose message names the file). The failure message lists every failing case.

Then the exhaustive C3D campaign's CI slice (every header and parameter byte set to five values, data-section
mutations and truncations: every 97th mutant of three real files) and the batch commands (``prepare ntu``,
``prepare casia-b``, ``index``, ``kinect-fix apply`` with ``--skip-bad``, and ``refine --train FOLDER --skip-bad``)
on folders of good files plus mutants: every good file kept, every file kept or reported by name.

The longer runs are ``bench/bench_fuzz.py`` (``--c3d-exhaustive``, ``--batch``).
"""

from __future__ import annotations

import os
from collections import Counter
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


# --------------------------------------------------------------------------- C3D: every header and parameter byte

C3D_FILES = ("Eb015pi.c3d", "Walking_Hybrid_1_1.c3d", "pc_real.c3d")  # integer storage; Qualisys; AMASS/Vicon 370
#: The tests' slice of the exhaustive campaign: every 97th mutant (a prime, so the slice walks over every region
#: and every byte value); ``python bench/bench_fuzz.py --c3d-exhaustive`` reads them all.
C3D_EVERY = 97


def test_c3d_mutants_set_every_header_and_parameter_byte_to_each_value():
    path = SAMPLES / "c3d" / "pc_real.c3d"
    if not path.is_file():
        pytest.skip(f"real data not found at {path}")
    data = path.read_bytes()
    sections = fuzzing.c3d_sections(data)
    assert sections["header"] == range(512) and sections["parameters"].start == 512
    mutants = fuzzing.c3d_mutants(data, seed="t", data_mutations=50, truncations=20)
    assert iter(mutants) is mutants  # a generator: the campaign streams them
    by_offset: dict[int, set[int]] = {}
    regions = Counter()
    for m in mutants:
        regions[m.region] += 1
        if m.region in ("header", "parameters"):
            ((offset, new),) = m.edits
            by_offset.setdefault(offset, set()).add(new[0])
        elif m.region == "truncation":
            assert sections["data"].start <= m.truncate < len(data)
        else:
            assert all(sections["data"].start <= o and o + len(b) <= len(data) for o, b in m.edits)
    assert regions["data"] == 50 and regions["truncation"] == 20
    covered = [*sections["header"], *sections["parameters"]]
    assert sorted(by_offset) == covered  # every byte
    for offset in covered:
        b = data[offset]
        assert {0, 255, (b + 1) % 256, (b - 1) % 256} - {b} <= by_offset[offset] and b not in by_offset[offset]
    again = [m.description for m in fuzzing.c3d_mutants(data, seed="t", data_mutations=50, truncations=20)]
    assert again == [m.description for m in fuzzing.c3d_mutants(data, seed="t", data_mutations=50, truncations=20)]


def test_c3d_exhaustive_slice_never_kills_the_reader(tmp_path):
    files = [SAMPLES / "c3d" / name for name in C3D_FILES]
    if not all(f.is_file() for f in files):
        pytest.skip(f"real data not found at {SAMPLES / 'c3d'}")
    counts, bad = fuzzing.run_c3d_campaign(
        files, tmp_path, seed="ci", data_mutations=300, truncations=100, every=C3D_EVERY, keep_failures=tmp_path / "bad"
    )
    print("\n" + fuzzing.campaign_table(counts))
    assert not bad, "\n".join(o.line() for o in bad)
    for f in files:
        plan = sum(fuzzing.count_c3d_mutants(f.read_bytes(), f"ci:{f.name}", 300, 100).values())
        assert counts[f.name]["mutants"] == len(range(0, plan, C3D_EVERY))
        assert counts[f.name]["ok"] + counts[f.name]["located"] == counts[f.name]["mutants"]
    assert sum(c["located"] for c in counts.values()) > 0  # the slice does break files


# --------------------------------------------------------------------------- batch commands: nothing dropped

BATCH_MUTANTS = 5
HDM05_MM = SHARED / "data" / "hdm05_cuts11" / "mm"
BATCH = ("prepare ntu", "prepare casia-b", "index", "kinect-fix apply", "refine --train")


@pytest.fixture(scope="module")
def batch_runs(tmp_path_factory):
    """``{command: BatchCampaign}``: each command run once (``python -m mocapkit``) over good files + mutants."""
    root = tmp_path_factory.mktemp("batch")
    runs = {"prepare casia-b": fuzzing.batch_prepare_casia_b(root, BATCH_MUTANTS, seed=SEED)}
    if _seeds("ntu"):
        runs["prepare ntu"] = fuzzing.batch_prepare_ntu(SAMPLES, root, BATCH_MUTANTS, seed=SEED)
    if _seeds("msr"):
        runs["index"] = fuzzing.batch_index(SAMPLES, root, BATCH_MUTANTS, seed=SEED)
        model = fuzzing.tiny_kinect_model(root / "gp.npz")
        runs["kinect-fix apply"] = fuzzing.batch_kinect_fix(SAMPLES, root, model, BATCH_MUTANTS, seed=SEED)
    if HDM05_MM.is_dir():
        take = HDM05_MM / "HDM_mm_squat1Reps_040_120.amc"
        runs["refine --train"] = fuzzing.batch_refine_train(HDM05_MM, take, root, BATCH_MUTANTS, seed=SEED, files=2)
    for campaign in runs.values():
        fuzzing.run_batch(campaign)
    print("\n" + fuzzing.batch_table(list(runs.values())))
    return runs


@pytest.mark.parametrize("command", BATCH)
def test_batch_command_keeps_every_good_file_and_names_every_bad_one(command, batch_runs):
    if command not in batch_runs:
        pytest.skip(f"real data for {command} not found under {SHARED}")
    campaign = batch_runs[command]
    assert not campaign.problems(), "\n".join(campaign.problems())
    summary = campaign.summary()
    assert summary["good_kept"] == summary["good"] > 0
    assert campaign.unreadable and summary["unreadable_reported"] == len(campaign.unreadable)  # not vacuous


def test_batch_check_finds_what_is_dropped_or_unnamed():
    """The checker of the batch campaigns, on made-up outcomes: each broken promise is a problem."""
    case = fuzzing.Case("m", "msr", "truncate at byte 3", "/d/m.txt", "motion")

    def campaign(kept, reported, returncode=0):
        return fuzzing.BatchCampaign(
            "cmd",
            [],
            good=["/d/good.txt"],
            mutants={"/d/m.txt": case, "/d/n.txt": case},
            unreadable={"/d/m.txt"},
            returncode=returncode,
            kept=set(kept),
            reported=dict(reported),
        )

    fine = campaign({"/d/good.txt", "/d/n.txt"}, {"/d/m.txt": "/d/m.txt: line 3: truncated"})
    assert fine.problems() == []
    assert any("good /d/good.txt not kept" in p for p in campaign({"/d/n.txt"}, fine.reported).problems())
    assert any("dropped silently" in p for p in campaign({"/d/good.txt"}, fine.reported).problems())
    assert any("not reported" in p for p in campaign({"/d/good.txt", "/d/n.txt", "/d/m.txt"}, {}).problems())
    unnamed = campaign({"/d/good.txt", "/d/n.txt"}, {"/d/m.txt": "line 3: truncated"}).problems()
    assert any("does not name it" in p for p in unnamed)
    assert any("signal 11" in p for p in campaign(set(), {}, returncode=-11).problems())
