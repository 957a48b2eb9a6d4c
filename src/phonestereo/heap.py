"""Large arrays from the reused heap, not fresh pages: glibc's malloc tuned for image work.

glibc serves every allocation above its mmap threshold (at most 32 MB) with a fresh ``mmap``
and returns it to the kernel on ``free``. The renderer and the pipeline allocate and free
arrays of a view's size many times over (a 6.5 MP float64 array is 52 MB): each one costs
a page fault per 4 KB touched and the kernel's zeroing of those pages, again every time.
Measured on a random-3095 face capture (two 6.5 MP views, 2 cores): 19.1 s wall with
2.7 s of system time and 70 000 page faults by default, 14.5 s with 0.07 s and 300 faults
with every block taken from the heap and the heap not trimmed (docs/module-random.md,
session 26).

:func:`keep_large_arrays_on_the_heap` does that for this process (``mallopt``: no mmap'd
blocks, trim the heap's top only past 2 GB) and, through ``MALLOC_MMAP_MAX_`` and
``MALLOC_TRIM_THRESHOLD_``, for the processes it starts. The cost is memory: the heap keeps
its peak (up to the trim threshold) for reuse, as a long render or batch would reach it again.
Threads other than the main one still get mmap'd blocks when their arena cannot hold one
(glibc falls back). A value the user set for either variable wins; on a C library other than
glibc (macOS, musl) nothing changes. The CLI calls it first thing; tests and benchmarks too.
"""

from __future__ import annotations

import ctypes
import os
import platform

#: ``mallopt`` parameters (glibc's malloc.h).
M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4

#: Free memory at the heap's top kept for reuse, bytes (``mallopt`` takes a C int: < 2 GiB).
TRIM_THRESHOLD_BYTES = 2**31 - 1

#: The environment variables glibc reads these from when a process starts.
MALLOC_VARIABLES = {"MALLOC_MMAP_MAX_": "0", "MALLOC_TRIM_THRESHOLD_": str(TRIM_THRESHOLD_BYTES)}


def keep_large_arrays_on_the_heap() -> bool:
    """Serve large arrays from the heap and keep freed memory for reuse (module docstring).

    Returns
    -------
    bool
        True if glibc's malloc was tuned in this process; False on another C library or where
        the user set either variable (then nothing is changed).
    """
    if platform.libc_ver()[0] != "glibc" or any(name in os.environ for name in MALLOC_VARIABLES):
        return False
    try:
        libc = ctypes.CDLL(None)
        ok = libc.mallopt(M_MMAP_MAX, 0) == 1
        ok &= libc.mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
    except (OSError, AttributeError):  # pragma: no cover - glibc always has mallopt
        return False
    if ok:
        os.environ.update(MALLOC_VARIABLES)
    return bool(ok)


__all__ = ["MALLOC_VARIABLES", "keep_large_arrays_on_the_heap"]
