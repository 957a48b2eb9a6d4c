"""``phonestereo bench modules``: the demo flow on many random modules (issue #18 item 7).

A thin wrapper over :func:`~phonestereo.evaluation.module_bench.run_module_bench` on a local
Dask cluster (``--workers``) or a running scheduler (``--scheduler``), like ``batch``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from phonestereo.cli.app import app
from phonestereo.cli.scaleout import SchedulerOpt, WorkersOpt, _bar
from phonestereo.cli.widgets import RESUMABLE_OUT, error_exit, flag, json_option, track
from phonestereo.errors import InputError
from phonestereo.evaluation.module_bench import parse_seeds, run_module_bench
from phonestereo.evaluation.runner import check_address, dask_client
from phonestereo.sim.random_module import load_ranges

bench_app = typer.Typer(
    help="Benches over many simulated modules (`bench modules --seeds 1000-1019`).",
    no_args_is_help=True,
)
app.add_typer(bench_app, name="bench")


def _pct(v: float | None) -> str:
    return "-" if v is None else f"{100 * v:.2f} %"


@bench_app.command("modules")
def bench_modules(
    seeds: Annotated[str, typer.Option("--seeds", help="Module seeds: A-B, N or a list.")],
    out: RESUMABLE_OUT = Path("bench_modules"),
    ranges: Annotated[
        Path | None, typer.Option("--ranges", help="JSON overriding the random-module ranges.")
    ] = None,
    keep_images: Annotated[
        bool, flag("--keep-images", "Keep each module's rendered images.")
    ] = False,
    scheduler: SchedulerOpt = None,
    workers: WorkersOpt = 2,
    retry_failed: Annotated[
        bool, typer.Option(help="Rerun modules whose earlier run failed.")
    ] = True,
    as_json: Annotated[bool, json_option("Print the distribution as JSON.")] = False,
) -> None:
    """Run the demo flow on random modules: one row per module, the distribution, a figure.

    For each seed, module `random-<seed>` (`phonestereo module random --seed N`) is drawn, the
    demo's quick thesis bench is simulated on it (planned for the module: faces and charts
    where both cameras see them), learned, applied and scored. OUT/modules.csv has one row
    per module (median, p90, within-σ, captures measured/gated with the reasons),
    OUT/distribution.json the quantiles and the issue #18 acceptance counts, OUT/modules.png
    the figure. About 2-10 min per module on one core (12 MP modules are the slow ones).

    Example: phonestereo bench modules --seeds 1000-1019 --out runs/modules
    """
    console = Console(stderr=True)
    try:
        seed_list = parse_seeds(seeds)
        load_ranges(ranges)  # checked before the cluster starts
        if scheduler is not None:
            check_address(scheduler)
        with dask_client(scheduler, workers) as client, _bar(console, "modules", as_json) as bar:
            result = run_module_bench(
                seed_list, out, ranges_path=ranges, keep_images=keep_images, client=client,
                retry_failed=retry_failed,
                progress=track(bar, "modules", field="key", total=len(seed_list)),
            )
    except InputError as exc:
        raise error_exit(exc) from exc
    if as_json:
        typer.echo(json.dumps({**result.distribution, "files": result.files}, indent=1))
    else:
        table = Table(title=f"bench modules → {out}")
        for col in ("seed", "ratio", "size", "median", "p90", "within σ", "measured", "reason"):
            table.add_column(col)
        for r in result.rows:
            if r["status"] != "ok":
                table.add_row(str(r["seed"]), "", "", "", "", "", "", r["reason"][:60])
                continue
            table.add_row(
                str(r["seed"]), f"x{r['focal_ratio']:.2f}", r["size"], _pct(r["median_rel_err"]),
                _pct(r["p90_rel_err"]), _pct(r["within_sigma"]),
                f"{r['measured']}/{r['captures']}", "",
            )
        Console().print(table)
        acc = result.distribution["acceptance"]
        typer.echo(
            f"of {acc['of_modules']} modules: median <= 1 % on {acc['median_le_1pct']}, p90 <= "
            f"2.5 % on {acc['p90_le_2p5pct']}, within-σ 50-90 % on "
            f"{acc['within_sigma_50_90pct']}; {acc['captures_over_4_sigma']} captures beyond 4σ; "
            f"{_pct(acc['measured_fraction'])} measured; files: {', '.join(result.files.values())}"
        )
    if any(r["status"] != "ok" for r in result.rows):
        raise typer.Exit(1)
