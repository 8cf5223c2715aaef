"""Keep freed tensor memory inside the process (glibc's malloc), so a step does not fault its pages in again.

glibc serves an allocation above its mmap threshold (128 KiB at first, raised as blocks are freed) with a fresh
``mmap`` and unmaps it on free, and it trims the heap's top above its trim threshold. A training or inference
step allocates the same large tensors step after step, so with the defaults each step maps, faults in and
unmaps tens of megabytes again: on the demo's energy image that was two thirds of its time. PyTorch's CPU
performance guide suggests jemalloc or tcmalloc for this; raising glibc's two thresholds gives the same with the
allocator already loaded (docs/decisions.md#malloc-thresholds). Memory freed by a step stays reserved by the
process, as it would with those allocators.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys

#: ``mallopt`` parameters (glibc's malloc.h).
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3
#: Blocks up to 32 MiB come from the heap (glibc's largest mmap threshold on 64-bit systems) ...
MMAP_THRESHOLD = 32 * 2**20
#: ... and up to 1 GiB of free heap top is kept for the next step.
TRIM_THRESHOLD = 2**30
#: glibc's own environment variables: a user who set either keeps his settings.
GLIBC_VARIABLES = ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds for this process (and the data-loader workers it forks).

    Does nothing on other C libraries and systems, or where ``MALLOC_MMAP_THRESHOLD_`` or
    ``MALLOC_TRIM_THRESHOLD_`` is set. Returns whether the thresholds were set.
    """
    if not sys.platform.startswith("linux") or any(name in os.environ for name in GLIBC_VARIABLES):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # musl and others: no mallopt
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
