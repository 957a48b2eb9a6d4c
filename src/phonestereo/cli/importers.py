"""``phonestereo import android|apple|exif``: real phones in (docs/import-*.md).

Each command is a thin wrapper over :mod:`phonestereo.io.importers`; the capture set is
written all-or-nothing and the summary says what was converted and how.
"""

from __future__ import annotations

import importlib
import json
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table

from phonestereo.cli.app import app
from phonestereo.cli.outputs import require_writable
from phonestereo.cli.widgets import JSON_SUMMARY, error_exit
from phonestereo.errors import InputError

import_app = typer.Typer(
    help="Import a phone's captures and factory calibration: an Android Camera2 dump, an "
    "Apple AVFoundation dump, or plain EXIF JPEGs (docs/import-*.md).",
    no_args_is_help=True,
)
app.add_typer(import_app, name="import")

_OUT = typer.Option("--out", "-o", help="New capture-set folder (must not exist or be empty).")
_DUMP = typer.Argument(help="Dump folder: session.json, captures/*.json, images.")


def _report(result: Any, as_json: bool) -> None:
    from phonestereo.cli.io_commands import calibration_summary
    from phonestereo.io import load_calibration

    summary = result.to_dict()
    summary["calibration"] = calibration_summary(load_calibration(result.out / "calibration.json"))
    if as_json:
        typer.echo(json.dumps(summary, indent=1))
        return
    table = Table(title=f"imported {result.captures} captures → {result.out}", show_header=False)
    for key in ("cameras", "lens_fit_px"):
        table.add_row(key, escape(str(summary[key])))
    for key, value in summary["calibration"].items():
        table.add_row(key, escape(str(value)))
    Console().print(table)
    for note in result.notes:
        Console().print(f"note: {escape(note)}")


def _run(fn: Any, *args: Any, **kwargs: Any) -> Any:
    try:
        return fn(*args, **kwargs)
    except InputError as exc:
        raise error_exit(exc) from exc


def _dump_command(platform: str, doc: str) -> None:
    """Register ``import PLATFORM DUMP --out OUT``: the dump importer
    ``phonestereo.io.importers.PLATFORM.import_PLATFORM`` with ``doc`` as its help."""

    def command(
        dump: Annotated[Path, _DUMP],
        out: Annotated[Path, _OUT],
        as_json: JSON_SUMMARY = False,
    ) -> None:
        module = importlib.import_module(f"phonestereo.io.importers.{platform}")
        _run(require_writable, out)
        _report(_run(getattr(module, f"import_{platform}"), dump, out), as_json)

    command.__name__ = f"import_{platform}_command"
    command.__doc__ = doc
    import_app.command(platform)(command)


_dump_command(
    "android",
    """Import an Android Camera2 dump (docs/import-android.md).

    Converts each physical camera's CameraCharacteristics (intrinsics, distortion, pose) into
    calibration.json and each capture's CaptureResult + accelerometer into manifest.json.

    Example: phonestereo import android phone_dump --out runs/phone_set
    """,
)
_dump_command(
    "apple",
    """Import an Apple AVFoundation dump (docs/import-apple.md).

    Converts each camera's AVCameraCalibrationData into calibration.json (the distortion
    lookup table fitted by the radial-odd-centred lens, residual reported) and each capture into
    manifest.json.

    Example: phonestereo import apple iphone_dump --out runs/iphone_set
    """,
)


@import_app.command("exif")
def import_exif_command(
    wide_glob: Annotated[str, typer.Argument(help="Quoted glob of the wide camera's JPEGs.")],
    tele_glob: Annotated[str, typer.Argument(help="Quoted glob of the tele camera's JPEGs.")],
    calibration: Annotated[
        Path, typer.Option("--calibration", help="The rig's calibration.json (EXIF has none).")
    ],
    out: Annotated[Path, _OUT],
    kind: Annotated[
        str, typer.Option("--kind", help="face, verification, scene or calibration (not in EXIF).")
    ],
    focus_mode: Annotated[
        str, typer.Option("--focus-mode", help="manual or auto: how you shot (not in EXIF).")
    ],
    time_offset_s: Annotated[
        float,
        typer.Option(
            "--time-offset-s",
            help="Seconds the camera app had run before the first pair (not in EXIF).",
        ),
    ],
    orientation: Annotated[
        str | None,
        typer.Option(
            "--orientation", help="Orientation bucket for images without EXIF Orientation."
        ),
    ] = None,
    max_gap_s: Annotated[
        float, typer.Option("--max-gap-s", help="Largest wide/tele capture-time gap of a pair.")
    ] = 1.0,
    as_json: JSON_SUMMARY = False,
) -> None:
    """Import plain JPEGs, pairing wide and tele by EXIF capture time (docs/import-exif.md).

    Reads DateTimeOriginal/SubSecTimeOriginal, FocalLength, Orientation and SubjectDistance;
    what EXIF lacks is a required option, never a guess.

    Example: phonestereo import exif 'shots/wide_*.jpg' 'shots/tele_*.jpg'
    --calibration calibration.json --kind scene --focus-mode auto --time-offset-s 0 --out set
    """
    from phonestereo.io.importers.exif import import_exif

    if kind not in ("face", "verification", "scene", "calibration"):
        raise typer.BadParameter(
            "must be face, verification, scene or calibration", param_hint="--kind"
        )
    if focus_mode not in ("manual", "auto"):
        raise typer.BadParameter("must be manual or auto", param_hint="--focus-mode")
    _run(require_writable, out)
    result = _run(import_exif, wide_glob, tele_glob, calibration, out, kind=kind,
                  focus_mode=focus_mode, time_offset_s=time_offset_s, orientation=orientation,
                  max_gap_s=max_gap_s)
    _report(result, as_json)
