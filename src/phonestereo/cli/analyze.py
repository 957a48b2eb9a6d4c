"""``phonestereo analyze NAME CAPTURE_SET --out DIR``: a chapter-3 analysis (thesis §3.1–§3.6).

A thin wrapper over :func:`phonestereo.evaluation.analyses.run_analysis`; the analyses and what
each needs are in :data:`phonestereo.evaluation.analyses.ANALYSES`. Exit code 0 when the
analysis produced its result, 1 when the data could not give it (the reason is printed), 2 on
bad input (an unknown analysis, an invalid capture set, or one lacking the captures needed).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

from phonestereo.cli.app import app
from phonestereo.cli.outputs import require_writable
from phonestereo.cli.widgets import json_option
from phonestereo.errors import InputError
from phonestereo.evaluation.analyses import ANALYSES, run_analysis

_NAME_HELP = "One of: " + "; ".join(f"{k} ({v.summary})" for k, v in ANALYSES.items())


def _json_safe(v: Any) -> Any:
    if isinstance(v, dict):
        return {k: _json_safe(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [_json_safe(x) for x in v]
    if isinstance(v, float) and v != v:  # NaN
        return None
    return v


@app.command("analyze")
def analyze_command(
    name: Annotated[str, typer.Argument(help=_NAME_HELP, show_default=False, metavar="NAME")],
    capture_set: Annotated[
        Path,
        typer.Argument(
            help="Capture-set folder (with manifest.json).",
            show_default=False,
            metavar="CAPTURE_SET",
        ),
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Folder for the figures and table.")],
    as_json: Annotated[bool, json_option("Print the analysis table as JSON.")] = False,
) -> None:
    """Run a chapter-3 analysis on a capture set: PNG figures and a JSON table into --out.

    Example: phonestereo simulate heating --out heat && phonestereo analyze heating heat --out fig
    """
    console = Console(stderr=True)
    bar = Progress(
        TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
        TimeRemainingColumn(), console=console, transient=True,
    )
    try:
        require_writable(out)
        with bar:
            task = bar.add_task(f"{name}: measuring captures", total=None)

            def step(done: int, total: int, capture_id: str) -> None:
                bar.update(task, completed=done, total=total, description=f"{name}: {capture_id}")

            result = run_analysis(name, capture_set, out, progress=step)
    except InputError as exc:
        needs = ANALYSES[name].needs if name in ANALYSES else ""
        console.print(f"[red]error:[/red] {exc}" + (f"\n{name} needs: {needs}" if needs else ""))
        raise typer.Exit(2) from exc
    if as_json:
        table = {**_json_safe(result.table), "files": [str(p) for p in result.files]}
        typer.echo(json.dumps(table, allow_nan=False))
    else:
        for line in result.summary:
            typer.echo(line)
        typer.echo("wrote " + ", ".join(str(p) for p in result.files))
    if not result.ok:
        console.print(f"[yellow]no result:[/yellow] {result.reason}")
        raise typer.Exit(1)
