"""One BLAS thread per process: the package's linear algebra is many tiny problems.

The detectors, fits and flows solve thousands of 2×2 to 6×6 systems at a time (batched
``np.linalg.solve`` / ``inv``: one LAPACK call per matrix). A multi-threaded OpenBLAS wakes
and synchronises its thread pool for every one of them; when the machine's cores are all busy
(two pytest or Dask workers on 2 cores, a bench beside a render) each of those waits costs a
scheduler slice. Measured on 2 cores under a load of 3: three verification-chart detections
14.0 s with OpenBLAS's default 2 threads, 3.65 s with 1 (``np.linalg.solve`` 6.5 → < 0.1 s,
``inv`` 3.7 → < 0.1 s); the application phase 193 → 154 ms of CPU per capture
(docs/module-random.md, session 25). The few large products (the renderer's ray field) lose
at most their second core. Dask's nanny sets the same variables to 1 in its workers for the
same reason (``distributed.nanny.pre-spawn-environ``).

:func:`single_blas_thread` sets ``OPENBLAS_NUM_THREADS`` and ``MKL_NUM_THREADS`` to 1 where
the user has not set them (child processes read them when they load their BLAS) and limits an
already-loaded BLAS with threadpoolctl. The CLI calls it first thing; tests and benchmarks too.
A user's own value of either variable wins.
"""

from __future__ import annotations

import os

#: The variables BLAS libraries read their thread count from at load time.
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def single_blas_thread() -> None:
    """Run BLAS on one thread in this process and the processes it starts (module docstring);
    a value the user set in the environment is kept."""
    for name in BLAS_THREAD_VARIABLES:
        os.environ.setdefault(name, "1")
    if os.environ["OPENBLAS_NUM_THREADS"] != "1":
        return  # the user asked for threads
    from threadpoolctl import threadpool_limits

    threadpool_limits(1, user_api="blas")


__all__ = ["BLAS_THREAD_VARIABLES", "single_blas_thread"]
