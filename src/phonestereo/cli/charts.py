"""``phonestereo chart``: write a printable verification or face chart at physical size."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer

from phonestereo.charts.base import Chart
from phonestereo.charts.export import M_PER_INCH, export_pdf, export_png
from phonestereo.charts.faces import FaceChart
from phonestereo.charts.verification import VerificationChart
from phonestereo.cli.app import app
from phonestereo.cli.outputs import require_output_file
from phonestereo.cli.widgets import flag, json_option
from phonestereo.errors import InputError


class ChartKind(StrEnum):
    """The printable charts."""

    verification = "verification"
    faces = "faces"


_KIND_HELP = (
    "verification: 40 × 28-square chessboard with four circle pairs (thesis §1.2.2); "
    "faces: 4 × 2 real portraits, every IPD 63 mm (thesis §2.2)."
)


@app.command("chart")
def chart_command(
    kind: Annotated[ChartKind, typer.Argument(help=_KIND_HELP, show_default=False)],
    out: Annotated[
        Path,
        typer.Option("--out", "-o", help="Output file: .pdf (with scale bar) or .png."),
    ],
    square_mm: Annotated[
        float | None,
        typer.Option("--square-mm", help="Square side in mm (verification only; default 25)."),
    ] = None,
    dpi: Annotated[
        float,
        typer.Option("--dpi", help="Raster resolution: the face chart in a PDF, or a PNG."),
    ] = 300.0,
    as_json: Annotated[bool, json_option("Print the sizes as JSON.")] = False,
    force: Annotated[bool, flag("--force", "Overwrite an existing --out file.")] = False,
) -> None:
    """Write a printable chart at physical size (PDF: chart + scale-bar strip; print at 100 %).

    Example: phonestereo chart verification --out verification.pdf --square-mm 25
    """
    try:
        require_output_file(out, force=force, suffixes=(".pdf", ".png"))
        chart: Chart
        if kind is ChartKind.verification:
            chart = VerificationChart(square_m=(square_mm or 25.0) / 1000.0)
        else:
            if square_mm is not None:
                raise InputError("--square-mm applies to the verification chart only")
            chart = FaceChart()
        suffix = out.suffix.lower()
        if suffix == ".pdf":
            info = export_pdf(chart, out, raster_dpi=dpi)
        elif suffix == ".png":
            info = export_png(chart, out, dpi / M_PER_INCH)
        else:
            raise InputError(f"--out must end in .pdf or .png, got {out.name!r}")
    except InputError as err:
        raise typer.BadParameter(str(err)) from err
    if as_json:
        typer.echo(json.dumps(info.to_dict(), indent=1))
    else:
        w, h = info.page_size_m
        typer.echo(f"wrote {info.path} ({w * 1000:.0f} × {h * 1000:.0f} mm); print at 100 %")
