"""Large arrays from the reused heap, not fresh pages: glibc's malloc tuned for image work.

glibc serves every allocation above its mmap threshold (dynamic, at most 32 MB) with a fresh
``mmap``, returns it to the kernel on ``free``, and gives the top of its heap back once more
than its trim threshold is free. The renderer, the matcher and the application phase allocate
and free arrays of a view's size or of all a matcher's windows ((n, q, M²) float64, megabytes)
over and over: each time every 4 KB page is faulted in again and zeroed by the kernel.

Measured (2 cores): a random-3095 face capture rendered (two 6.5 MP views) 19.1 s wall with
2.7 s of system time and 70 000 page faults by default, 14.5 s with 0.07 s and 300 faults with
no block mmap'd and the heap not trimmed (docs/module-random.md, session 26). At 2000 × 1500,
``measure_roi`` in a fresh process faulted ~5000 times per call with glibc's defaults (~10 % of
its CPU, 84 → 73 ms per capture with the heap kept; docs/architecture.md).

:func:`keep_large_arrays_on_the_heap` sets, once per process, ``M_MMAP_MAX`` = 0 (every block
from the heap) and ``M_TRIM_THRESHOLD`` just under 2 GiB (freed memory kept for reuse), and
exports ``MALLOC_MMAP_MAX_`` / ``MALLOC_TRIM_THRESHOLD_`` so the processes it starts do the same.
The cost is memory: the heap keeps its peak (up to the threshold), which a long render or
batch reaches again anyway (a 6.5 MP render's peak RSS 2.9 GB either way). Threads other than
the main one still get mmap'd blocks when their arena cannot hold one (glibc falls back).

The CLI calls it first thing; the matcher (``refine_lk``) and ``measure_roi`` call it for a
library user; tests and benchmarks too. Nothing changes on a C library other than glibc, where
the user set any of ``MALLOC_MMAP_MAX_``, ``MALLOC_MMAP_THRESHOLD_`` or
``MALLOC_TRIM_THRESHOLD_`` (their tuning wins), or with ``PHONESTEREO_MALLOC=default``.
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

#: A user's variables that mean "my own glibc tuning": any of them leaves glibc alone.
USER_VARIABLES = (*MALLOC_VARIABLES, "MALLOC_MMAP_THRESHOLD_")

_state: list[bool] = []


def keep_large_arrays_on_the_heap() -> bool:
    """Serve large arrays from the heap and keep freed memory for reuse (module docstring).

    Applied once per process; later calls return the first call's answer.

    Returns
    -------
    bool
        True if glibc's malloc is tuned in this process; False on another C library, with
        ``PHONESTEREO_MALLOC=default``, or where the user set glibc's own variables.

    Examples
    --------
    >>> isinstance(keep_large_arrays_on_the_heap(), bool)
    True
    """
    if not _state:
        _state.append(_apply())
    return _state[0]


def _apply() -> bool:
    env = os.environ
    if env.get("PHONESTEREO_MALLOC", "").strip().lower() == "default":
        return False
    if platform.libc_ver()[0] != "glibc" or any(name in env for name in USER_VARIABLES):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # pragma: no cover - glibc always has mallopt
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    ok = mallopt(M_MMAP_MAX, 0) == 1 and mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
    if ok:
        env.update(MALLOC_VARIABLES)
    return ok


__all__ = ["MALLOC_VARIABLES", "USER_VARIABLES", "keep_large_arrays_on_the_heap"]
