"""``phonestereo depth`` and ``phonestereo evaluate``: the application phase and its scoring."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeElapsedColumn
from rich.table import Table

from phonestereo.cli.app import app
from phonestereo.cli.flow_options import CONFIG_OPTION
from phonestereo.cli.outputs import require_output_file
from phonestereo.cli.widgets import error_exit, flag, json_option
from phonestereo.errors import InputError, PhysicsError, StoreError
from phonestereo.evaluation.analyses._common import json_clean as clean
from phonestereo.evaluation.bench import run_bench
from phonestereo.features.match_input import parse_roi
from phonestereo.flows import application
from phonestereo.flows.config_file import load_flow_config
from phonestereo.flows.corrector import Corrector
from phonestereo.flows.learning import stack_corrections, store_context
from phonestereo.flows.roi_disparity import reference_rectification
from phonestereo.io import load_calibration, load_capture_set, read_gray
from phonestereo.learning.store_open import open_for_reading
from phonestereo.learning.store_radial import radial_fits


def _bar(label: str, console: Console, disable: bool) -> Progress:
    cols = (TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn())
    return Progress(*cols, console=console, transient=True, disable=disable)


@app.command("depth")
def depth(
    capture_set: Annotated[Path, typer.Argument(help="Capture-set folder (manifest.json).")],
    calibration: Annotated[Path, typer.Option("--calibration", help="calibration.json.")],
    store: Annotated[Path, typer.Option("--store", help="Fix store learned by `learn`.")],
    capture: Annotated[
        str | None, typer.Option("--capture", help="One capture id (default: all but faces).")
    ] = None,
    roi: Annotated[
        str | None, typer.Option("--roi", help="x,y,w,h in raw wide pixels (default: manifest).")
    ] = None,
    config: CONFIG_OPTION = None,
    as_json: Annotated[bool, json_option("Print the results as JSON.")] = False,
) -> None:
    """Metric depth of the ROI of each capture, with its σ (thesis Fig. 4-2).

    Gates (warm-up, fixed focus, orientation, enough learned observations) → features in the
    ROI matched into the tele → focus fix of the refocus stack → majority disparity, ROI
    expansion, majority again → W-T scale → the learned correction from STORE → depth. A
    capture that does not pass says which gate or block stopped it and why — never a silent
    number. Only the store's observations learned under this calibration, lens model,
    rectification mode and flow config (--config) are applied; a store learned under another
    is refused, naming the field that differs. The store is only read. Exit code 0 when every
    capture got a depth, 1 when some did not, 2 on bad input.

    Example: phonestereo depth runs/verification --calibration calibration.json --store
    fixes.sqlite --json
    """
    console = Console(stderr=True, soft_wrap=True)
    try:
        cfg = load_flow_config(config)
        cs = load_capture_set(capture_set)
        cal = load_calibration(calibration)
        if not Path(store).is_file():
            raise InputError(
                f"fix store {store} does not exist; learn one with `phonestereo learn "
                "CAPTURE_SET --calibration FILE --store FILE` first"
            )
        with open_for_reading(store) as fs:
            choice = fs.context_for_applying(store_context(cfg, cal.rig))
            obs = fs.observations(context_id=-1 if choice.id is None else choice.id)
            radial = radial_fits(fs, -1 if choice.id is None else choice.id)
        if choice.warning:
            console.print(f"[yellow]warning:[/yellow] {escape(choice.warning)}")
        corrector = (
            Corrector.for_calibration(obs, cfg, cal, radial_fits=radial)
            if len(obs) else None
        )
        entries = [c for c in cs.captures() if c.kind != "face"]
        if capture is not None:
            entries = [cs.get(capture)]
        if not entries:
            raise InputError(f"{cs.root} has no non-face captures to measure; pass --capture ID")
        box = None
        if roi is not None:
            box = parse_roi(roi, cal.rig.wide.size)
        focus = stack_corrections(cfg, cs, entries, cal)
        ref = reference_rectification(cal.rig, cfg.mode)
        results = []
        with _bar("depth", console, as_json) as bar:
            task = bar.add_task("depth", total=len(entries))
            for e in entries:
                w, t = (read_gray(p) for p in cs.image_paths(e.id))
                inputs = application.ApplicationInputs(
                    cal, e, w, t, corrector, box, focus.get(e.id), ref
                )
                results.append(application.run(cfg, inputs))
                bar.advance(task)
    except (InputError, StoreError, PhysicsError) as exc:
        raise error_exit(exc) from exc
    if as_json:
        doc = {
            "results": [r.to_dict() for r in results],
            "config": cfg.to_dict(),
            "store": {"path": str(store), "context_id": choice.id, "warning": choice.warning},
        }
        typer.echo(json.dumps(doc, indent=1))
    else:
        table = Table(title=f"depth of the ROI ({cs.root})")
        for col in ("capture", "depth (m)", "σ (m)", "d (px)", "correction (px)", "gate / why"):
            table.add_column(col)
        for r in results:
            if r.ok:
                table.add_row(
                    r.capture_id,
                    f"{r.depth_m:.4f}",
                    f"{r.sigma_m:.4f}",
                    f"{r.disparity_fixed_px:.3f}",
                    f"{r.correction_px:+.3f}",
                    "",
                )
            else:
                table.add_row(r.capture_id, "–", "–", "–", "–", f"{r.gate}: {r.reason}")
        Console().print(table)
    if not all(r.ok for r in results):
        raise typer.Exit(1)


def print_bench(res: dict[str, Any], title: str) -> None:
    """The stage table of a bench result (per distance; median / p90)."""
    table = Table(title=title)
    stages = (("naive", "naive"), ("measured", "fixes only"), ("full", "full flow"),
              ("cramer_rao_floor", "matching σ"))
    table.add_column("distance")
    for _, label in stages:
        table.add_column(f"{label}\nmedian/p90 %", justify="right")

    def pc(v: float | None) -> str:  # ∞: a naive depth at or beyond infinity (unbounded)
        return "∞" if v == float("inf") else "–" if v is None or v != v else f"{100 * v:.2f}"

    def cell(s: dict[str, Any] | None) -> str:
        if not s or s.get("median_rel_err") is None:
            return "–"
        return f"{pc(s['median_rel_err'])} / {pc(s['p90_rel_err'])}"

    for row in res["per_distance"]:
        table.add_row(f"{row['distance_m']:.1f} m", *(cell(row.get(k)) for k, _ in stages))
    table.add_row("all", *(cell(res["stages"][k]) for k, _ in stages))
    Console().print(table)
    _print_rows(
        "ablation: each fix switched the other way in turn",
        ("change", "median", "p90", "gated"),
        [(r["without"], *_errors(r), str(r["gated"])) for r in res.get("ablation") or ()],
    )
    _print_rows(
        "learned-correction lookups (thesis Figure 3-31, plus the smooth field)",
        ("lookup", "median", "p90", "within σ"),
        [(r["lookup"], *_errors(r), _pct(r["within_sigma"], 0)) for r in res.get("lookups") or ()],
    )
    within = res["stages"].get("within_sigma")
    if within is not None:
        Console().print(f"|Z − Z_true| ≤ σ for {100 * within:.0f} % of the verification captures")


@app.command("evaluate")
def evaluate(
    capture_set: Annotated[Path, typer.Argument(help="Simulated set with ground_truth.json.")],
    ablations: Annotated[bool, typer.Option(help="Also switch each fix off in turn.")] = False,
    lookups: Annotated[
        bool, typer.Option(help="Also compare the lookup strategies of Figure 3-31.")
    ] = False,
    report: Annotated[Path | None, typer.Option(help="Write an HTML report here.")] = None,
    store: Annotated[
        Path | None,
        typer.Option(
            "--store",
            help="Learn into this fix store (refused when it was learned under another "
            "calibration or --config) and apply its observations. Default: in memory.",
        ),
    ] = None,
    config: CONFIG_OPTION = None,
    as_json: Annotated[bool, json_option("Print the scores as JSON.")] = False,
    force: Annotated[bool, flag("--force", "Overwrite an existing --report file.")] = False,
) -> None:
    """Score every stage of the flows against ground truth (the thesis bench, docs/architecture.md).

    Learns from the set's face captures, applies on its verification captures, and prints the
    relative depth error per distance for naive Z = f·B/d, the fixes without the learned
    correction, the full flow and the Cramér–Rao floor, plus how often |Z − Z_true| ≤ σ.
    """
    console = Console(stderr=True, soft_wrap=True)
    try:
        if report is not None:
            require_output_file(report, force=force, flag="--report", suffixes=(".html",))
        cfg = load_flow_config(config)
        with _bar("evaluate", console, as_json) as bar:
            task = bar.add_task("evaluate", total=None)

            def progress(stage: str, done: int, total: int) -> None:
                bar.update(task, completed=done, total=total, description=stage)

            res = run_bench(
                capture_set,
                cfg,
                ablations=ablations,
                lookups=lookups,
                store_path=store,
                progress=progress,
            )
    except (InputError, StoreError, PhysicsError) as exc:
        raise error_exit(exc) from exc
    if report is not None:
        from phonestereo.report.bench_report import write_report

        write_report(res, report, title=f"phonestereo evaluate: {capture_set}")
    if as_json:
        typer.echo(json.dumps(clean(res)))
        return
    print_bench(res, f"relative depth error, {capture_set}")
    if report is not None:
        Console().print(f"report: {report}")


__all__ = ["clean", "depth", "evaluate", "print_bench"]


def _pct(fraction: float | None, digits: int = 2) -> str:
    """A fraction as a percentage for a table cell; "–" where there is none."""
    return "–" if fraction is None else f"{100 * fraction:.{digits}f} %"


def _errors(row: dict[str, Any]) -> tuple[str, str]:
    """The median and p90 relative-error cells of an ablation or lookup row."""
    return _pct(row["median_rel_err"]), _pct(row["p90_rel_err"])


def _print_rows(title: str, columns: tuple[str, ...], rows: list[tuple[str, ...]]) -> None:
    """A right-aligned Rich table of ``rows`` under ``columns``; nothing when there are none."""
    if not rows:
        return
    table = Table(title=title)
    for col in columns:
        table.add_column(col, justify="right")
    for row in rows:
        table.add_row(*row)
    Console().print(table)
