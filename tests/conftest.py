"""Suite-wide hooks.

- ``tests/`` is on ``sys.path`` (pytest inserts a rootdir conftest's folder), so tests import
  their shared helpers as ``_support.<module>``.
- BLAS runs on one thread, as under the CLI (:mod:`phonestereo.blas_threads`): the suite's
  two workers on two cores would otherwise stall in OpenBLAS's thread pool.
- The slow tests run longest first (:mod:`_support.slow_order`), so that `make acceptance`'s two
  workers finish together.
- Under ``CI=true`` a test skipped because the real third-party data (``../shared/data``) or
  the headless browser (Chromium) is missing fails instead: CI must not stay green without
  the real-data tests or the report's browser test.
"""

from __future__ import annotations

import os
from collections.abc import Generator
from typing import Any

import pytest

from _support import SHARED_DATA
from _support.slow_order import order_slowest_first
from phonestereo.blas_threads import single_blas_thread
from phonestereo.heap import keep_large_arrays_on_the_heap

single_blas_thread()
keep_large_arrays_on_the_heap()

#: Skip reasons that mean "an input CI must have is missing" (the tests' own wording).
CI_REQUIRED = {
    "shared/data": f"the real data is missing ({SHARED_DATA} not found): put the shared folder "
    "beside the clone (../shared/data)",
    "chromium not installed": "Chromium is missing: apt-get install -y chromium (.ci/run does)",
}


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    order_slowest_first(items)


def ci_enabled() -> bool:
    """True when the environment says this is CI (``CI=true``, as most CI services set)."""
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo[None]
) -> Generator[None, Any, None]:
    outcome = yield
    report = outcome.get_result()
    if not (ci_enabled() and report.skipped):
        return
    why = str(report.longrepr)
    for key, message in CI_REQUIRED.items():
        if key in why:
            report.outcome = "failed"
            report.longrepr = f"{item.nodeid}: CI=true and {message}; or unset CI to skip"
            return
