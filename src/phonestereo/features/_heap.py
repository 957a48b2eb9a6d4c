"""Keep freed heap memory in the process between captures (glibc's ``mallopt``).

The matcher works on all its windows at once (:func:`~phonestereo.features.subpixel.refine_lk`:
(n, q, M²) float64 arrays of a megabyte or more), and every block of the application phase
allocates and frees arrays of that size. glibc gives the top of its heap back to the kernel
once more than ``M_TRIM_THRESHOLD`` of it is free, and maps blocks above
``M_MMAP_THRESHOLD`` fresh from the kernel (both dynamic: twice and once the largest block
freed so far); each page of such memory is faulted in again on its next use. At 2000 × 1500
that was ~5000 page faults per ``measure_roi`` (~2 µs each on the 2-core machine: ~10 % of
its CPU). With fixed thresholds of 32 MB (glibc's own dynamic maximum) and 64 MB the process
keeps up to 64 MB of freed heap per arena and reuses it: ~700 faults. (A process that has
already run the learning flow had raised glibc's own thresholds far enough: there
``measure_roi`` faults ~0 times either way; the setting pays in a fresh process.)

Linux with glibc only (elsewhere, or with ``MALLOC_TRIM_THRESHOLD_`` / ``MALLOC_MMAP_THRESHOLD_``
already set, or ``PHONESTEREO_MALLOC=default``, nothing is changed). Process-wide and set once:
the flows call :func:`retain_freed_memory` on their first capture.
"""

from __future__ import annotations

import ctypes
import os
import sys

__all__ = ["retain_freed_memory"]

#: glibc's ``mallopt`` parameter numbers (malloc.h).
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
#: Blocks up to this size come from the heap (glibc's dynamic threshold stops here too).
MMAP_THRESHOLD_BYTES = 32 << 20
#: Free heap kept per arena before its top is given back.
TRIM_THRESHOLD_BYTES = 64 << 20

_state: list[bool] = []


def retain_freed_memory() -> bool:
    """Set the thresholds (module docstring) once per process; True when they are in force.

    >>> isinstance(retain_freed_memory(), bool)
    True
    """
    if not _state:
        _state.append(_apply())
    return _state[0]


def _apply() -> bool:
    env = os.environ
    if env.get("PHONESTEREO_MALLOC", "").strip().lower() == "default":
        return False
    if "MALLOC_TRIM_THRESHOLD_" in env or "MALLOC_MMAP_THRESHOLD_" in env:
        return False  # the user's own glibc tuning wins
    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    return bool(
        mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES) == 1
        and mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES) == 1
    )
