"""``phonestereo simulate`` and ``phonestereo module``: the virtual module from the command line.

Each command is a thin wrapper over :mod:`phonestereo.sim` (docs/architecture.md):
``simulate`` plans a
scenario and writes its capture set (images, manifest.json, calibration.json,
ground_truth.json); ``module list`` / ``module show`` print the presets and their schema.
"""

from __future__ import annotations

import json
import time
from collections import Counter
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.table import Table

from phonestereo.cli.app import app
from phonestereo.cli.outputs import prepare_capture_set_folder, require_output_file
from phonestereo.cli.widgets import JSON_SUMMARY, error_exit, flag, json_option, progress_bar
from phonestereo.errors import InputError
from phonestereo.sim.module import EFFECT_NAMES, ModuleSpec, list_presets, load_module
from phonestereo.sim.scenarios import SCENARIOS, plan_scenario
from phonestereo.sim.writer import write_capture_set

module_app = typer.Typer(
    help="Virtual module presets: list them, or show one (or your JSON) with its schema.",
    no_args_is_help=True,
)
app.add_typer(module_app, name="module")

_SCENARIO_HELP = "One of: " + ", ".join(f"{n} ({s.summary})" for n, s in SCENARIOS.items())


def _load(module: str, hint: str = "--module") -> ModuleSpec:
    try:
        return load_module(module)
    except InputError as err:
        raise typer.BadParameter(str(err), param_hint=hint) from err


def _summary(spec: ModuleSpec, plan: Any, result: Any, seconds: float) -> dict[str, Any]:
    kinds = Counter(pc.state.conditions.kind for pc in plan.captures)
    groups = {pc.state.conditions.focus_group for pc in plan.captures} - {None}
    return {
        "scenario": plan.scenario,
        "module": spec.name,
        "seed": plan.seed,
        "out": str(result.folder),
        "captures": result.captures,
        "kinds": dict(sorted(kinds.items())),
        "focus_groups": len(groups),
        "images_rendered": 2 * result.captures if result.rendered else 0,
        "wide_size": list(spec.wide.size),
        "tele_size": list(spec.tele.size),
        "time_span_s": [
            plan.captures[0].state.conditions.time_s,
            plan.captures[-1].state.conditions.time_s,
        ],
        "effects_off": [n for n in EFFECT_NAMES if not getattr(spec.effects, n)],
        "plan_notes": list(plan.notes),
        "seconds": round(seconds, 2),
    }


@app.command("simulate")
def simulate_command(
    scenario: Annotated[str, typer.Argument(help=_SCENARIO_HELP, show_default=False)],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder of the capture set.")],
    module: Annotated[
        str, typer.Option("--module", "-m", help="Preset name or path of a module JSON file.")
    ] = "folded-x3",
    seed: Annotated[int, typer.Option("--seed", help="Random seed (same seed, same bytes).")] = 0,
    quick: Annotated[bool, flag("--quick", "A small version (for tests).")] = False,
    no_images: Annotated[
        bool, flag("--no-images", "Write the JSON files only (no rendering).")
    ] = False,
    export: Annotated[
        list[str] | None,
        typer.Option(
            "--export",
            help="Also write OUT/android or OUT/apple: the set as a phone dump for "
            "`phonestereo import` (repeatable).",
        ),
    ] = None,
    as_json: JSON_SUMMARY = False,
    force: Annotated[
        bool, flag("--force", "Replace an earlier capture set in OUT (its files go first).")
    ] = False,
) -> None:
    """Simulate a scenario of the virtual module and write its capture set.

    Writes OUT/images/*.png, OUT/manifest.json, OUT/calibration.json (the imperfect factory
    calibration) and OUT/ground_truth.json (for evaluation only). OUT must be new or empty;
    an earlier capture set there is replaced only with --force.

    Example: phonestereo simulate verification --module folded-x3 --out runs/ver --seed 1

    With --export android (or apple) it also writes OUT/android (OUT/apple): the same captures
    as the dump a phone capture app writes, for `phonestereo import android OUT/android`.
    """
    if scenario not in SCENARIOS:
        raise typer.BadParameter(
            f"unknown scenario {scenario!r}; choose one of {list(SCENARIOS)}",
            param_hint="SCENARIO",
        )
    exports = list(dict.fromkeys(export or []))
    for name in exports:
        if name not in ("android", "apple"):
            raise typer.BadParameter(f"unknown export {name!r}; choose android or apple",
                                     param_hint="--export")
    spec = _load(module)
    start = time.perf_counter()
    try:
        plan = plan_scenario(scenario, spec, seed, quick=quick)
    except InputError as err:
        raise typer.BadParameter(str(err)) from err
    try:
        prepare_capture_set_folder(out, force=force)
    except InputError as err:
        raise typer.BadParameter(str(err), param_hint="--out") from err
    console = Console(stderr=True)
    bar_label = "[bold]{task.description}"
    with progress_bar(bar_label, console, field="capture", disable=as_json, transient=False) as bar:
        task = bar.add_task(f"{scenario} ({spec.name})", total=len(plan.captures), capture="")
        try:
            result = write_capture_set(
                out,
                plan,
                render=not no_images,
                progress=lambda done, total, cid: bar.update(task, completed=done, capture=cid),
            )
        except InputError as err:
            raise typer.BadParameter(str(err), param_hint="--out") from err
    for name in exports:
        _export(name, out, plan)
    summary = _summary(spec, plan, result, time.perf_counter() - start)
    if exports:
        summary["exports"] = [str(out / name) for name in exports]
    if as_json:
        typer.echo(json.dumps(summary, indent=1))
        return
    table = Table(title=f"simulated '{scenario}' → {result.folder}", show_header=False)
    for key, value in summary.items():
        table.add_row(key, str(value))
    Console().print(table)


def _export(name: str, out: Path, plan: Any) -> None:
    """Write OUT/<name>: the simulated set as an Android or Apple dump."""
    from phonestereo.sim.export_android import write_android_dump
    from phonestereo.sim.export_apple import write_apple_dump
    from phonestereo.sim.writer import IMAGE_DIR

    write = write_android_dump if name == "android" else write_apple_dump
    try:
        write(out / name, plan.calibration, plan.manifest(IMAGE_DIR), out)
    except InputError as err:
        raise typer.BadParameter(str(err), param_hint="--export") from err


@module_app.command("list")
def module_list(
    as_json: Annotated[bool, json_option("Print as JSON.")] = False,
) -> None:
    """List the module presets."""
    rows = [(name, load_module(name).description) for name in list_presets()]
    if as_json:
        typer.echo(json.dumps([{"name": n, "description": d} for n, d in rows], indent=1))
        return
    table = Table("preset", "description")
    for row in rows:
        table.add_row(*row)
    Console().print(table)


@module_app.command("show")
def module_show(
    module: Annotated[str, typer.Argument(help="Preset name or path of a module JSON file.")],
    as_json: Annotated[bool, json_option("Print the full spec (the module JSON schema).")] = False,
) -> None:
    """Show a module preset (or your module JSON): optics, rig and effect magnitudes.

    `--json` prints the complete spec; edit it and pass the file to `simulate --module FILE`.
    """
    spec = _load(module, "MODULE")
    if as_json:
        typer.echo(spec.to_json(), nl=False)
        return
    table = Table("parameter", "wide", "tele", title=f"module '{spec.name}'")
    w, t = spec.wide, spec.tele
    table.add_row("size (px)", str(w.size), str(t.size))
    table.add_row("focal length (mm)", f"{w.focal_length_mm}", f"{t.focal_length_mm}")
    table.add_row("f at infinity (px)", f"{w.focal_px_infinity:.1f}", f"{t.focal_px_infinity:.1f}")
    table.add_row("f-number", f"{w.f_number}", f"{t.f_number}")
    table.add_row("lens", w.lens.model, t.lens.model)
    table.add_row("heating drift (px)", str(w.heating_drift_px), str(t.heating_drift_px))
    table.add_row("sag (px per g)", f"{w.sag_px_per_g}", f"{t.sag_px_per_g}")
    table.add_row("focus noise (rel.)", f"{w.focus_noise_rel:g}", f"{t.focus_noise_rel:g}")
    Console().print(table)
    ex = spec.extrinsics
    on = [n for n in EFFECT_NAMES if getattr(spec.effects, n)]
    Console().print(
        f"tele centre {list(ex.tele_center_mm)} mm, rotation {list(ex.rotation_deg)} deg; "
        f"calibration at {spec.calibration.focus_distance_m} m focus; effects on: {', '.join(on)}"
    )


@module_app.command("random")
def module_random(
    seed: Annotated[int, typer.Option("--seed", help="Seed (>= 0): same seed, same module.")],
    ranges: Annotated[
        Path | None,
        typer.Option("--ranges", help="JSON of ranges overriding the shipped ones (any subset)."),
    ] = None,
    out: Annotated[
        Path | None, typer.Option("--out", "-o", help="Write the module JSON here.")
    ] = None,
    as_json: Annotated[bool, json_option("Print the module JSON (default when no --out).")] = False,
    force: Annotated[bool, flag("--force", "Overwrite an existing --out file.")] = False,
) -> None:
    """Draw a physically consistent random module from documented ranges.

    The ranges (focal ratio 2-6, baseline 8-25 mm in any in-plane direction, t_z 0-6 mm,
    rotations ±0.6°, 2000x1500 to 4000x3000 px, pitch 0.8-2.8 µm, heating drift 0-7 px, ...)
    are in docs/module-random.md; `--ranges FILE` overrides any of them. Pass the written
    file to `simulate --module FILE`, `demo --module FILE`.

    Example: phonestereo module random --seed 1000 --out runs/random-1000.json
    """
    from phonestereo.sim.random_module import load_ranges, random_module

    try:
        if out is not None:
            require_output_file(out, force=force, suffixes=(".json",))
        spec = random_module(seed, load_ranges(ranges))
    except InputError as err:
        raise error_exit(err) from err
    text = spec.to_json()
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    if as_json or out is None:
        typer.echo(text, nl=False)
    else:
        Console().print(f"{spec.description}\nwritten to {out}", soft_wrap=True)
