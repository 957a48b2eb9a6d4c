"""Helpers shared by tests and benchmarks (not tests themselves; never collected).

``tests/conftest.py`` puts ``tests/`` on ``sys.path`` so tests import ``_support.<module>``;
a benchmark inserts ``tests/`` itself.
"""

from pathlib import Path

#: The real third-party data beside the clone (``../shared/data``; README there).
SHARED_DATA = Path(__file__).resolve().parents[3] / "shared" / "data"
