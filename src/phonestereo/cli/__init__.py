"""The ``phonestereo`` command line: one Typer app, each command a thin wrapper over a library call.

Each sub-module registers its commands on :data:`phonestereo.cli.app.app`. They are imported
lazily, when their command runs (:class:`phonestereo.cli.app.LazyGroup`), so that ``--help`` and
``version`` start in a fraction of a second.
"""

from __future__ import annotations

from phonestereo.blas_threads import single_blas_thread
from phonestereo.cli.app import app
from phonestereo.heap import keep_large_arrays_on_the_heap

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point (BLAS on one thread: :mod:`phonestereo.blas_threads`; large
    arrays on the heap: :mod:`phonestereo.heap`)."""
    single_blas_thread()
    keep_large_arrays_on_the_heap()
    app()
