"""BLAS on one thread (phonestereo.blas_threads): the batched tiny solves of the detectors and
fits stalled in OpenBLAS's thread pool on a busy machine (14.0 → 3.65 s for three chart
detections at load 3 on 2 cores, docs/module-random.md, session 25)."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
from threadpoolctl import threadpool_info

from phonestereo.blas_threads import single_blas_thread


def test_blas_runs_on_one_thread_and_children_inherit_it() -> None:
    single_blas_thread()  # numpy (and its BLAS) is already loaded here
    blas = [p for p in threadpool_info() if p["user_api"] == "blas"]
    assert blas and all(p["num_threads"] == 1 for p in blas), blas
    assert os.environ["OPENBLAS_NUM_THREADS"] == "1"
    assert np.allclose(np.linalg.solve(np.eye(3)[None] * 2, np.ones((1, 3))), 0.5)


def test_a_thread_count_the_user_set_is_kept() -> None:
    code = (
        "import numpy\n"
        "from threadpoolctl import threadpool_info\n"
        "from phonestereo.blas_threads import single_blas_thread\n"
        "single_blas_thread()\n"
        "print([p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas'])\n"
    )
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "2"}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, env=env)
    # OpenBLAS caps the count at the machine's cores (and its build's maximum)
    assert out.stdout.strip() == str([min(2, os.cpu_count() or 1)]), out.stdout
