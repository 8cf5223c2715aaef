"""Fuzzing harness for the motion-file readers: seeded mutators, special files, and an isolated runner.

Nothing here imports mocapkit at module level: the mutators work on bytes, and only the
worker process (:func:`worker_main`) imports the readers. ``tests/datasets/test_fuzz.py`` (bounded)
and ``bench/bench_fuzz.py`` (long run) build cases with :func:`make_cases` /
:func:`make_special_cases` and run them with :func:`run_cases`.

Two campaigns on top (same worker, same outcome classes):

- **C3D, exhaustive** (:func:`c3d_mutants`, :func:`run_c3d_campaign`): every byte of the header and of the
  parameter section of a real file set to 0x00, 0xFF, byte+1, byte−1 and a random byte, plus random multi-byte
  mutations and truncations of the data section, streamed through one file per source;
- **batch commands** (:class:`BatchCampaign`, :func:`run_batch`): ``prepare ntu``, ``prepare casia-b``, ``index``,
  ``kinect-fix apply`` with ``--skip-bad`` and ``refine --train FOLDER --skip-bad`` run as ``python -m mocapkit`` on
  a folder of good files plus mutants; every good file must be kept, every file kept or reported by name, every
  file the reader alone rejects reported, and the process must end with exit code 0.

Outcome classes (:data:`OUTCOMES`) of reading one file:

``ok``             the reader returned, every observed value is finite (positions/rotations
                   where not missing, raw values kept in metadata, fps), and a mutation that
                   wrote a non-finite token (``nan``, ``inf``, ``1e309``) did not silently turn
                   into extra "missing" samples;
``clean_error``    the reader raised a documented error: a ``MotionFormatError`` subclass, an
                   ``OSError`` subclass, or a ``ValueError`` subclass defined in mocapkit
                   (``UnsupportedFormatError``...). ``names_file`` says whether its message names
                   the file (the tests require it);
``crash``          the worker died (a signal such as SIGSEGV/SIGABRT, or ``os._exit``);
``hang``           no answer within the per-file timeout (the worker is killed);
``memory``         ``MemoryError`` (the worker runs under ``RLIMIT_AS``), or a crash whose
                   stderr says ``bad_alloc``;
``raw_exception``  any other exception (IndexError, KeyError, a bare ValueError, UnicodeDecodeError...);
``non_finite``     the read "succeeded" but returned non-finite observed values.

The worker is batched: one process reads many files (requests and answers are JSON lines)
and is restarted after a crash, hang or memory blow-up. Cases flagged ``blocking`` (FIFOs:
``open()`` waits for a writer forever) each get their own worker, run concurrently, since a
blocked process costs no CPU.
"""

from __future__ import annotations

import json
import math
import os
import random
import re
import select
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import threading
import time
import zlib
from collections import Counter
from collections.abc import Iterator
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

OUTCOMES = ("ok", "clean_error", "crash", "hang", "memory", "raw_exception", "non_finite")
#: The outcomes a robust reader may have.
GOOD = ("ok", "clean_error")

#: Formats: sample glob under ``shared/samples``, the file name a special file gets, how it is read.
FORMATS = {
    "ntu": {
        "glob": "ntu_skeleton/*.skeleton",
        "special": "S001C001P001R001A001.skeleton",
        "kind": "ntu",
        "binary": False,
    },
    "amc": {"glob": "asf_amc/*/*.amc", "special": "x.amc", "kind": "motion", "binary": False},
    "bvh": {"glob": "bvh/*.bvh", "special": "x.bvh", "kind": "motion", "binary": False},
    "c3d": {"glob": "c3d/*.c3d", "special": "x.c3d", "kind": "motion", "binary": True},
    "msr": {
        "glob": "msr3d/*_skeleton*.txt",
        "special": "a01_s01_e01_skeleton3D.txt",
        "kind": "motion",
        "binary": False,
    },
    "png": {"glob": None, "special": "001-nm-01-090-001.png", "kind": "silhouette", "binary": True},
}

#: The folder that holds the ``mocapkit`` package the worker imports (a checkout's root or site-packages).
PACKAGE_ROOT = Path(__file__).resolve().parents[2]


@dataclass
class Case:
    """One file to read.

    Attributes:
        id: unique label, e.g. ``"bvh-017"``.
        fmt: format key of :data:`FORMATS`.
        mutation: what was done to the seed (human-readable).
        path: the file handed to the reader.
        kind: ``"motion"`` (``read_motion``), ``"ntu"`` (``read_skeleton`` then ``read_motion``),
            ``"silhouette"`` (``read_silhouette``) or ``"sequence"`` (``read_sequence`` of ``path``'s folder).
        seed: the unmutated original (or None); a successful read is compared with it.
        nonfinite_token: the mutation wrote ``nan``/``inf``/``1e309`` into a numeric field.
        blocking: the read may block in ``open()`` (FIFO): run in its own worker.
        names: the file names an error message may name (the file, and e.g. its ASF).
    """

    id: str
    fmt: str
    mutation: str
    path: str
    kind: str
    seed: str | None = None
    nonfinite_token: bool = False
    blocking: bool = False
    names: list[str] = field(default_factory=list)


@dataclass
class Outcome:
    case: Case
    outcome: str
    exc_type: str = ""
    message: str = ""
    names_file: bool = True
    seconds: float = 0.0

    @property
    def good(self) -> bool:
        return self.outcome in GOOD and (self.outcome != "clean_error" or self.names_file)

    def line(self) -> str:
        what = f"{self.exc_type}: {self.message}" if self.exc_type else self.message
        flag = "" if self.names_file else " [message does not name the file]"
        return f"{self.case.fmt} | {self.case.mutation} | {self.outcome}{flag} | {what}"


# =========================================================================== mutators: text

_NUM = re.compile(rb"(?<![\w.+\-])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?(?![\w.])")
_COUNT_PATTERNS = (
    re.compile(rb"(?m)^[ \t]*(\d+)[ \t]*\r?$"),  # a line holding one integer
    re.compile(rb"Frames:[ \t]*(\d+)"),  # BVH
    re.compile(rb"CHANNELS[ \t]+(\d+)"),
    re.compile(rb"(?m)^[ \t]*(?:length|id|dof)[ \t]+(\S+)"),
)  # ASF
NONFINITE_TOKENS = (b"nan", b"NaN", b"inf", b"-inf", b"Infinity", b"1e309", b"-1e309", b"nan(0x1)")
ODD_NUMBERS = (
    b"-0",
    b"+0.0",
    b"1e39",
    b"-1e39",
    b"1e-400",
    b"99999999999999999999",
    b"-2147483649",
    b"18446744073709551616",
    b"0x10",
    b"1_000",
    b"1.2.3",
    b"--1",
    b"1e",
    b".",
    b"\xd9\xa1\xd9\xa2",
    b"\xef\xbc\x91",
)  # Arabic-Indic "12", full-width "1": float() accepts both
HUGE_COUNTS = (
    b"2147483647",
    b"2147483648",
    b"4294967296",
    b"999999999999",
    b"100000000",
    b"-1",
    b"0",
    b"9" * 40,
    b"1e9",
)


def _pick_token(data: bytes, rng: random.Random, pattern=_NUM) -> re.Match | None:
    """A numeric token near a random offset (the first one at or after it, wrapping around)."""
    if not data:
        return None
    start = rng.randrange(len(data))
    return pattern.search(data, start) or pattern.search(data, 0)


def _replace(data: bytes, m: re.Match, new: bytes, group: int = 0) -> bytes:
    return data[: m.start(group)] + new + data[m.end(group) :]


def _lines(data: bytes) -> list[bytes]:
    return data.splitlines(keepends=True)


def m_truncate(data, rng):
    # bias towards the start (headers) half of the time
    n = len(data)
    off = rng.randrange(n) if rng.random() < 0.5 else rng.randrange(min(n, 2048))
    return data[:off], f"truncate at byte {off}/{n}", False


def m_flip_bits(data, rng):
    b = bytearray(data)
    k = rng.randint(1, 8)
    where = sorted(rng.randrange(len(b)) for _ in range(k))
    for i in where:
        b[i] ^= 1 << rng.randrange(8)
    return bytes(b), f"flip {k} bits at {where[:4]}{'...' if k > 4 else ''}", False


def m_set_bytes(data, rng):
    b = bytearray(data)
    k = rng.randint(1, 6)
    vals = (0x00, 0xFF, 0x0A, 0x0D, 0x20, 0x2D, 0x2E, 0x65, 0x80, rng.randrange(256))
    where = []
    for _ in range(k):
        i = rng.randrange(len(b))
        b[i] = rng.choice(vals)
        where.append((i, b[i]))
    return bytes(b), f"set bytes {where[:4]}", False


def m_nonfinite(data, rng):
    k = rng.choice((1, 1, 1, 3))
    toks = []
    for _ in range(k):
        m = _pick_token(data, rng)
        if m is None:
            break
        tok = rng.choice(NONFINITE_TOKENS)
        toks.append((m.group().decode("latin-1"), tok.decode()))
        data = _replace(data, m, tok)
    return data, f"non-finite token {toks} (line {_line_of(data, m.start()) if m else '?'})", True


def m_odd_number(data, rng):
    m = _pick_token(data, rng)
    if m is None:
        return data + b"1e309\n", "append 1e309", True
    tok = rng.choice(ODD_NUMBERS)
    return (
        _replace(data, m, tok),
        (f"number {m.group().decode('latin-1')!r} -> {tok!r} (line {_line_of(data, m.start())})"),
        False,
    )


def m_huge_count(data, rng):
    cands = []
    for pat in _COUNT_PATTERNS:
        for i, m in enumerate(pat.finditer(data)):
            cands.append(m)
            if i > 200:  # the first few hundred are plenty (frame numbers go on and on)
                break
    if not cands:
        m = _pick_token(data, rng)
        if m is None:
            return data, "no count found", False
        cands = [m]
    # headers first: half the time the earliest count of the file
    m = min(cands, key=lambda c: c.start()) if rng.random() < 0.5 else rng.choice(cands)
    tok = rng.choice(HUGE_COUNTS)
    return (
        _replace(data, m, tok, 1 if m.re.groups else 0),
        (
            f"count {m.group(1 if m.re.groups else 0).decode('latin-1')!r} -> {tok.decode()} "
            f"(line {_line_of(data, m.start())})"
        ),
        False,
    )


def _line_of(data: bytes, offset: int) -> int:
    return data.count(b"\n", 0, offset) + 1


def m_dup_lines(data, rng):
    lines = _lines(data)
    i = rng.randrange(len(lines))
    k = rng.randint(1, 30)
    j = rng.randrange(len(lines) + 1)
    chunk = lines[i : i + k]
    return b"".join(lines[:j] + chunk + lines[j:]), f"duplicate lines {i + 1}..{i + len(chunk)} at line {j + 1}", False


def m_delete_lines(data, rng):
    lines = _lines(data)
    i = rng.randrange(len(lines)) if rng.random() < 0.7 else rng.randrange(min(len(lines), 10))
    k = rng.randint(1, 30)
    return b"".join(lines[:i] + lines[i + k :]), f"delete lines {i + 1}..{min(len(lines), i + k)}", False


def m_line_ends(data, rng):
    lf = data.replace(b"\r\n", b"\n")
    how = rng.choice(("cr", "mixed", "crcrlf", "no-final", "blank-lines"))
    if how == "cr":
        return lf.replace(b"\n", b"\r"), "CR-only line ends", False
    if how == "crcrlf":
        return lf.replace(b"\n", b"\r\r\n"), "CR CR LF line ends", False
    if how == "no-final":
        return data.rstrip(b"\r\n"), "no final line end", False
    if how == "blank-lines":
        lines = _lines(lf)
        out = [ln + (b"\n" * rng.randint(1, 3) if rng.random() < 0.1 else b"") for ln in lines]
        return b"".join(out), "blank lines inserted", False
    out = []
    for ln in _lines(lf):
        out.append(ln[:-1] + rng.choice((b"\n", b"\r\n", b"\r")) if ln.endswith(b"\n") else ln)
    return b"".join(out), "mixed LF/CRLF/CR line ends", False


def m_encoding(data, rng):
    how = rng.choice(("utf16", "utf16le", "utf8bom", "latin1", "bad-utf8", "nul", "utf8-in-number"))
    text = data.decode("latin-1")
    if how == "utf16":
        return text.encode("utf-16"), "re-encoded UTF-16 (BOM)", False
    if how == "utf16le":
        return text.encode("utf-16-le"), "re-encoded UTF-16-LE (no BOM)", False
    if how == "utf8bom":
        return b"\xef\xbb\xbf" + data, "UTF-8 BOM prepended", False
    pos = rng.randrange(len(data) + 1)
    if how == "latin1":
        ins = "Müller é".encode("latin-1")
    elif how == "bad-utf8":
        ins = b"\xff\xfe\x80\xc3"
    elif how == "nul":
        ins = b"\x00" * rng.randint(1, 8)
    else:
        m = _pick_token(data, rng)
        if m is not None:
            pos = m.start() + 1
        ins = "é".encode()
    return data[:pos] + ins + data[pos:], f"{how} bytes {ins!r} at byte {pos} (line {_line_of(data, pos)})", False


def m_fields(data, rng):
    lines = _lines(data)
    i = rng.randrange(len(lines))
    ln = lines[i]
    body, end = ln.rstrip(b"\r\n"), ln[len(ln.rstrip(b"\r\n")) :]
    toks = body.split()
    how = rng.choice(("extra", "drop", "drop-all", "garbage"))
    if how == "extra":
        toks.append(rng.choice((b"0", b"1.5", b"abc", b"nan")))
    elif how == "drop" and toks:
        toks.pop()
    elif how == "drop-all":
        toks = []
    else:
        toks.insert(rng.randrange(len(toks) + 1), rng.choice((b"abc", b"#", b":", b"{", b"}", b"\x00")))
    lines[i] = b" ".join(toks) + end
    return b"".join(lines), f"{how} field on line {i + 1}", how == "extra" and toks[-1] == b"nan"


def m_wipe(data, rng):
    how = rng.choice(("empty", "whitespace", "garbage-tail", "random-head"))
    if how == "empty":
        return b"", "emptied", False
    if how == "whitespace":
        return b" \n\r\n\t\n", "whitespace only", False
    if how == "garbage-tail":
        return data + bytes(rng.randrange(256) for _ in range(rng.randint(1, 300))), "random bytes appended", False
    k = rng.randint(1, 64)
    return bytes(rng.randrange(256) for _ in range(k)) + data[k:], f"first {k} bytes random", False


TEXT_MUTATORS = {
    "truncate": (m_truncate, 3),
    "flip_bits": (m_flip_bits, 2),
    "set_bytes": (m_set_bytes, 2),
    "nonfinite": (m_nonfinite, 4),
    "odd_number": (m_odd_number, 3),
    "huge_count": (m_huge_count, 4),
    "dup_lines": (m_dup_lines, 2),
    "delete_lines": (m_delete_lines, 2),
    "line_ends": (m_line_ends, 2),
    "encoding": (m_encoding, 3),
    "fields": (m_fields, 2),
    "wipe": (m_wipe, 1),
}


# =========================================================================== mutators: C3D


@dataclass
class C3DParam:
    group: str
    name: str
    dtype: int  # -1 char, 1 byte, 2 int16, 4 float
    ndim_offset: int  # byte holding the number of dimensions
    data_offset: int
    data_len: int


def c3d_layout(data: bytes) -> tuple[str, list[C3DParam], int, bool]:
    """(struct byte-order char, parameters, data section offset, float storage) of a C3D file, best effort."""
    if len(data) < 512:
        return "<", [], 512, True
    start = max(data[0] - 1, 1) * 512
    if start + 4 > len(data):
        return "<", [], 512, True
    order = ">" if data[start + 3] == 86 else "<"
    scale = struct.unpack_from(order + "f", data, 12)[0]
    data_start = max(struct.unpack_from(order + "H", data, 16)[0] - 1, 0) * 512
    stop = min(len(data), start + max(data[start + 2], 1) * 512)
    groups, raw = {}, []
    pos = start + 4
    while pos + 2 <= stop:
        nlen, gid = struct.unpack_from("bb", data, pos)
        if nlen == 0:
            break
        nlen = abs(nlen)
        name = data[pos + 2 : pos + 2 + nlen].decode("latin-1")
        off = pos + 2 + nlen
        if off + 2 > stop:
            break
        nxt = struct.unpack_from(order + "h", data, off)[0]
        if gid < 0:
            groups[-gid] = name
        elif off + 4 <= stop:
            q = off + 2
            dtype, ndim = struct.unpack_from("bB", data, q)
            dims = list(data[q + 2 : q + 2 + ndim])
            raw.append((gid, name, dtype, q + 1, q + 2 + ndim, abs(dtype) * math.prod(dims)))
        if nxt <= 0:
            break
        pos = off + nxt
    params = [C3DParam(groups.get(g, str(g)), n, t, nd, do, dl) for g, n, t, nd, do, dl in raw]
    return order, params, data_start, not (scale >= 0)


_C3D_KEY_PARAMS = {
    ("POINT", "USED"),
    ("POINT", "FRAMES"),
    ("POINT", "SCALE"),
    ("POINT", "RATE"),
    ("POINT", "LABELS"),
    ("POINT", "UNITS"),
    ("POINT", "DATA_START"),
    ("ANALOG", "USED"),
    ("ANALOG", "RATE"),
    ("ANALOG", "LABELS"),
    ("ANALOG", "SCALE"),
    ("ANALOG", "GEN_SCALE"),
    ("TRIAL", "ACTUAL_END_FIELD"),
    ("TRIAL", "ACTUAL_START_FIELD"),
    ("POINT", "LONG_FRAMES"),
}
_BAD_FLOATS = (float("nan"), float("inf"), float("-inf"), 1e38, -1e38, 0.0, -0.0, 1e-45)
_BAD_INT16 = (0x7FFF, 0xFFFF, 0x8000, 0)


def m_c3d_header(data, rng):
    order, *_ = c3d_layout(data)
    b = bytearray(data)
    word = rng.choice((2, 3, 4, 5, 6, 9, 10, 1, "scale", "rate", "key", "pblock"))
    if word in ("scale", "rate"):
        off = 12 if word == "scale" else 20
        v = rng.choice(_BAD_FLOATS)
        struct.pack_into(order + "f", b, off, v)
        return bytes(b), f"header {word} float -> {v}", not math.isfinite(v)
    if word == "key":
        b[1] = rng.choice((0, 0x51, 0xFF))
        return bytes(b), f"header key byte -> {b[1]:#x}", False
    if word == "pblock":
        b[0] = rng.choice((0, 2, 200, 255))
        return bytes(b), f"header parameter block -> {b[0]}", False
    v = rng.choice(_BAD_INT16)
    struct.pack_into(order + "H", b, 2 * (word - 1), v)
    names = {
        1: "parameter block/key",
        2: "points",
        3: "analog per frame",
        4: "first frame",
        5: "last frame",
        6: "max gap",
        9: "data start block",
        10: "analog samples per frame",
    }
    return bytes(b), f"header word {word} ({names[word]}) -> {v:#x}", False


def m_c3d_param(data, rng):
    order, params, *_ = c3d_layout(data)
    if not params:
        return m_flip_bits(data, rng)
    key = [p for p in params if (p.group, p.name) in _C3D_KEY_PARAMS]
    p = rng.choice(key) if key and rng.random() < 0.7 else rng.choice(params)
    b = bytearray(data)
    label = f"{p.group}:{p.name}"
    how = rng.random()
    if how < 0.2 and p.ndim_offset < len(b):
        if b[p.ndim_offset] and rng.random() < 0.5:  # a dimension, not the count of them
            b[p.ndim_offset + 1] = 255
            return bytes(b), f"param {label} first dimension -> 255", False
        b[p.ndim_offset] = rng.choice((7, 255))
        return bytes(b), f"param {label} number of dimensions -> {b[p.ndim_offset]}", False
    if p.data_len <= 0 or p.data_offset + min(p.data_len, 4) > len(b):
        return m_flip_bits(data, rng)
    if p.dtype == 4:
        v = rng.choice(_BAD_FLOATS)
        struct.pack_into(order + "f", b, p.data_offset + 4 * rng.randrange(p.data_len // 4), v)
        return bytes(b), f"param {label} float -> {v}", not math.isfinite(v)
    if p.dtype == 2:
        v = rng.choice(_BAD_INT16)
        struct.pack_into(order + "H", b, p.data_offset + 2 * rng.randrange(p.data_len // 2), v)
        return bytes(b), f"param {label} int16 -> {v:#x}", False
    if p.dtype == -1:
        junk = rng.choice((b"\xfc\xe9", b"\x00\x00", "é".encode(), b"\xff\xfe", b"\x80"))
        i = p.data_offset + rng.randrange(max(p.data_len - len(junk), 1))
        b[i : i + len(junk)] = junk
        return bytes(b), f"param {label} chars -> {junk!r}", False
    b[p.data_offset] = rng.choice((0, 255))
    return bytes(b), f"param {label} byte -> {b[p.data_offset]}", False


def m_c3d_section(data, rng):
    """Parameter-section header (block count, processor type = the number encoding) or data-section values."""
    order, _, data_start, is_float = c3d_layout(data)
    b = bytearray(data)
    start = max(data[0] - 1, 1) * 512 if data else 512
    how = rng.choice(("nblocks", "processor", "data", "data", "data"))
    if how in ("nblocks", "processor") and start + 4 <= len(b):
        off = start + (2 if how == "nblocks" else 3)
        b[off] = rng.choice((0, 255, 1) if how == "nblocks" else (84, 85, 86, 0, 99))
        return bytes(b), f"parameter section {how} byte -> {b[off]}", False
    if data_start + 8 > len(b):
        return m_truncate(data, rng)
    k = rng.randint(1, 4)
    vals = []
    for _ in range(k):
        off = data_start + 4 * rng.randrange((len(b) - data_start) // 4)
        if is_float:
            v = rng.choice(_BAD_FLOATS[:5])
            struct.pack_into(order + "f", b, off, v)
        else:
            v = rng.choice(_BAD_INT16)
            struct.pack_into(order + "H", b, off, v)
        vals.append((off, v))
    # not flagged: in C3D a sample with a non-finite coordinate is a gap whatever its residual (docs/robustness.md#c3d-gaps)
    return bytes(b), f"data section {'float' if is_float else 'int16'} values {vals[:3]}", False


def m_c3d_truncate(data, rng):
    _, _, data_start, _ = c3d_layout(data)
    choices = [
        512,
        516,
        max(data_start - 1, 0),
        data_start,
        data_start + 7,
        len(data) - 1,
        len(data) - 512,
        rng.randrange(len(data)),
    ]
    off = max(0, min(len(data) - 1, rng.choice(choices)))
    return data[:off], f"truncate at byte {off}/{len(data)} (data section at {data_start})", False


def m_c3d_encoding(data, rng):
    how = rng.choice(("utf16", "bom", "text"))
    if how == "utf16":
        return data.decode("latin-1").encode("utf-16"), "bytes re-encoded as UTF-16", False
    if how == "bom":
        return b"\xef\xbb\xbf" + data, "UTF-8 BOM prepended (every offset shifted)", False
    return data.replace(b"\n", b"\r\n"), "LF bytes -> CRLF (text-mode copy)", False


BINARY_MUTATORS = {
    "truncate": (m_c3d_truncate, 3),
    "flip_bits": (m_flip_bits, 3),
    "set_bytes": (m_set_bytes, 2),
    "header": (m_c3d_header, 4),
    "param": (m_c3d_param, 5),
    "section": (m_c3d_section, 4),
    "encoding": (m_c3d_encoding, 1),
    "wipe": (m_wipe, 1),
}


# =========================================================================== mutators: PNG


def png_chunks(data: bytes) -> list[tuple[int, bytes, int]]:
    """``(offset, type, length)`` of each chunk after the signature."""
    out, pos = [], 8
    while pos + 8 <= len(data):
        length, ctype = struct.unpack_from(">I4s", data, pos)
        out.append((pos, ctype, length))
        pos += 12 + length
    return out


def _png_set_chunk(data: bytes, offset: int, payload: bytes) -> bytes:
    """Replace a chunk's payload, with a valid CRC (so the damage is in the meaning, not the checksum)."""
    length, ctype = struct.unpack_from(">I4s", data, offset)
    new = struct.pack(">I4s", len(payload), ctype) + payload + struct.pack(">I", zlib.crc32(ctype + payload))
    return data[:offset] + new + data[offset + 12 + length :]


def m_png_header(data, rng):
    chunks = png_chunks(data)
    ihdr = next((c for c in chunks if c[1] == b"IHDR"), None)
    if ihdr is None:
        return m_flip_bits(data, rng)
    payload = bytearray(data[ihdr[0] + 8 : ihdr[0] + 8 + ihdr[2]])
    how = rng.choice(("size", "size", "depth", "colour", "interlace"))
    if how == "size":
        w, h = rng.choice(
            ((0x7FFFFFFF, 0x7FFFFFFF), (100000, 100000), (10000, 10000), (0, 10), (1, 1 << 30), (65535, 65535), (3, 2))
        )
        struct.pack_into(">II", payload, 0, w, h)
        desc = f"IHDR size -> {w}x{h} (CRC fixed)"
    elif how == "depth":
        payload[8] = rng.choice((0, 3, 7, 16, 32))
        desc = f"IHDR bit depth -> {payload[8]} (CRC fixed)"
    elif how == "colour":
        payload[9] = rng.choice((1, 5, 7, 255))
        desc = f"IHDR colour type -> {payload[9]} (CRC fixed)"
    else:
        payload[12] = rng.choice((1, 2))
        desc = f"IHDR interlace -> {payload[12]} (CRC fixed)"
    return _png_set_chunk(data, ihdr[0], bytes(payload)), desc, False


_BOMB: list[bytes] = []


def _zlib_bomb(mib: int = 32) -> bytes:
    """A zlib stream of ``mib`` MiB of zeros (about 32 KiB), built once in 1 MiB steps."""
    if not _BOMB:
        z, block = zlib.compressobj(9), b"\x00" * (1 << 20)
        _BOMB.append(b"".join(z.compress(block) for _ in range(mib)) + z.flush())
    return _BOMB[0]


def m_png_chunks(data, rng):
    chunks = png_chunks(data)
    how = rng.choice(("no-iend", "dup-idat", "idat-garbage", "huge-length", "bomb", "no-idat"))
    idat = [c for c in chunks if c[1] == b"IDAT"]
    if how == "no-iend":
        iend = [c for c in chunks if c[1] == b"IEND"]
        return (data[: iend[0][0]] if iend else data), "IEND removed", False
    if not idat:
        return m_truncate(data, rng)
    off, _, length = idat[0]
    if how == "dup-idat":
        chunk = data[off : off + 12 + length]
        return data[:off] + chunk + data[off:], "IDAT duplicated", False
    if how == "no-idat":
        return data[:off] + data[off + 12 + length :], "IDAT removed", False
    if how == "huge-length":
        b = bytearray(data)
        struct.pack_into(">I", b, off, rng.choice((0x7FFFFFFF, 0xFFFFFFFF, length + 1000)))
        return bytes(b), f"IDAT length -> {struct.unpack_from('>I', b, off)[0]:#x}", False
    if how == "bomb":  # a small IDAT that inflates to 32 MiB
        return _png_set_chunk(data, off, _zlib_bomb()), "IDAT inflates to 32 MiB (CRC fixed)", False
    payload = bytearray(data[off + 8 : off + 8 + length])
    for _ in range(rng.randint(1, 6)):
        if payload:
            payload[rng.randrange(len(payload))] = rng.randrange(256)
    return _png_set_chunk(data, off, bytes(payload)), "IDAT bytes damaged (CRC fixed)", False


PNG_MUTATORS = {
    "truncate": (m_truncate, 3),
    "flip_bits": (m_flip_bits, 3),
    "set_bytes": (m_set_bytes, 2),
    "header": (m_png_header, 4),
    "chunks": (m_png_chunks, 4),
    "wipe": (m_wipe, 1),
}


def mutators_for(fmt: str) -> dict:
    return PNG_MUTATORS if fmt == "png" else BINARY_MUTATORS if FORMATS[fmt]["binary"] else TEXT_MUTATORS


def mutate(fmt: str, data: bytes, rng: random.Random) -> tuple[bytes, str, bool]:
    """One seeded mutation of ``data``: ``(new bytes, description, wrote a non-finite token)``."""
    table = mutators_for(fmt)
    names = list(table)
    name = rng.choices(names, weights=[table[n][1] for n in names])[0]
    if not data:
        return data + b"\x00", "empty seed + NUL", False
    new, desc, nonfinite = table[name][0](data, rng)
    return new, f"{name}: {desc}", nonfinite


# =========================================================================== cases


def sample_files(samples: Path, fmt: str) -> list[Path]:
    """The seed files of a format under ``samples`` (``shared/samples``), sorted."""
    pattern = FORMATS[fmt]["glob"]
    return sorted(samples.glob(pattern)) if pattern else []


def _asf_for(amc: Path) -> Path | None:
    """The ASF beside an AMC (same stem, else the longest stem that prefixes the AMC's, else the only one)."""
    asfs = sorted(amc.parent.glob("*.asf"))
    same = [a for a in asfs if a.stem == amc.stem]
    prefixed = sorted((a for a in asfs if amc.stem.startswith(a.stem)), key=lambda a: -len(a.stem))
    return (same or prefixed or asfs or [None])[0]


def make_silhouette_seeds(folder: Path, frames: int = 3, size: tuple[int, int] = (64, 44)) -> list[Path]:
    """Binary walking-figure silhouettes as CASIA-B-style PNGs in ``folder`` (PIL only): 8-bit gray
    frames, plus one 1-bit and one palette frame, named ``001-nm-01-090-NNN.png``."""
    from PIL import Image, ImageDraw

    folder.mkdir(parents=True, exist_ok=True)
    h, w = size
    out = []
    for t in range(frames):
        img = Image.new("L", (w, h), 0)
        d = ImageDraw.Draw(img)
        cx = w // 2 + t
        d.ellipse((cx - 5, 2, cx + 5, 12), fill=255)  # head
        d.rectangle((cx - 6, 12, cx + 6, 34), fill=255)  # trunk
        d.line((cx, 34, cx - 6 + 3 * t, h - 1), fill=255, width=4)  # legs
        d.line((cx, 34, cx + 6 - 3 * t, h - 1), fill=255, width=4)
        mode = ("L", "1", "P")[t % 3]
        path = folder / f"001-nm-01-090-{t + 1:03d}.png"
        (img if mode == "L" else img.convert(mode)).save(path)
        out.append(path)
    return out


def make_cases(fmt: str, seeds: list[Path], out_dir: Path, n: int, seed: int = 0, start: int = 0) -> list[Case]:
    """``n`` mutated copies of the ``seeds`` of ``fmt`` under ``out_dir/<fmt>/<i>/`` (one folder per case,
    the seed's file name kept, since readers look at names: the AMC's ASF, NTU/MSR names, CASIA-B folders).

    AMC cases copy the seed's ASF beside the AMC and mutate one of the two (the ASF a third of the time).
    PNG cases (``seeds`` = one sequence folder of frames) are laid out as ``001/nm-01/090/`` with one frame
    mutated, read as a sequence every other case and as a single silhouette otherwise.
    """
    cases = []
    cache: dict[Path, bytes] = {}
    for i in range(start, start + n):
        rng = random.Random(f"{seed}:{fmt}:{i}")
        src = seeds[i % len(seeds)]
        case_dir = out_dir / fmt / f"{i:05d}"
        kind = FORMATS[fmt]["kind"]
        names = []
        if fmt == "png":
            folder = case_dir / "001" / "nm-01" / "090"
            folder.mkdir(parents=True, exist_ok=True)
            frames = sorted(src.parent.glob("*.png"))
            for f in frames:
                shutil.copyfile(f, folder / f.name)
            target = folder / src.name
            path = target
            kind = "sequence" if i % 2 else "silhouette"
            names = [str(folder)] + [str(folder / f.name) for f in frames]
            label = f"{src.name}"
        else:
            case_dir.mkdir(parents=True, exist_ok=True)
            path = target = case_dir / src.name
            label = src.name
            names = [str(path)]
            mut_src = src
            if fmt == "amc":
                asf = _asf_for(src)
                if asf is not None:
                    shutil.copyfile(asf, case_dir / asf.name)
                    names.append(str(case_dir / asf.name))
                    if rng.random() < 1 / 3:  # mutate the ASF, keep the AMC
                        shutil.copyfile(src, path)
                        target, mut_src, label = case_dir / asf.name, asf, f"{src.name} with [ASF] {asf.name}"
            src = mut_src
        if src not in cache:
            cache[src] = src.read_bytes()
        new, desc, nonfinite = mutate(fmt, cache[src], rng)
        target.write_bytes(new)
        orig = seeds[i % len(seeds)]
        cases.append(
            Case(
                id=f"{fmt}-{i:05d}",
                fmt=fmt,
                mutation=f"{label}: {desc}",
                path=str(path),
                kind=kind,
                seed=str(orig),
                nonfinite_token=nonfinite,
                names=names,
            )
        )
    return cases


SPECIALS = ("directory", "fifo", "dev_zero", "empty", "dangling_symlink", "dev_null")


def make_special_cases(fmt: str, out_dir: Path, companion: Path | None = None) -> list[Case]:
    """A directory, a FIFO, a symlink to ``/dev/zero``, an empty file, a dangling symlink and a symlink
    to ``/dev/null``, each under the format's file name (``x.c3d``...). ``companion`` (an ASF for AMC)
    is copied beside it. PNG specials are read with ``read_silhouette``."""
    name = FORMATS[fmt]["special"]
    cases = []
    for special in SPECIALS:
        d = out_dir / fmt / f"special-{special}"
        d.mkdir(parents=True, exist_ok=True)
        p = d / name
        if companion is not None:
            shutil.copyfile(companion, d / companion.name)
        if special == "directory":
            p.mkdir()
        elif special == "fifo":
            os.mkfifo(p)
        elif special == "dev_zero":
            p.symlink_to("/dev/zero")
        elif special == "dev_null":
            p.symlink_to("/dev/null")
        elif special == "empty":
            p.write_bytes(b"")
        else:
            p.symlink_to(d / "does-not-exist")
        cases.append(
            Case(
                id=f"{fmt}-special-{special}",
                fmt=fmt,
                mutation=f"special file: {special} ({name})",
                path=str(p),
                kind=FORMATS[fmt]["kind"],
                blocking=special == "fifo",
                names=[str(p)],
            )
        )
    return cases


# =========================================================================== runner (parent side)


class _Worker:
    """One worker process: JSON-line requests on stdin, JSON-line answers on stdout."""

    def __init__(self, mem_limit: int, python: str, startup_timeout: float = 120.0):
        self.mem_limit = mem_limit
        self.python = python
        self.startup_timeout = startup_timeout
        self.proc: subprocess.Popen | None = None
        self.err = None
        self.starts = 0

    def start(self) -> None:
        self.err = tempfile.TemporaryFile()  # noqa: SIM115 - lives as long as the worker
        env = dict(
            os.environ,
            OMP_NUM_THREADS="1",
            OPENBLAS_NUM_THREADS="1",
            MKL_NUM_THREADS="1",
            PYTHONFAULTHANDLER="1",
            MOCAPKIT_FUZZ_MEM=str(self.mem_limit),
        )
        entry = (
            f"import sys; sys.path.insert(0, {str(PACKAGE_ROOT)!r}); "
            "from mocapkit.testing import fuzzing; fuzzing.worker_main()"
        )
        self.proc = subprocess.Popen(
            [self.python, "-c", entry],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.err,
            cwd=str(PACKAGE_ROOT),
            env=env,
            bufsize=0,
        )
        self.starts += 1
        line = self._readline(self.startup_timeout)
        if line is None or json.loads(line).get("ready") is not True:
            raise RuntimeError(f"fuzz worker did not start: {self._stderr_tail()}")

    def _readline(self, timeout: float) -> bytes | None:
        """A line from the worker, or None on EOF/timeout (``self.timed_out`` tells which)."""
        self.timed_out = False
        buf = b""
        deadline = time.monotonic() + timeout
        fd = self.proc.stdout.fileno()
        while not buf.endswith(b"\n"):
            left = deadline - time.monotonic()
            if left <= 0:
                self.timed_out = True
                return None
            ready, _, _ = select.select([fd], [], [], left)
            if not ready:
                continue
            chunk = os.read(fd, 65536)
            if not chunk:
                return None
            buf += chunk
        return buf

    def _stderr_tail(self, n: int = 400) -> str:
        try:
            self.err.seek(0)
            text = self.err.read().decode("utf-8", "replace")
        except (OSError, ValueError):
            return ""
        lines = [ln for ln in text.strip().splitlines() if ln.strip()]
        tail = " / ".join(lines[-4:])
        return tail[-n:]

    def kill(self) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
        if self.proc is not None:
            self.proc.wait()
            for s in (self.proc.stdin, self.proc.stdout):
                try:
                    s.close()
                except OSError:
                    pass
        self.proc = None

    def run(self, case: Case, timeout: float) -> Outcome:
        if self.proc is None or self.proc.poll() is not None:
            self.kill()
            self.start()
        t = time.monotonic()
        req = (
            json.dumps(
                {
                    "path": case.path,
                    "kind": case.kind,
                    "seed": case.seed,
                    "names": case.names,
                    "nonfinite_token": case.nonfinite_token,
                }
            )
            + "\n"
        )
        try:
            self.proc.stdin.write(req.encode())
        except BrokenPipeError:
            pass
        line = self._readline(timeout)
        dt = time.monotonic() - t
        if line is not None:
            ans = json.loads(line)
            return Outcome(
                case, ans["outcome"], ans.get("exc_type", ""), ans.get("message", ""), ans.get("names_file", True), dt
            )
        if self.timed_out:
            self.kill()
            return Outcome(case, "hang", "", f"no answer in {timeout:g} s (worker killed)", True, dt)
        rc = self.proc.wait()
        tail = self._stderr_tail()
        self.kill()
        if rc < 0:
            try:
                sig = signal.Signals(-rc).name
            except ValueError:
                sig = f"signal {-rc}"
        else:
            sig = f"exit code {rc}"
        outcome = (
            "memory" if re.search(r"bad_alloc|MemoryError|Cannot allocate memory|out of memory", tail) else "crash"
        )
        return Outcome(case, outcome, sig, tail or "(no stderr)", True, dt)


def run_cases(
    cases: list[Case], timeout: float = 10.0, mem_limit: int = 2 << 30, python: str | None = None, progress=None
) -> list[Outcome]:
    """Read every case in a worker (see the module docstring) and classify it; outcomes in case order.

    ``progress(done, total, outcome)`` is called after each case (from worker threads, under a lock).
    """
    python = python or sys.executable
    results: dict[str, Outcome] = {}
    lock = threading.Lock()
    total = len(cases)

    def record(o: Outcome) -> None:
        with lock:
            results[o.case.id] = o
            if progress is not None:
                progress(len(results), total, o)

    def batch(chunk: list[Case]) -> None:
        w = _Worker(mem_limit, python)
        try:
            for c in chunk:
                record(w.run(c, timeout))
        finally:
            w.kill()

    blocking = [c for c in cases if c.blocking]
    threads = [threading.Thread(target=batch, args=([c],), daemon=True) for c in blocking]
    threads.append(threading.Thread(target=batch, args=([c for c in cases if not c.blocking],), daemon=True))
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return [results[c.id] for c in cases]


def table(outcomes: list[Outcome]) -> str:
    """Counts per format × outcome as a Markdown table."""
    fmts = sorted({o.case.fmt for o in outcomes}, key=lambda f: list(FORMATS).index(f) if f in FORMATS else 99)
    unnamed = Counter(o.case.fmt for o in outcomes if o.outcome == "clean_error" and not o.names_file)
    head = "| format | cases | " + " | ".join(OUTCOMES) + " | clean but file not named |"
    rows = [head, "|---|" + "---:|" * (len(OUTCOMES) + 2)]
    for f in fmts + ["all"]:
        sel = [o for o in outcomes if f == "all" or o.case.fmt == f]
        c = Counter(o.outcome for o in sel)
        un = sum(unnamed.values()) if f == "all" else unnamed[f]
        rows.append(f"| {f} | {len(sel)} | " + " | ".join(str(c[k]) for k in OUTCOMES) + f" | {un} |")
    return "\n".join(rows)


def failures(outcomes: list[Outcome]) -> list[Outcome]:
    return [o for o in outcomes if not o.good]


def describe_failures(outcomes: list[Outcome]) -> str:
    bad = failures(outcomes)
    return f"{len(bad)} of {len(outcomes)} fuzz cases failed (format | mutation | outcome | exception):\n" + "\n".join(
        f"  {o.line()}" for o in bad
    )


def outcome_dict(o: Outcome) -> dict:
    d = asdict(o)
    return d


# =========================================================================== C3D exhaustive campaign

#: The values every byte of a C3D header and parameter section is set to (a value equal to the original byte, or to
#: one already tried at that offset, is skipped: it would read the same file twice).
BYTE_VALUES = ("0x00", "0xFF", "+1", "-1", "random")


@dataclass(frozen=True)
class C3DMutant:
    """One mutant of a C3D file, as edits of the original bytes (the campaign writes the original once and patches
    it in place, so no mutant is ever held whole in memory).

    Attributes:
        region: ``"header"``, ``"parameters"``, ``"data"`` or ``"truncation"``.
        description: what was done, with byte offsets (0-based, from the file's start).
        edits: ``(offset, new bytes)`` pairs.
        truncate: the file is cut to this many bytes (None: not cut).
    """

    region: str
    description: str
    edits: tuple[tuple[int, bytes], ...] = ()
    truncate: int | None = None


def c3d_sections(data: bytes) -> dict[str, range]:
    """Byte ranges of a C3D file's ``header`` (the first 512 bytes), ``parameters`` (the blocks the parameter
    section's own header declares, from the block header byte 1 points to) and ``data`` (from ``POINT:DATA_START``
    in header word 9 to the end), clamped to the file."""
    size = len(data)
    start = max(data[0] - 1, 1) * 512 if size else 512
    blocks = data[start + 2] if start + 2 < size else 0
    data_start = max(struct.unpack_from("<H", data, 16)[0] - 1, 0) * 512 if size >= 18 else size
    if data_start >= size or data_start < start:  # a header that points nowhere useful: after the parameters
        data_start = min(size, start + blocks * 512)
    return {
        "header": range(0, min(512, size)),
        "parameters": range(min(start, size), min(start + blocks * 512, size)),
        "data": range(data_start, size),
    }


def c3d_mutants(
    data: bytes, seed: str = "0", data_mutations: int = 1000, truncations: int = 300
) -> Iterator[C3DMutant]:
    """Every mutant of the exhaustive C3D campaign of ``data``, generated lazily, seeded by ``seed``:

    - every byte of the header and of the parameter section set to each of :data:`BYTE_VALUES` (``+1`` / ``-1``
      wrap around; ``random`` drawn per offset);
    - ``data_mutations`` random multi-byte mutations of the data section: 2–16 random bytes set to random values,
      a run of 4–64 random bytes, or 1–8 aligned 4-byte words set to NaN / ±Inf / ±1e38 / a denormal (a float
      file) or to 0x7FFF / 0x8000 / 0xFFFF pairs (an integer file);
    - ``truncations`` cuts inside the data section: at random bytes, at frame boundaries (16 bytes × points) and
      one byte either side of them.
    """
    sections = c3d_sections(data)
    for region in ("header", "parameters"):
        span = sections[region]
        for offset in span:
            original = data[offset]
            draw = random.Random(f"{seed}:{offset}").randrange(256)
            values = {"0x00": 0, "0xFF": 255, "+1": (original + 1) % 256, "-1": (original - 1) % 256, "random": draw}
            tried = {original}
            for name, value in values.items():
                if value in tried:
                    continue
                tried.add(value)
                yield C3DMutant(
                    region,
                    f"{region} byte {offset} (+{offset - span.start}): {original:#04x} -> {value:#04x} ({name})",
                    ((offset, bytes([value])),),
                )
    span = sections["data"]
    if len(span) < 8:
        return
    rng = random.Random(f"{seed}:data")
    floats = struct.unpack_from("<f", data, 12)[0] < 0 if len(data) >= 16 else True
    bad_words = (
        [struct.pack("<f", v) for v in (math.nan, math.inf, -math.inf, 1e38, -1e38, 1e-45)]
        if floats
        else [struct.pack("<HH", a, b) for a in (0x7FFF, 0x8000, 0xFFFF) for b in (0x7FFF, 0x8000, 0)]
    )
    for _ in range(data_mutations):
        how = rng.choice(("bytes", "block", "words"))
        if how == "bytes":
            edits = tuple(
                (rng.randrange(span.start, span.stop), bytes([rng.randrange(256)])) for _ in range(rng.randint(2, 16))
            )
            what = f"{len(edits)} random bytes at {sorted(o for o, _ in edits)[:4]}..."
        elif how == "block":
            length = rng.randint(4, 64)
            at = rng.randrange(span.start, max(span.start + 1, span.stop - length))
            edits = ((at, bytes(rng.randrange(256) for _ in range(length))),)
            what = f"{length} random bytes from {at}"
        else:
            words = (len(span) // 4) or 1
            edits = tuple(
                (span.start + 4 * rng.randrange(words), rng.choice(bad_words)) for _ in range(rng.randint(1, 8))
            )
            what = (
                f"{len(edits)} {'float' if floats else 'int16'} words set to odd values at {[o for o, _ in edits][:4]}"
            )
        yield C3DMutant("data", f"data: {what}", edits)
    points = struct.unpack_from("<H", data, 2)[0] if len(data) >= 4 else 0
    frame = max(16 * points, 1) if floats else max(8 * points, 1)
    for _ in range(truncations):
        if rng.random() < 0.5:
            cut = rng.randrange(span.start, span.stop)
        else:
            cut = span.start + frame * rng.randrange(max(len(span) // frame, 1)) + rng.choice((-1, 0, 1))
        cut = min(max(cut, span.start), len(data) - 1)
        yield C3DMutant("truncation", f"truncated at byte {cut} of {len(data)} (data from {span.start})", truncate=cut)


def count_c3d_mutants(data: bytes, seed: str = "0", data_mutations: int = 1000, truncations: int = 300) -> dict:
    """Mutants per region of :func:`c3d_mutants` (counted by generating their descriptions only)."""
    return dict(Counter(m.region for m in c3d_mutants(data, seed, data_mutations, truncations)))


#: The columns of the campaign table, in order (``located``: a documented error whose message names the file;
#: ``unlocated``: one that does not).
CAMPAIGN_COLUMNS = ("mutants", "ok", "located", "unlocated", "crash", "hang", "memory", "raw_exception", "non_finite")


def _column(o: Outcome) -> str:
    if o.outcome == "clean_error":
        return "located" if o.names_file else "unlocated"
    return o.outcome


def run_c3d_campaign(
    files: list[Path],
    out_dir: Path,
    seed: str = "0",
    data_mutations: int = 1000,
    truncations: int = 300,
    timeout: float = 10.0,
    mem_limit: int = 2 << 30,
    keep_failures: Path | None = None,
    progress=None,
    python: str | None = None,
    every: int = 1,
) -> tuple[dict[str, Counter], list[Outcome]]:
    """Read every mutant of :func:`c3d_mutants` of each file with ``read_motion`` in a worker process (per-file
    ``timeout``, ``RLIMIT_AS`` ``mem_limit``; the worker is restarted after a crash, hang or memory blow-up).

    Each file's mutants are streamed through one path ``out_dir/<stem>/<name>``: the original is written once and
    each mutant patched in and back out, so disk and memory stay at one file. A mutant that is neither ``ok`` nor a
    located error is copied to ``keep_failures/<stem>-<n>.c3d`` (when given) with its description. ``every``
    takes every ``every``-th mutant only (a slice spread over all regions: the tests' CI-sized run).

    Returns:
        ``({file name: Counter of CAMPAIGN_COLUMNS}, [the failing outcomes])``.
    """
    counts: dict[str, Counter] = {}
    bad: list[Outcome] = []
    worker = _Worker(mem_limit, python or sys.executable)
    try:
        for src in files:
            data = Path(src).read_bytes()
            folder = out_dir / Path(src).stem
            folder.mkdir(parents=True, exist_ok=True)
            path = folder / Path(src).name
            path.write_bytes(data)
            tally = counts.setdefault(Path(src).name, Counter())
            for n, mutant in enumerate(c3d_mutants(data, f"{seed}:{Path(src).name}", data_mutations, truncations)):
                if n % every:
                    continue
                with open(path, "r+b") as f:
                    for offset, new in mutant.edits:
                        f.seek(offset)
                        f.write(new)
                    if mutant.truncate is not None:
                        f.truncate(mutant.truncate)
                case = Case(
                    id=f"{Path(src).stem}-{n}",
                    fmt="c3d",
                    mutation=f"{Path(src).name}: {mutant.description}",
                    path=str(path),
                    kind="motion",
                    names=[str(path)],
                )
                outcome = worker.run(case, timeout)
                tally["mutants"] += 1
                tally[_column(outcome)] += 1
                if not outcome.good:
                    bad.append(outcome)
                    if keep_failures is not None:
                        keep_failures.mkdir(parents=True, exist_ok=True)
                        kept = keep_failures / f"{Path(src).stem}-{n}.c3d"
                        shutil.copyfile(path, kept)
                        kept.with_suffix(".txt").write_text(outcome.line() + "\n")
                if mutant.truncate is not None:
                    path.write_bytes(data)
                else:
                    with open(path, "r+b") as f:
                        for offset, new in mutant.edits:
                            f.seek(offset)
                            f.write(data[offset : offset + len(new)])
                if progress is not None:
                    progress(Path(src).name, tally, outcome)
    finally:
        worker.kill()
    return counts, bad


def campaign_table(counts: dict[str, Counter]) -> str:
    """The campaign's counts per file (and all files) as a Markdown table of :data:`CAMPAIGN_COLUMNS`."""
    head = "| file | " + " | ".join(CAMPAIGN_COLUMNS) + " |"
    rows = [head, "|---|" + "---:|" * len(CAMPAIGN_COLUMNS)]
    total = Counter()
    for name, c in counts.items():
        total.update(c)
        rows.append(f"| {name} | " + " | ".join(f"{c[k]:,}" for k in CAMPAIGN_COLUMNS) + " |")
    rows.append("| all | " + " | ".join(f"{total[k]:,}" for k in CAMPAIGN_COLUMNS) + " |")
    return "\n".join(rows)


# =========================================================================== batch commands


@dataclass
class BatchCampaign:
    """One batch command run over a folder of good files plus mutated ones (:func:`run_batch`).

    Attributes:
        command: what ran, e.g. ``"prepare ntu --skip-bad"``.
        argv: the ``mocapkit`` arguments.
        good: the units (files, or CASIA-B sequence names) that must be kept.
        mutants: the mutated units, each with the fuzz :class:`Case` that made it (its mutation).
        unreadable: the mutants the reader rejects on its own (they must be reported by name).
        collect: after the run, ``() -> (kept units, {reported unit: message})`` from the command's report.
        returncode, stderr, seconds: the run (``returncode`` negative: the signal that ended it).
        kept, reported: what ``collect`` found.
        trained: for ``refine --train``, the number of training files it says it used (its report names no
            file it kept): the count check replaces the per-file one.
    """

    command: str
    argv: list[str]
    good: list[str]
    mutants: dict[str, Case]
    unreadable: set[str] = field(default_factory=set)
    collect: object = None
    returncode: int | None = None
    stderr: str = ""
    seconds: float = 0.0
    kept: set[str] = field(default_factory=set)
    reported: dict[str, str] = field(default_factory=dict)
    trained: int | None = None

    def problems(self) -> list[str]:
        """Everything that breaks the promise: the command died or failed, a good unit was not kept, a unit was
        neither kept nor reported (dropped silently), an unreadable mutant was not reported, a report entry that
        does not name its unit."""
        out = []
        if self.returncode != 0:
            how = f"signal {-self.returncode}" if self.returncode and self.returncode < 0 else "exit code"
            out.append(f"{self.command}: ended with {how} {self.returncode}: {self.stderr[-400:]}")
            return out
        units = [*self.good, *self.mutants]
        if self.trained is not None:  # refine --train: counts only
            if self.trained + len(self.reported) != len(units):
                out.append(
                    f"{self.command}: {len(units)} files, trained on {self.trained} and reported "
                    f"{len(self.reported)}: {len(units) - self.trained - len(self.reported)} dropped silently"
                )
        for unit in self.good:
            if unit in self.reported or (self.trained is None and unit not in self.kept):
                out.append(f"{self.command}: good {unit} not kept ({self.reported.get(unit, 'not reported')})")
        for unit, case in self.mutants.items():
            if self.trained is None and unit not in self.kept and unit not in self.reported:
                out.append(f"{self.command}: {unit} dropped silently ({case.mutation})")
            if unit in self.unreadable and unit not in self.reported:
                out.append(f"{self.command}: unreadable {unit} not reported ({case.mutation})")
        for unit, message in self.reported.items():
            if Path(unit).name not in message and unit not in message:
                out.append(f"{self.command}: the report on {unit} does not name it: {message[:200]}")
        return out

    def summary(self) -> dict:
        """One row of the batch table: units, good kept, mutants kept / reported, unreadable reported, problems."""
        return {
            "command": self.command,
            "files": len(self.good) + len(self.mutants),
            "good_kept": sum(
                u in self.kept or (self.trained is not None and u not in self.reported) for u in self.good
            ),
            "good": len(self.good),
            "mutants_kept": sum(u in self.kept for u in self.mutants)
            if self.trained is None
            else sum(u not in self.reported for u in self.mutants),
            "mutants_reported": sum(u in self.reported for u in self.mutants),
            "unreadable_reported": sum(u in self.reported for u in self.unreadable),
            "unreadable": len(self.unreadable),
            "exit": self.returncode,
            "problems": len(self.problems()),
            "seconds": round(self.seconds, 1),
        }


def run_batch(campaign: BatchCampaign, timeout: float = 600.0, python: str | None = None) -> BatchCampaign:
    """Run ``python -m mocapkit *campaign.argv`` in a child process (one thread per library, ``timeout`` s) and
    fill in its outcome and what its report kept and reported."""
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    env["PYTHONPATH"] = os.pathsep.join([str(PACKAGE_ROOT), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    start = time.monotonic()
    try:
        proc = subprocess.run(
            [python or sys.executable, "-m", "mocapkit", *campaign.argv],
            capture_output=True,
            text=True,
            timeout=timeout,
            env=env,
            cwd=str(PACKAGE_ROOT),
        )
        campaign.returncode, campaign.stderr = proc.returncode, proc.stderr
        stdout = proc.stdout
    except subprocess.TimeoutExpired as exc:
        campaign.returncode, campaign.stderr, stdout = -9, f"hang: no end in {timeout:g} s", str(exc.stdout or "")
    campaign.seconds = time.monotonic() - start
    if campaign.returncode == 0:
        campaign.kept, campaign.reported, campaign.trained = campaign.collect(stdout)
    return campaign


def _unit(path) -> str:
    return str(Path(path).resolve())


def _mutate_into(fmt: str, seeds: list[Path], folder: Path, n: int, seed: int, name) -> dict[str, Case]:
    """``n`` fuzz mutants of ``seeds`` (:func:`make_cases`) moved into ``folder`` as ``name(i, seed_path)``;
    AMC mutants are of the AMC only (the folder shares its ASF)."""
    work = folder.parent / f"{folder.name}-cases"
    out: dict[str, Case] = {}
    i = 0
    while len(out) < n:
        (case,) = make_cases(fmt, seeds, work, 1, seed=seed, start=i)
        i += 1
        if "[ASF]" in case.mutation:
            continue
        target = folder / name(len(out), Path(case.seed))
        shutil.move(case.path, target)
        case.path, case.names = str(target), [str(target)]
        out[_unit(target)] = case
    shutil.rmtree(work, ignore_errors=True)
    return out


def _rejected(cases: dict[str, Case], kind: str) -> set[str]:
    """The units whose mutant the reader alone does not read (``kind``: how; see :func:`_read`), each read in the
    worker."""
    units = list(cases)
    outcomes = run_cases([replace(cases[u], kind=kind, id=f"unit-{i}") for i, u in enumerate(units)])
    return {u for u, o in zip(units, outcomes) if o.outcome != "ok"}


def batch_prepare_ntu(samples: Path, root: Path, n: int, seed: int = 0) -> BatchCampaign:
    """``prepare ntu --skip-bad``: the NTU samples plus ``n`` mutants of them (renamed to unused sample names)."""
    src = root / "ntu-src"
    src.mkdir(parents=True, exist_ok=True)
    seeds = sample_files(samples, "ntu")
    good = []
    for s in seeds:
        shutil.copyfile(s, src / s.name)
        good.append(_unit(src / s.name))
    mutants = _mutate_into(
        "ntu", seeds, src, n, seed, lambda i, _: f"S017C003P{i // 60 + 1:03d}R002A{i % 60 + 1:03d}.skeleton"
    )
    out = root / "ntu-cache"

    def collect(_stdout):
        report = json.loads((out / "report.json").read_text())
        kept = {_unit(src / f"{b['name']}.skeleton") for b in report["bodies"]}
        kept |= {_unit(src / f"{e['name'] if isinstance(e, dict) else e}.skeleton") for e in report["empty_samples"]}
        return kept, {_unit(s["file"]): s["message"] for s in report["skipped"]}, None

    return BatchCampaign(
        "prepare ntu --skip-bad",
        ["prepare", "ntu", "--src", str(src), "--out", str(out), "--skip-bad", "--quiet"],
        good,
        mutants,
        _rejected(mutants, "ntu"),
        collect,
    )


def batch_prepare_casia_b(root: Path, n: int, seed: int = 0, good_sequences: int = 3) -> BatchCampaign:
    """``prepare casia-b --skip-bad``: ``good_sequences`` generated silhouette sequences plus ``n`` copies with one
    frame mutated (units: sequence names ``SSS/cc-nn/VVV``)."""
    src = root / "casia-src"
    frames = make_silhouette_seeds(root / "casia-seeds")
    good = []
    for i in range(good_sequences):
        name = f"{i + 1:03d}/nm-01/090"
        (src / name).mkdir(parents=True, exist_ok=True)
        for f in frames:
            shutil.copyfile(f, src / name / f.name)
        good.append(name)
    work = root / "casia-cases"
    mutants: dict[str, Case] = {}
    for i, case in enumerate(make_cases("png", frames, work, n, seed=seed)):
        name = f"{50 + i // 11:03d}/bg-01/{18 * (i % 11):03d}"
        folder = src / name
        folder.parent.mkdir(parents=True, exist_ok=True)
        shutil.move(str(Path(case.path).parent), folder)
        for f in folder.iterdir():  # frames keep their sequence's own name
            f.rename(folder / f.name.replace("001-nm-01-090", name.replace("/", "-")))
        target = folder / Path(case.path).name.replace("001-nm-01-090", name.replace("/", "-"))
        case.path, case.id, case.kind = str(target), name, "sequence"
        case.names = [str(folder), *map(str, folder.iterdir())]
        mutants[name] = case
    shutil.rmtree(work, ignore_errors=True)
    out = root / "casia-cache"

    def collect(_stdout):
        import numpy as np

        report = json.loads((out / "report.json").read_text())
        with np.load(out / "index.npz", allow_pickle=False) as index:
            kept = {str(name) for name in index["names"]}
        return (
            kept,
            {s["sequence"]: f"{s['sequence']} ({s['folder']}): {s['message']}" for s in report["skipped"]},
            None,
        )

    return BatchCampaign(
        "prepare casia-b --skip-bad",
        ["prepare", "casia-b", "--src", str(src), "--out", str(out), "--skip-bad", "--quiet"],
        good,
        mutants,
        _rejected(mutants, "sequence"),
        collect,
    )


def _msr_folder(samples: Path, root: Path, n: int, seed: int, label: str) -> tuple[Path, list[str], dict[str, Case]]:
    """MSR Action3D skeleton files (the usable ones: not the all-zero ``a13_s09_e02``) plus ``n`` mutants."""
    src = root / label
    src.mkdir(parents=True, exist_ok=True)
    seeds = [p for p in sample_files(samples, "msr") if p.name.endswith("_skeleton3D.txt") and "a13_s09" not in p.name]
    good = []
    for s in seeds:
        shutil.copyfile(s, src / s.name)
        good.append(_unit(src / s.name))
    mutants = _mutate_into(
        "msr", seeds, src, n, seed, lambda i, s: f"a{i % 20 + 1:02d}_s{i // 20 + 11:02d}_e01_skeleton3D.txt"
    )
    return src, good, mutants


def batch_index(samples: Path, root: Path, n: int, seed: int = 0) -> BatchCampaign:
    """``index --skip-bad`` of MSR Action3D files plus ``n`` mutants (the default retrieval method)."""
    src, good, mutants = _msr_folder(samples, root, n, seed, "index-src")
    out = root / "index"

    def collect(_stdout):
        manifest = json.loads((out / "manifest.json").read_text())
        return (
            {_unit(f["path"]) for f in manifest["files"]},
            {_unit(s["path"]): s["why"] for s in manifest["skipped"]},
            None,
        )

    return BatchCampaign(
        "index --skip-bad",
        ["index", str(src), "--out", str(out), "--skip-bad"],
        good,
        mutants,
        _rejected(mutants, "motion"),
        collect,
    )


def batch_kinect_fix(samples: Path, root: Path, model: Path, n: int, seed: int = 0) -> BatchCampaign:
    """``kinect-fix apply --skip-bad`` with ``model`` on MSR Action3D files plus ``n`` mutants."""
    src, good, mutants = _msr_folder(samples, root, n, seed, "kinect-src")
    out = root / "kinect-out"

    def collect(_stdout):
        report = json.loads((out / "report.json").read_text())
        return {_unit(f["input"]) for f in report["fixed"]}, {_unit(p): why for p, why in report["skipped"]}, None

    return BatchCampaign(
        "kinect-fix apply --skip-bad",
        ["kinect-fix", "apply", str(src), "--model", str(model), "--out", str(out), "--skip-bad"],
        good,
        mutants,
        _rejected(mutants, "motion"),
        collect,
    )


def batch_refine_train(
    amc_folder: Path, take: Path, root: Path, n: int, seed: int = 0, files: int = 4
) -> BatchCampaign:
    """``refine TAKE OUT.npz --method pose-prior --train FOLDER --skip-bad``: ``refine`` reads one take; the folder it
    reads is the training folder: the ``files`` smallest AMC of one performer (and their ASF) plus ``n`` AMC
    mutants."""
    src = root / "refine-train"
    src.mkdir(parents=True, exist_ok=True)
    seeds = sorted((p for p in amc_folder.glob("*.amc") if p != take), key=lambda p: (p.stat().st_size, p.name))[:files]
    asf = _asf_for(seeds[0])
    shutil.copyfile(asf, src / asf.name)
    good = []
    for s in seeds:
        shutil.copyfile(s, src / s.name)
        good.append(_unit(src / s.name))
    mutants = _mutate_into("amc", seeds, src, n, seed, lambda i, s: f"{s.stem[:-4]}_m{i:03d}_120.amc")
    skipped_line = re.compile(r"^skipped training file (.+?): (.*)$")

    def collect(stdout):
        trained = re.search(r"trained on (\d+) motion file", stdout)
        reported = {}
        for line in stdout.splitlines():
            m = skipped_line.match(line.strip())
            if m:
                reported[_unit(m.group(1))] = m.group(0)
        return set(), reported, int(trained.group(1)) if trained else 0

    return BatchCampaign(
        "refine --train FOLDER --skip-bad",
        ["refine", str(take), str(root / "refined.npz"), "--method", "pose-prior", "--train", str(src), "--skip-bad"],
        good,
        mutants,
        _rejected(mutants, "motion"),
        collect,
    )


def tiny_kinect_model(path: Path, seed: int = 0) -> Path:
    """A Zhou GP Kinect reconstructor (the ``kinect-fix`` default) fitted in a second on two random 40-frame
    Kinect-20 clips and saved to ``path``: for ``kinect-fix apply`` campaigns, where what matters is the files."""
    import numpy as np

    from mocapkit.kinect.reconstruction import KinectPostureReconstructor

    rng = np.random.default_rng(seed)
    rest = rng.normal(0.0, 0.3, (1, 20, 3)) + [0.0, 1.0, 3.0]
    clean = [rest + 0.02 * rng.normal(size=(40, 20, 3)) for _ in range(2)]
    noisy = [c + 0.01 * rng.normal(size=c.shape) for c in clean]
    model = KinectPostureReconstructor(n_inducing=8, max_train_frames=80, gp_iterations=1)
    return model.fit(noisy, clean).save(path)


def batch_table(campaigns: list[BatchCampaign]) -> str:
    """The batch campaigns as a Markdown table (:meth:`BatchCampaign.summary`)."""
    rows = [
        "| command | files | good kept | mutants kept | mutants reported | unreadable reported | exit | problems | s |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for c in campaigns:
        s = c.summary()
        rows.append(
            f"| `{s['command']}` | {s['files']} | {s['good_kept']}/{s['good']} | {s['mutants_kept']} | "
            f"{s['mutants_reported']} | {s['unreadable_reported']}/{s['unreadable']} | {s['exit']} | "
            f"{s['problems']} | {s['seconds']:.0f} |"
        )
    return "\n".join(rows)


# =========================================================================== worker (child side)

_RAW_METADATA_KEYS = ("channels", "amc_values", "confidence")


def _nonfinite_report(motion, label: str = "") -> str:
    """Empty when every observed value of a Motion is finite, else what is not."""
    import numpy as np

    problems = []
    pos = np.asarray(motion.positions)
    miss = np.asarray(motion.missing, dtype=bool) if motion.missing is not None else np.zeros(pos.shape[:2], bool)
    bad = ~np.isfinite(pos[~miss])
    if bad.any():
        problems.append(f"{int(bad.sum())} non-finite observed position values")
    if getattr(motion, "rotations", None) is not None:
        rot = np.asarray(motion.rotations)
        badr = ~np.isfinite(rot[~miss])
        if badr.any():
            problems.append(f"{int(badr.sum())} non-finite rotation values")
    fps = getattr(motion, "fps", None)
    if fps is not None and not (isinstance(fps, (int, float)) and math.isfinite(fps) and fps > 0):
        problems.append(f"fps {fps!r}")

    def scan(value, key, depth=0):
        if depth > 3:
            return
        if isinstance(value, dict):
            for k, v in value.items():
                scan(v, f"{key}.{k}" if key else str(k), depth + 1)
        elif isinstance(value, (list, tuple)) and value and not isinstance(value[0], str):
            for i, v in enumerate(value[:16]):
                scan(v, f"{key}[{i}]", depth + 1)
        elif isinstance(value, float):
            if math.isinf(value) or (math.isnan(value) and key.split(".")[0] in _RAW_METADATA_KEYS):
                problems.append(f"metadata {key} = {value}")
        elif isinstance(value, np.ndarray) and value.dtype.kind == "f":
            raw = key.split(".")[0].split("[")[0] in _RAW_METADATA_KEYS
            n = int((~np.isfinite(value)).sum() if raw else np.isinf(value).sum())
            if n:
                problems.append(f"metadata {key}: {n} {'non-finite' if raw else 'infinite'} values")

    scan(getattr(motion, "metadata", {}) or {}, "")
    return "; ".join(problems)


def _read(kind: str, path: str):
    """Read one case; returns (Motion or None, extra non-finite report)."""
    import numpy as np

    if kind.startswith("fake:"):  # the runner's self-test (tests/test_fuzz.py)
        what = kind[5:]
        if what == "segv":
            os.kill(os.getpid(), signal.SIGSEGV)
        elif what == "hang":
            time.sleep(1e6)
        elif what == "memory":
            return bytearray(8 << 30), ""
        elif what == "raw":
            return [][1], ""  # noqa: PLE0643 - on purpose
        elif what == "clean":
            raise FileNotFoundError(f"{path}: no such file (fake)")
        return None, "fake: 3 infinite values" if what == "inf" else ""
    if kind == "silhouette":
        from mocapkit.datasets.formats.casia_b import read_silhouette

        mask = read_silhouette(path)
        ok = mask.dtype == np.uint8 and mask.ndim == 2
        return None, "" if ok else f"mask dtype {mask.dtype} ndim {mask.ndim}"
    if kind == "sequence":
        from mocapkit.datasets.formats.casia_b import GaitSequence, parse_sequence_folder, read_sequence

        folder = Path(path).parent
        rel = folder.relative_to(folder.parents[2])
        seq = GaitSequence(parse_sequence_folder(rel), folder, tuple(sorted(folder.glob("*.png"))))
        read_sequence(seq)
        return None, ""
    from mocapkit.datasets.formats.motion_io import read_motion

    extra = ""
    if kind == "ntu":
        from mocapkit.datasets.formats.ntu_skeleton import read_skeleton

        seq = read_skeleton(path)
        present = np.asarray(seq.present, dtype=bool)
        bad = int((~np.isfinite(np.asarray(seq.joints)[present])).sum())
        badb = int((~np.isfinite(np.asarray(seq.body_info)[present])).sum())
        if bad or badb:
            extra = f"read_skeleton: {bad} non-finite joint values, {badb} non-finite body values"
    return read_motion(path), extra


def _classify_exception(exc: BaseException, names: list[str]) -> dict:
    from mocapkit.datasets.formats.errors import MotionFormatError

    etype = type(exc)
    qual = f"{etype.__module__}.{etype.__qualname__}".removeprefix("builtins.")
    msg = str(exc)
    first = (msg.splitlines() or [""])[0][:300]
    if isinstance(exc, MemoryError):
        outcome = "memory"
    elif isinstance(exc, (MotionFormatError, OSError)) or (
        isinstance(exc, ValueError) and etype.__module__.startswith("mocapkit")
    ):
        outcome = "clean_error"
    else:
        outcome = "raw_exception"
    named = any(n and (n in msg or Path(n).name in msg) for n in names)
    return {"outcome": outcome, "exc_type": qual, "message": first, "names_file": named}


def worker_main() -> None:
    """The worker loop (run with ``python -c``): cap the address space, import the readers, answer requests."""
    import resource

    limit = int(os.environ.get("MOCAPKIT_FUZZ_MEM", str(2 << 30)))
    answers = os.fdopen(os.dup(1), "w", buffering=1)
    os.dup2(2, 1)  # anything a reader prints goes to stderr, not the protocol
    sys.stdout = sys.stderr
    resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    import numpy as np  # noqa: F401

    import mocapkit.datasets.formats.motion_io  # noqa: F401

    answers.write(json.dumps({"ready": True}) + "\n")
    baselines: dict[str, int] = {}
    for line in sys.stdin:
        req = json.loads(line)
        path, names = req["path"], req["names"] or [req["path"]]
        try:
            motion, extra = _read(req["kind"], path)
            report = extra
            if motion is not None:
                report = "; ".join(r for r in (extra, _nonfinite_report(motion)) if r)
                if not report and req["nonfinite_token"] and req["seed"]:
                    seed = req["seed"]
                    if seed not in baselines:
                        try:
                            base, _ = _read(req["kind"], seed)
                            baselines[seed] = (base.positions.shape, int(base.missing.sum()))
                        except Exception:  # noqa: BLE001 - the seed is real data; if it fails, skip the check
                            baselines[seed] = None
                    b = baselines[seed]
                    if b is not None and b[0] == motion.positions.shape and int(motion.missing.sum()) > b[1]:
                        report = (
                            f"non-finite token read as missing: {int(motion.missing.sum()) - b[1]} more "
                            f"missing samples than the original"
                        )
            ans = {"outcome": "non_finite", "exc_type": "", "message": report} if report else {"outcome": "ok"}
        except MemoryError as exc:
            ans = {"outcome": "memory", "exc_type": "MemoryError", "message": str(exc)[:300]}
        except BaseException as exc:  # noqa: BLE001 - classifying everything is the point
            try:
                ans = _classify_exception(exc, names)
            except MemoryError:
                ans = {"outcome": "memory", "exc_type": type(exc).__name__, "message": "(MemoryError classifying)"}
        motion = None
        answers.write(json.dumps(ans) + "\n")
