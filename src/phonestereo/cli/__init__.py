"""The ``phonestereo`` command line: one Typer app, each command a thin wrapper over a library call.

Each sub-module registers its commands on :data:`phonestereo.cli.app.app`; importing them here
builds the whole app.
"""

from __future__ import annotations

from phonestereo.cli import analyze as _analyze  # noqa: F401  (registers commands)
from phonestereo.cli import bench_modules as _bench_modules  # noqa: F401
from phonestereo.cli import calibrate as _calibrate  # noqa: F401
from phonestereo.cli import charts as _charts  # noqa: F401
from phonestereo.cli import demo as _demo  # noqa: F401
from phonestereo.cli import depth as _depth  # noqa: F401
from phonestereo.cli import detect as _detect  # noqa: F401
from phonestereo.cli import faces as _faces  # noqa: F401
from phonestereo.cli import io_commands as _io  # noqa: F401
from phonestereo.cli import learn as _learn  # noqa: F401
from phonestereo.cli import match as _match  # noqa: F401
from phonestereo.cli import rectify as _rectify  # noqa: F401
from phonestereo.cli import scaleout as _scaleout  # noqa: F401
from phonestereo.cli import simulate as _simulate  # noqa: F401
from phonestereo.cli import store as _store  # noqa: F401
from phonestereo.cli.app import app

__all__ = ["app", "main"]


def main() -> None:
    """Console-script entry point."""
    app()
