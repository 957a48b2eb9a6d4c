"""Options shared by the flow commands (learn, depth, evaluate, demo, batch)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

#: ``--config FLOW.json``: the flow configuration (docs/flow-config.md).
CONFIG_OPTION = Annotated[
    Path | None,
    typer.Option(
        "--config",
        help="Flow configuration JSON (any subset of the knobs; `phonestereo config show` "
        "prints them all with their defaults). Default: the built-in defaults.",
        show_default=False,
    ),
]
