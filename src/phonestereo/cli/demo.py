"""`phonestereo demo`: the thesis bench on the virtual module, end to end (docs/architecture.md).

Simulates the thesis bench (learning from the face chart at 1–3 m, verification charts at 0.8–4 m;
heated, manual focus at 1.5 m, handheld) on a built-in module with every effect
(docs/architecture.md), runs the learning and the application phases, and prints the relative depth
error per distance for each stage — naive Z = f·B/d, the fixes without the learned correction, the
full flow — beside the Cramér–Rao floor, and writes an HTML report with the figures.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import replace
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn

from phonestereo.cli.app import app
from phonestereo.cli.depth import clean, print_bench
from phonestereo.cli.flow_options import CONFIG_OPTION
from phonestereo.cli.outputs import prepare_capture_set_folder
from phonestereo.cli.widgets import error_exit, flag, json_option
from phonestereo.errors import InputError
from phonestereo.evaluation.bench import run_bench
from phonestereo.flows.config_file import load_flow_config
from phonestereo.report.bench_report import write_report
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import BenchConfig, LearningConfig, VerificationConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set

#: The quick bench: the face chart at 3 distances × 5 sensor positions (one attempt each; a
#: face capture takes ~5 s to render), the verification chart at 9 distances × 2 attempts
#: (33 captures; ≤ 90 s on 2 cores). Learning from 15 instead of 40 face captures measured
#: the same full-flow error on two seeds (0.46 / 0.53 % median vs 0.44 / 0.61 %).
QUICK = BenchConfig(
    LearningConfig(distances_m=(1.0, 2.0, 3.0), attempts=1), VerificationConfig(attempts=2)
)


@app.command()
def demo(
    out: Annotated[Path, typer.Option(help="Folder for the capture set and report.")] = Path(
        "demo_out"
    ),
    module: Annotated[str, typer.Option(help="Module preset or JSON file.")] = "folded-x3",
    full: Annotated[
        bool, typer.Option(help="The complete bench (5 attempts per stack) and the ablations.")
    ] = False,
    seed: Annotated[int, typer.Option(help="Random seed.")] = 0,
    workers: Annotated[
        int, typer.Option(help="Rendering processes (0: one per core, up to 2).", min=0)
    ] = 0,
    config: CONFIG_OPTION = None,
    as_json: Annotated[bool, json_option("Print the scores as JSON.")] = False,
    roi_jitter: Annotated[
        float,
        typer.Option(
            help="User ROIs instead of oracle boxes: move and resize each verification ROI by "
            "up to ± this fraction of its size (0.2 = ±20 %), possibly off the chart.",
            min=0.0,
            max=0.5,
        ),
    ] = 0.0,
    force: Annotated[
        bool, flag("--force", "Replace an earlier demo's capture set in --out (files go first).")
    ] = False,
) -> None:
    """Simulate the thesis bench, learn, apply and score every stage against ground truth.

    Writes the capture set (images, manifest, factory calibration, ground truth) and
    report.html (error vs distance per stage, rendered captures with their ROIs, the learned
    correction over the sensor; with --full the ablation table) into --out. --out must be new
    or empty; an earlier demo's capture set there is replaced only with --force.
    """
    t0 = time.perf_counter()
    try:
        cfg = load_flow_config(config)
        spec = load_module(module)
        prepare_capture_set_folder(out, force=force)
    except InputError as exc:
        raise error_exit(exc) from exc
    bench = BenchConfig() if full else QUICK
    if roi_jitter > 0:
        bench = replace(
            bench, verification=replace(bench.verification, roi_jitter=float(roi_jitter))
        )
    plan = plan_scenario("thesis-bench", spec, seed, config=bench)
    console = Console(stderr=True)
    n_workers = workers or min(2, os.cpu_count() or 1)
    cols = (TextColumn("{task.description}"), BarColumn(), MofNCompleteColumn(),
            TimeElapsedColumn())
    with Progress(*cols, console=console, disable=as_json, transient=True) as bar:
        task = bar.add_task("rendering", total=len(plan.captures))
        write_capture_set(
            out, plan, workers=n_workers,
            progress=lambda done, total, cid: bar.update(task, completed=done),
        )

        def progress(stage: str, done: int, total: int) -> None:
            bar.update(task, description=stage, completed=done, total=total)

        res = run_bench(out, cfg, ablations=full, lookups=full, progress=progress)
    res["module"] = spec.name
    res["plan_notes"] = list(plan.notes)  # what was planned for this module, what it cannot see
    report = write_report(res, out / "report.html", title=f"phonestereo demo: {spec.name}")
    res["report"] = str(report)
    res["total_seconds"] = round(time.perf_counter() - t0, 2)
    if as_json:
        typer.echo(json.dumps(clean(res)))
        return
    print_bench(
        res,
        f"relative depth error per verification capture, {spec.name} "
        f"({len(res['captures'])} captures, {res['learning']['n_observations']} learned faces)",
    )
    for note in plan.notes:
        Console().print(f"plan: {note}", soft_wrap=True)
    Console().print(
        f"capture set and report in {out} ({report.name}); {res['total_seconds']:.0f} s in all"
    )
