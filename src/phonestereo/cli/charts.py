"""``phonestereo chart``: write a printable verification or face chart at physical size."""

from __future__ import annotations

import json
import math
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


#: The largest raster written (pixels): 1 GB of 8-bit grey; 300 dpi needs ~0.1 G for the
#: verification chart at its default size.
MAX_RASTER_PX = 1_000_000_000

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
        if not (math.isfinite(dpi) and dpi > 0):
            raise InputError(f"--dpi must be a positive resolution in dots per inch (e.g. 300), "
                             f"got {dpi}")
        chart: Chart
        if kind is ChartKind.verification:
            if square_mm is not None and not (math.isfinite(square_mm) and square_mm > 0):
                raise InputError(f"--square-mm must be a positive side in millimetres (e.g. 25), "
                                 f"got {square_mm}")
            chart = VerificationChart(square_m=(25.0 if square_mm is None else square_mm) / 1e3)
        else:
            if square_mm is not None:
                raise InputError("--square-mm applies to the verification chart only")
            chart = FaceChart()
        suffix = out.suffix.lower()
        _check_raster(chart, dpi, rasterised=kind is ChartKind.faces or suffix == ".png")
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


def _check_raster(chart: Chart, dpi: float, *, rasterised: bool) -> None:
    """Refuse a ``--dpi`` whose raster would not fit in memory (a PNG, or the face chart in a
    PDF; the verification chart's PDF is vector)."""
    w, h = chart.size_m
    px = (w * dpi / M_PER_INCH) * (h * dpi / M_PER_INCH)
    if rasterised and px > MAX_RASTER_PX:
        raise InputError(
            f"--dpi {dpi:g} gives a {w * dpi / M_PER_INCH:.0f} × {h * dpi / M_PER_INCH:.0f} px "
            f"raster ({px / 1e9:.1f} G pixels, more than {MAX_RASTER_PX / 1e9:g} G); lower --dpi "
            "(300 prints sharp) or --square-mm"
        )
