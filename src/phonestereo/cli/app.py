"""The one Typer app; command modules in this package register on it."""

from __future__ import annotations

import typer

from phonestereo import __version__

app = typer.Typer(
    name="phonestereo",
    help="Metric depth from a phone's wide + tele stereo cameras (calibrate, simulate, measure).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_show_locals=False,
)


@app.callback()
def _root() -> None:
    """Metric depth from a phone's wide + tele stereo cameras.

    Start with `phonestereo demo`; every command has --help.
    """


@app.command()
def version() -> None:
    """Print the phonestereo version."""
    typer.echo(__version__)
