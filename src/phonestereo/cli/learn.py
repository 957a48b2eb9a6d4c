"""``phonestereo learn``: face captures → disparity observations in a fix store (thesis §4.1.3)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn
from rich.table import Table

from phonestereo.cli.app import app
from phonestereo.errors import InputError, StoreError
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.learning import run as run_learning
from phonestereo.io import load_calibration, load_capture_set
from phonestereo.learning.learn import LearnSummary, learn_capture_set
from phonestereo.learning.store import FixStore


def _table(summary: LearnSummary) -> Table:
    table = Table(title=f"learned into {summary.store_path}")
    for col in ("capture", "faces", "d − d_expected (px)", "time (s)", "note"):
        table.add_column(col)
    for r in summary.results:
        faces = r.disparity.faces if r.disparity is not None else ()
        corr = ", ".join(f"{f.d_px - f.d_expected_px:+.2f}" for f in faces[:4])
        corr += " ..." if len(faces) > 4 else ""
        table.add_row(
            r.capture_id, str(len(r.observations)), corr, f"{r.timing_s['total']:.2f}", r.reason
        )
    return table


@app.command("learn")
def learn(
    capture_set: Annotated[Path, typer.Argument(help="Capture-set folder (manifest.json).")],
    calibration: Annotated[
        Path, typer.Option("--calibration", help="calibration.json to learn on.")
    ],
    store: Annotated[
        Path, typer.Option("--store", help="Fix store (SQLite) to write; created when absent.")
    ],
    ipd_mm: Annotated[
        float, typer.Option("--ipd-mm", help="IPD of the face chart's faces, millimetres.")
    ] = 63.0,
    population: Annotated[
        bool,
        typer.Option(
            "--population",
            help="Real faces of unknown IPD: use the population prior (thesis §3.6) instead.",
        ),
    ] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the summary as JSON.")] = False,
) -> None:
    """Learn disparity observations from the face captures of CAPTURE_SET into STORE.

    Face-chart mode (default) runs the learning flow of thesis Fig. 4-3/4-4: gates (warm-up,
    fixed focus, orientation), focus calibration of each refocus stack, faces in the wide and
    tele, depth from the IPD, disparity at the eyes, the W-T scale over the chart, one
    observation per face (rectified wide position, measured and expected disparity, depth,
    orientation, focus group, time, temperature). Captures without usable faces are skipped
    with the reason. Exit code 0 when something was learned, 1 when nothing was, 2 on bad input.

    Example: phonestereo learn runs/learning --calibration runs/learning/calibration.json
    --store fixes.sqlite
    """
    console = Console(stderr=True)
    columns = (
        TextColumn("learning"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        TextColumn("{task.fields[capture]}"),
    )
    if not population:
        _learn_flow(capture_set, calibration, store, ipd_mm, as_json, columns, console)
        return
    try:
        with Progress(*columns, console=console, transient=True, disable=as_json) as bar:
            task = bar.add_task("learn", total=None, capture="")
            summary = learn_capture_set(
                capture_set,
                calibration,
                store,
                ipd_mm=ipd_mm,
                population=population,
                progress=lambda done, total, cid: bar.update(
                    task, completed=done, total=total, capture=cid
                ),
            )
    except (InputError, StoreError) as exc:
        console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from exc
    if as_json:
        typer.echo(json.dumps(summary.to_dict(), indent=1))
    else:
        Console().print(_table(summary))
        typer.echo(
            f"{summary.n_observations} observation(s) from "
            f"{sum(r.ok for r in summary.results)}/{len(summary.results)} face capture(s); "
            f"{summary.seconds_per_capture:.2f} s per capture"
        )
    if summary.n_observations == 0:
        raise typer.Exit(1)


def _learn_flow(
    capture_set: Path, calibration: Path, store: Path, ipd_mm: float, as_json: bool,
    columns: tuple[Any, ...], console: Console,
) -> None:  # fmt: skip
    """Face-chart mode: the learning flow (:mod:`phonestereo.flows.learning`)."""
    try:
        cs = load_capture_set(capture_set)
        cal = load_calibration(calibration)
        with (
            FixStore(store) as fs,
            Progress(*columns, console=console, transient=True, disable=as_json) as bar,
        ):
            task = bar.add_task("learn", total=None, capture="")
            res = run_learning(
                FlowConfig(), cs, cal, fs, ipd_mm=ipd_mm,
                progress=lambda done, total, cid: bar.update(
                    task, completed=done, total=total, capture=cid
                ),
            )  # fmt: skip
    except (InputError, StoreError) as exc:
        console.print(f"[red]error:[/red] {exc}")
        raise typer.Exit(2) from exc
    if as_json:
        typer.echo(
            json.dumps(
                {
                    **res.to_dict(),
                    "store": str(store),
                    "captures": [c.to_dict() for c in res.captures],
                },
                indent=1,
            )
        )
    else:
        table = Table(title=f"learned into {store}")
        for col in ("capture", "faces", "W-T scale", "time (s)", "skipped because"):
            table.add_column(col)
        for c in res.captures:
            wt = c.stages.get("wt_scale") or {}
            scale = f"{wt['scale']:.5f}" if wt.get("ok") else "–"
            table.add_row(c.capture_id, str(len(c.observations)), scale, f"{c.seconds:.2f}",
                          f"{c.gate}: {c.reason}" if c.gate else "")  # fmt: skip
        Console().print(table)
        n_ok = sum(c.ok for c in res.captures)
        typer.echo(f"{res.n_observations} observation(s) from {n_ok}/{len(res.captures)} face "
                   f"capture(s) in {res.seconds:.1f} s")  # fmt: skip
    if res.n_observations == 0:
        raise typer.Exit(1)
