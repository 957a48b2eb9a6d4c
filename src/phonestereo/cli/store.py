"""``phonestereo store stats|export|vacuum FILE``: inspect a fix store (docs/fix-store.md).

Thin wrappers over :class:`phonestereo.learning.store.FixStore`. A store the user can write is
opened normally (an older schema is migrated, with a ``.v<N>.bak`` copy kept); one they cannot
write is opened read-only. Errors (damaged file, bad path) print the store's message and exit 2.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer

from phonestereo.cli.app import app
from phonestereo.cli.outputs import require_output_file
from phonestereo.cli.widgets import error_exit, flag, json_option
from phonestereo.errors import InputError, StoreError
from phonestereo.learning.store import FixStore, StoreStats
from phonestereo.learning.store_open import open_for_reading, refuse_empty

store_app = typer.Typer(
    help="The fix store of learned disparity corrections: stats, export, vacuum.",
    no_args_is_help=True,
)
app.add_typer(store_app, name="store")

_FILE = typer.Argument(help="Fix store file (SQLite).", show_default=False)


def _open(path: Path, write: bool = False) -> FixStore:
    """Open an existing store (never create one from an inspection command)."""
    if not path.exists():
        raise StoreError(f"the fix store '{path}' does not exist; check the path")
    if not write:
        return open_for_reading(path)  # refuses an empty file itself
    refuse_empty(path)
    return FixStore(path)


def _kb(n: int) -> str:
    return f"{n / 1024:.1f} kB"


def format_stats(s: StoreStats) -> str:
    """The human-readable summary printed by ``store stats``."""
    lines = [
        f"{s.path}: schema v{s.schema_version}, journal {s.journal_mode}, {_kb(s.size_bytes)}",
        f"  {s.n_captures} captures, {s.n_observations} observations",
    ]
    for o, b in s.by_orientation.items():
        lines.append(
            f"  orientation {o}: {int(b['n'])} observations, correction "
            f"{b['correction_mean_px']:+.3f} ± {b['correction_std_px']:.3f} px"
        )
    for title, counts in (("focus groups", s.by_focus_group), ("sources", s.by_source)):
        if counts:
            items = ", ".join(f"{k or '(none)'} ({v})" for k, v in sorted(counts.items()))
            lines.append(f"  {title}: {items}")
    units = {"depth_m": "m", "time_s": "s", "temperature_c": "°C", "d_measured_px": "px"}
    spans = [
        f"{col.rsplit('_', 1)[0]} {r[0]:.4g}–{r[1]:.4g} {unit}"
        for col, unit in units.items()
        if (r := s.ranges.get(col)) is not None
    ]
    if spans:
        lines.append("  " + ", ".join(spans))
    for c in s.contexts:
        if c["recorded"]:
            what = (
                f"calibration {c['calibration_sha256']}, lens {c['lens_model']}, "
                f"{c['rectification_mode']}, flow config {c['flow_config_sha256']}"
            )
        else:
            what = "not recorded (learned before schema v3)"
        lines.append(
            f"  context #{c['id']}: {what}; {c['n_sets']} set(s), {c['n_captures']} captures, "
            f"{c['n_observations']} observations"
        )
        for st in (x for x in s.sets if x["context_id"] == c["id"]):
            where = f" {st['folder']}" if st["folder"] else ""
            lines.append(
                f"    set {st['fingerprint']}{where}: {st['n_captures']} captures, "
                f"{st['n_observations']} observations"
            )
    return "\n".join(lines)


@store_app.command("stats")
def stats(
    file: Annotated[Path, _FILE],
    as_json: Annotated[bool, json_option("Print JSON.")] = False,
) -> None:
    """Counts per orientation bucket, focus group and source; value ranges; the contexts
    (calibration, lens model, rectification mode, flow config) and the capture sets learned
    under each; integrity. Never writes to a file that is not a fix store."""
    try:
        with _open(file) as st:
            s = st.stats()
            integrity = st.integrity()
    except (StoreError, InputError) as exc:
        raise error_exit(exc) from exc
    if as_json:
        typer.echo(json.dumps({**s.to_dict(), "integrity": integrity}, indent=1))
        return
    typer.echo(format_stats(s) + f"\n  integrity: {integrity}")


@store_app.command("export")
def export(
    file: Annotated[Path, _FILE],
    out: Annotated[
        Path, typer.Option("--out", "-o", help="Output .csv or .json.", show_default=False)
    ],
    force: Annotated[bool, flag("--force", "Overwrite an existing --out file.")] = False,
) -> None:
    """Write every learned observation to CSV or JSON."""
    try:
        require_output_file(out, force=force, suffixes=(".csv", ".json"))
        with _open(file) as st:
            n = st.export(out)
    except (StoreError, InputError) as exc:
        raise error_exit(exc) from exc
    typer.echo(f"wrote {n} observations to {out}")


@store_app.command("vacuum")
def vacuum(file: Annotated[Path, _FILE]) -> None:
    """Checkpoint the WAL and compact the file (waits for other writers, never loses data)."""
    try:
        with _open(file, write=True) as st:
            before, after = st.vacuum()
    except (StoreError, InputError) as exc:
        raise error_exit(exc) from exc
    typer.echo(f"vacuumed {file}: {_kb(before)} → {_kb(after)}")
