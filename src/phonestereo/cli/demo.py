"""`phonestereo demo`: simulate the thesis bench on the virtual module and score it.

Until the Phase 0 flows land (issue #7), the demo simulates the verification scenario of the
built-in `folded-x3` module, writes the capture set, and scores the naive Z = f·B/d stage
against ground truth: the ~30 % error the thesis starts from.
"""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from phonestereo.cli.app import app
from phonestereo.evaluation.summary import score_capture_set
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import VerificationConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set


@app.command()
def demo(
    out: Annotated[Path, typer.Option(help="Folder for the simulated capture set.")] = Path(
        "demo_out"
    ),
    module: Annotated[str, typer.Option(help="Module preset or JSON file.")] = "folded-x3",
    full: Annotated[bool, typer.Option(help="The complete scenario (slower).")] = False,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print the scores as JSON.")] = False,
) -> None:
    """Simulate verification captures on the virtual module and score the naive depth.

    Renders real images with every effect of the module (heating, focus breathing, odd
    distortion, non-baseline translation, sag, handheld motion, factory-calibration error,
    sensor noise), writes the capture set to --out, and prints the relative depth error of
    the naive Z = f·B/d per distance. Later stages (each chapter-3 fix, the learned
    correction) are added to the same table as they land.
    """
    t0 = time.perf_counter()
    spec = load_module(module)
    # Default: every distance of the bench, 2 refocus attempts each (~20 s); --full: 5 attempts.
    config = None if full else VerificationConfig(attempts=2)
    plan = plan_scenario("verification", spec, seed, config=config)
    console = Console(stderr=True)
    columns = (TextColumn("rendering"), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    with Progress(*columns, console=console, disable=as_json) as bar:
        task = bar.add_task("render", total=len(plan.captures))
        write_capture_set(
            out, plan, progress=lambda done, total, cid: bar.update(task, completed=done)
        )
    scores = score_capture_set(out)
    scores["seconds"] = time.perf_counter() - t0
    scores["module"] = spec.name
    scores["out"] = str(out)
    if as_json:
        typer.echo(json.dumps(scores))
        return
    table = Table(
        title=f"relative depth error, {spec.name}, {scores['captures']} verification "
        "captures (per capture: median over chart corners)"
    )
    table.add_column("distance")
    table.add_column("naive median", justify="right")
    table.add_column("naive p90", justify="right")
    for row in scores["per_distance"]:
        s = row["stages"]["naive"]
        table.add_row(
            f"{row['distance_m']:.1f} m",
            f"{100 * s['median_rel_err']:.1f} %",
            f"{100 * s['p90_rel_err']:.1f} %",
        )
    s = scores["stages"]["naive"]
    table.add_row("all", f"{100 * s['median_rel_err']:.1f} %", f"{100 * s['p90_rel_err']:.1f} %")
    Console().print(table)
    Console().print(
        f"capture set written to {out} ({scores['seconds']:.1f} s). "
        "The fixes and the learned correction come with the Phase 0 flows."
    )
