"""``phonestereo batch`` and ``phonestereo study``: scale-out on Dask (docs/architecture.md).

Both run on a local Dask cluster (``--workers`` single-threaded processes) or on a running
scheduler (``--scheduler ADDRESS``) with the same code; every input is checked before the
cluster starts.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.progress import Progress
from rich.table import Table

from phonestereo.cli.app import app
from phonestereo.cli.flow_options import CONFIG_OPTION
from phonestereo.cli.widgets import (
    JSON_SUMMARY,
    RESUMABLE_OUT,
    error_exit,
    flag,
    progress_bar,
    track,
)
from phonestereo.errors import InputError
from phonestereo.evaluation.batch import (
    COMMANDS,
    expand_inputs,
    get_command,
    parse_params,
    run_batch,
)
from phonestereo.evaluation.runner import check_address, dask_client
from phonestereo.evaluation.study import METRICS, StudyConfig, run_study
from phonestereo.evaluation.study_bench import AnalyticBenchConfig, get_bench
from phonestereo.evaluation.tolerances import load_tolerances
from phonestereo.sim.module import load_module

SchedulerOpt = Annotated[
    str | None,
    typer.Option(
        "--scheduler",
        help="Address of a running Dask scheduler (tcp://HOST:PORT); default: a local cluster.",
    ),
]
WorkersOpt = Annotated[
    int, typer.Option("--workers", help="Local cluster worker processes (one thread each).")
]


def _bar(console: Console, what: str, quiet: bool) -> Progress:
    return progress_bar(what, console, field="key", disable=quiet)


@app.command()
def batch(
    command: Annotated[str, typer.Argument(help=f"One of: {', '.join(COMMANDS)}.")],
    inputs: Annotated[str, typer.Option("--inputs", help="Quoted glob of capture-set folders.")],
    out: RESUMABLE_OUT,
    param: Annotated[
        list[str] | None,
        typer.Option("--param", help="Command parameter KEY=VALUE (repeatable)."),
    ] = None,
    config: CONFIG_OPTION = None,
    scheduler: SchedulerOpt = None,
    workers: WorkersOpt = 2,
    retry_failed: Annotated[
        bool, typer.Option(help="Rerun inputs whose earlier run failed.")
    ] = True,
    as_json: JSON_SUMMARY = False,
) -> None:
    """Run COMMAND over many capture sets as Dask tasks: one results table, one log per input.

    Finished inputs are skipped on a rerun; an input that fails is recorded with the reason
    and the batch goes on (exit code 1 when any input failed, 2 on bad input).

    Example: phonestereo batch naive --inputs 'runs/phone*' --out runs/batch-naive
    """
    console = Console(stderr=True)
    try:
        cmd = get_command(command)
        params = parse_params(cmd, param)
        if config is not None:
            if "config" not in cmd.params:
                raise InputError(f"batch {command} does not run a flow: --config is for learn")
            from phonestereo.flows.config_file import load_flow_config

            load_flow_config(config)  # refuse a bad file before any task starts
            params["config"] = str(config.resolve())
        folders = expand_inputs(inputs)
        if scheduler is not None:
            check_address(scheduler)
        with dask_client(scheduler, workers) as client, _bar(console, command, as_json) as bar:
            result = run_batch(
                command,
                folders,
                out,
                params,
                client=client,
                retry_failed=retry_failed,
                progress=track(bar, command, field="key", total=len(folders)),
            )
    except InputError as exc:
        raise error_exit(exc) from exc
    summary: dict[str, Any] = {
        "command": command,
        "inputs": len(result.rows),
        "ok": result.n_ok,
        "failed": result.n_failed,
        "run_now": result.n_run,
        "seconds": round(result.seconds, 3),
        "files": result.files,
        "failures": [
            {"input": r["input"], "reason": r["reason"]} for r in result.rows if r["reason"]
        ],
    }
    if as_json:
        typer.echo(json.dumps(summary, indent=1))
    else:
        table = Table(title=f"batch {command} → {out}")
        for col in ("input", "status", "seconds", "reason"):
            table.add_column(col)
        for r in result.rows:
            table.add_row(r["input"], r["status"], f"{r['seconds']:.2f}", r["reason"][:80])
        Console().print(table)
        typer.echo(
            f"{result.n_ok}/{len(result.rows)} inputs ok ({result.n_run} run now); "
            f"table: {', '.join(result.files.values())}"
        )
    if result.n_failed:
        raise typer.Exit(1)


@app.command()
def study(
    module: Annotated[str, typer.Option("--module", help="Module preset name or JSON file.")],
    tolerances: Annotated[
        Path, typer.Option("--tolerances", help="Tolerances file (JSON, or YAML with PyYAML).")
    ],
    samples: Annotated[int, typer.Option("--samples", help="Number of Monte Carlo samples.")],
    out: RESUMABLE_OUT,
    seed: Annotated[int, typer.Option("--seed", help="Study seed (reproducible).")] = 0,
    bench: Annotated[
        str, typer.Option("--bench", help="Per-sample bench: analytic | flow (not yet).")
    ] = "analytic",
    quick: Annotated[
        bool,
        flag(
            "--quick",
            "Smaller bench (analytic: 3 distances, a 5x4 point grid; flow: 5 captures).",
        ),
    ] = False,
    metric: Annotated[
        str, typer.Option("--metric", help=f"Ranked metric: {' | '.join(METRICS)}.")
    ] = "median_rel_err",
    independent_phones: Annotated[
        bool,
        flag(
            "--independent-phones",
            "A new simulated phone (factory noise, hand shake) per sample; default: one "
            "phone for all samples (common random numbers: the spread is the tolerances').",
        ),
    ] = False,
    scheduler: SchedulerOpt = None,
    workers: WorkersOpt = 2,
    as_json: JSON_SUMMARY = False,
) -> None:
    """Sample module tolerances, run the bench per sample, rank the tolerances by their effect
    on the depth error: per-sample table, sensitivity table and a tornado figure in OUT.

    Example: phonestereo study --module folded-x3 --tolerances tol.json --samples 200
    --out runs/study
    """
    console = Console(stderr=True)
    try:
        spec = load_module(module)
        tol = load_tolerances(tolerances, spec)
        get_bench(bench)
        cfg = StudyConfig(
            samples,
            seed,
            bench,
            _quick_config(bench) if quick else None,
            metric,
            common_phone=not independent_phones,
        )
        if scheduler is not None:
            check_address(scheduler)
        with dask_client(scheduler, workers) as client, _bar(console, "study", as_json) as bar:
            result = run_study(
                spec,
                tol,
                out,
                cfg,
                client=client,
                progress=track(bar, "study", field="key", total=samples),
            )
    except InputError as exc:
        raise error_exit(exc) from exc
    if as_json:
        typer.echo((out / "sensitivity.json").read_text())
        return
    table = Table(title=f"tolerance study of {spec.name}: {metric} per +1σ ({result.n_ok} samples)")
    for col in ("rank", "parameter", "Δ per +1σ (pp)", "share of var.", "Spearman ρ"):
        table.add_column(col, no_wrap=True)
    for s in result.sensitivities:
        table.add_row(
            str(s.rank),
            s.parameter,
            f"{100 * s.coefficient:+.2f}",
            f"{100 * s.share_of_variance:.1f} %",
            f"{s.spearman_rho:+.2f}",
        )
    Console().print(table)
    typer.echo(
        f"mean {metric} {100 * result.metric_mean:.1f} %, R² {result.r_squared:.2f}, "
        f"{result.n_failed} failed sample(s), {result.n_run} run now; files in {out}"
    )


def _quick_config(bench: str) -> Any:
    """The smaller bench of ``--quick``."""
    if bench == "flow":
        from phonestereo.evaluation.flow_bench import FlowBenchConfig

        return FlowBenchConfig.quick()
    return AnalyticBenchConfig.quick()
