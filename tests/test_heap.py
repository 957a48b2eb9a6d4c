"""glibc's malloc tuned for image work (phonestereo.heap): a view-sized array comes from the
heap's reused pages instead of a fresh mapping faulted in again (a random-3095 face capture 19.1 →
14.5 s, system time 2.7 → 0.07 s, docs/module-random.md, session 26)."""

from __future__ import annotations

import os
import platform
import subprocess
import sys

import pytest

from phonestereo.heap import USER_VARIABLES

pytestmark = pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc only")

#: Bytes glibc holds in mmap'd blocks while a 64 MB array (one freed before it) is alive:
#: ``mallinfo2().hblkhd`` (glibc ≥ 2.33).
_CODE = (
    "import ctypes, sys, numpy as np\n"
    "from phonestereo.heap import keep_large_arrays_on_the_heap\n"
    "class Info(ctypes.Structure):\n"
    "    _fields_ = [(n, ctypes.c_size_t) for n in 'arena ordblks smblks hblks hblkhd usmblks "
    "fsmblks uordblks fordblks keepcost'.split()]\n"
    "libc = ctypes.CDLL(None); libc.mallinfo2.restype = Info\n"
    "tuned = keep_large_arrays_on_the_heap() if sys.argv[1] == '1' else None\n"
    "a = np.ones(8 << 20); del a\n"
    "a = np.ones(8 << 20)\n"
    "print(tuned, libc.mallinfo2().hblkhd)\n"
)


def _run(tune: bool, **env: str) -> tuple[str, int]:
    clean = {k: v for k, v in os.environ.items() if k not in USER_VARIABLES}
    out = subprocess.run(
        [sys.executable, "-c", _CODE, "1" if tune else "0"],
        capture_output=True, text=True, check=True, env={**clean, **env},
    )
    tuned, mapped = out.stdout.split()
    return tuned, int(mapped)


def test_large_arrays_come_from_the_heap_not_fresh_mappings() -> None:
    tuned, mapped = _run(True)
    # Blocks mapped before the call (imports) stay; the array is not among them.
    assert tuned == "True" and mapped < 8 << 20, (tuned, mapped)
    _, default = _run(False)
    assert default >= 64 << 20, default  # glibc's default: a fresh mmap per large array


@pytest.mark.parametrize(
    "env",
    [
        {"MALLOC_MMAP_MAX_": "65536"},
        {"MALLOC_MMAP_THRESHOLD_": "131072"},
        {"MALLOC_TRIM_THRESHOLD_": "131072"},
        {"PHONESTEREO_MALLOC": "default"},
    ],
)
def test_a_malloc_setting_the_user_made_is_kept(env: dict[str, str]) -> None:
    tuned, mapped = _run(True, **env)
    assert tuned == "False" and mapped >= 64 << 20, (tuned, mapped)
