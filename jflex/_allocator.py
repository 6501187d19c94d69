"""Keep large freed blocks in the process heap (glibc), so repeated batch calls stop page-faulting.

Each call of a jitted batch function returns fresh output buffers. With glibc's defaults a freed
block of a few MB goes back to the operating system (heap trimming, or ``munmap`` for blocks
above the dynamic mmap threshold), and the next call's output touches fresh pages: a page fault
every 4 kB. For a chunk of 64 tool FRFs (4.7 MB) that was half of the wall time on a 2-core
machine (``benchmarks/bench_modal.py``). :func:`tune_allocator` sets the two thresholds with
``mallopt`` so such blocks are reused instead. Blocks above 32 MB (glibc's ceiling for the mmap
threshold) are always mapped; starting Python with ``GLIBC_TUNABLES=glibc.malloc.hugetlb=1``
backs them with huge pages (see the README).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

_M_TRIM_THRESHOLD = -1
_M_MMAP_THRESHOLD = -3
_MMAP_MAX = 32 * 1024 * 1024  # glibc refuses larger mmap thresholds on 64-bit systems


@functools.cache
def _libc():
    name = ctypes.util.find_library("c")
    if name is None:
        return None
    try:
        lib = ctypes.CDLL(name)
        lib.mallopt  # noqa: B018 - absent outside glibc
        return lib
    except (OSError, AttributeError):
        return None


def tune_allocator(mmap_threshold: int = _MMAP_MAX, trim_threshold: int = 1 << 32) -> bool:
    """Serve blocks up to ``mmap_threshold`` bytes from the heap and trim the heap only above
    ``trim_threshold`` bytes of free memory at its top (glibc ``mallopt``), for the whole process.

    The cost: memory freed by a large computation stays resident until the process ends.

    **Returns:** True when glibc accepted both settings, False elsewhere (other C libraries, or
    a value glibc rejects); nothing else changes then.
    """
    if not 0 < int(mmap_threshold) <= _MMAP_MAX:
        raise ValueError(f"tune_allocator: mmap_threshold must be in (0, {_MMAP_MAX}] bytes, got {mmap_threshold}")
    if int(trim_threshold) <= 0:
        raise ValueError(f"tune_allocator: trim_threshold must be > 0 bytes, got {trim_threshold}")
    lib = _libc()
    if lib is None:
        return False
    ok = lib.mallopt(_M_MMAP_THRESHOLD, ctypes.c_int(int(mmap_threshold)))
    ok2 = lib.mallopt(_M_TRIM_THRESHOLD, ctypes.c_int(min(int(trim_threshold), 2**31 - 1)))
    return bool(ok) and bool(ok2)
