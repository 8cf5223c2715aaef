"""glibc keeps a freed step's memory for the next step once :func:`keep_freed_memory` ran."""

import ctypes
import subprocess
import sys

import pytest

from mocapkit.train.allocator import keep_freed_memory

#: Prints how much of a freed 8 MiB block glibc kept in its heap (mallinfo2's free bytes), with and without.
PROBE = """
import ctypes, sys
import numpy as np
from mocapkit.train.allocator import keep_freed_memory

class MallInfo2(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                 "keepcost")]

libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype = MallInfo2
if sys.argv[1] == "on":
    assert keep_freed_memory()
block = np.ones(8 * 2**20 // 8)
del block
print(libc.mallinfo2().fordblks)
"""


def _kept_bytes(mode: str) -> int:
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True)
    return int(out.stdout.split()[-1])


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc only")
def test_a_freed_block_stays_in_the_heap():
    try:
        has_mallinfo2 = hasattr(ctypes.CDLL("libc.so.6"), "mallinfo2")
    except OSError:
        has_mallinfo2 = False
    if not has_mallinfo2:
        pytest.skip("no glibc >= 2.33 (mallinfo2)")
    assert _kept_bytes("off") < 2**20  # glibc's default: mapped, then returned to the system
    assert _kept_bytes("on") >= 8 * 2**20  # kept for the next step


def test_the_users_own_glibc_settings_win(monkeypatch):
    monkeypatch.setenv("MALLOC_TRIM_THRESHOLD_", "131072")
    assert keep_freed_memory() is False
