"""Pieces several commands' output shares: the ``--json`` summary flag, progress bars, tables,
the error line of a typed error.

No commands here (``app.discover`` finds none); the commands import these so that one option
reads the same everywhere and one progress bar looks the same everywhere.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeRemainingColumn,
)
from rich.table import Table


def flag(name: str, help: str) -> Any:
    """A one-way boolean flag ``name`` (e.g. ``"--quick"``): off unless given, and no
    ``--no-...`` form. Use as ``quick: Annotated[bool, flag("--quick", "...")] = False``."""
    return typer.Option(name, help=help)


def json_option(help: str = "Print the summary as JSON.") -> Any:
    """The ``--json`` flag with a command's own ``help``: print the result as JSON (for scripts)
    instead of tables. Use as ``as_json: Annotated[bool, json_option("...")] = False``."""
    return flag("--json", help)


def overlay_option(what: str) -> Any:
    """The ``--overlay FILE`` option of a detector: write a PNG/JPEG with ``what`` drawn on
    the image. Use as ``overlay: Annotated[Path | None, overlay_option("...")] = None``."""
    return typer.Option("--overlay", help=f"Write a PNG/JPEG with the {what}.")


#: ``--json``: print the command's summary as JSON (for scripts) instead of tables.
JSON_SUMMARY = Annotated[bool, json_option()]

#: ``--out``: the output folder of a resumable run (a rerun with the same folder resumes it).
RESUMABLE_OUT = Annotated[Path, typer.Option("--out", help="Output folder (rerun to resume).")]


def error_exit(exc: Exception) -> typer.Exit:
    """Print ``error: <message>`` in red on stderr and return the exit (status 2) to raise:
    ``raise error_exit(exc) from exc``. The message is escaped: messages hold brackets
    ("[x, y, w, h]") that Rich would read as markup."""
    Console(stderr=True, soft_wrap=True).print(f"[red]error:[/red] {escape(str(exc))}")
    return typer.Exit(2)


def progress_bar(
    label: str, console: Console, *, field: str, disable: bool, transient: bool = True
) -> Progress:
    """A bar with ``label``, done/total, time remaining and the task's ``field`` (e.g. the
    capture id being worked on); ``disable`` under ``--json``."""
    cols: tuple[ProgressColumn, ...] = (
        TextColumn(label),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        TextColumn(f"{{task.fields[{field}]}}"),
    )
    return Progress(*cols, console=console, transient=transient, disable=disable)


def track(
    bar: Progress, description: str, *, field: str, total: int | None = None
) -> Callable[[int, int, str], None]:
    """Add a task to ``bar`` (a :func:`progress_bar` with ``field``) and return the
    ``progress(done, total, key)`` callback the library functions take: it moves the task to
    ``done`` of ``total`` and shows ``key`` in the ``field`` column."""
    blank: dict[str, Any] = {field: ""}
    task = bar.add_task(description, total=total, **blank)

    def update(done: int, of: int, key: str) -> None:
        shown: dict[str, Any] = {field: key}
        bar.update(task, completed=done, total=of, **shown)

    return update


def figure_table(title: str) -> Table:
    """An empty two-column table: a figure's name, and its value right-aligned."""
    table = Table(title=title)
    table.add_column("figure")
    table.add_column("value", justify="right")
    return table
