"""Suite-wide hooks.

- ``tests/`` is on ``sys.path`` (pytest inserts a rootdir conftest's folder), so tests import
  their shared helpers as ``_support.<module>``.
- Under ``CI=true`` a test skipped because ``../shared/data`` (the real third-party data) is
  missing fails instead: CI must not stay green without the real-data tests.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest

#: The real third-party data beside the clone (``/work/shared/data`` on the dev machine).
SHARED_DATA = Path(__file__).resolve().parents[2] / "shared" / "data"


def _ci() -> bool:
    return os.environ.get("CI", "").strip().lower() in ("true", "1", "yes")


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]):  # type: ignore[no-untyped-def]
    outcome = yield
    report = outcome.get_result()
    if not (_ci() and report.skipped and "shared/data" in str(report.longrepr)):
        return
    report.outcome = "failed"
    report.longrepr = (
        f"{item.nodeid}: CI=true and the real data is missing ({SHARED_DATA} not found): "
        "put the shared folder beside the clone (../shared/data), or unset CI to skip"
    )
