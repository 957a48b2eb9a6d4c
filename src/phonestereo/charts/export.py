"""Printable charts at physical size: PDF (vector boards, ≥ 300 dpi rasters) and PNG.

The PDF page is the chart plus a strip below it with a labelled scale bar and the chart's
parameters, so a print can be checked with a ruler ("print at 100 %, no fit-to-page").
Chessboards (with or without circle pairs) are drawn as vector shapes; every other chart
(faces, texture) is embedded as a grey raster sampled from :meth:`Chart.intensity` at
``raster_dpi``. Grey values are the sRGB print values of the chart's reflectances
(:func:`~phonestereo.charts.base.reflectance_to_print`: ink 0.05 → 0, paper 0.95 → 255).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.collections import PatchCollection
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Rectangle
from numpy.typing import NDArray
from PIL import Image

from phonestereo.charts.base import Chart, reflectance_to_print
from phonestereo.charts.verification import Chessboard, VerificationChart
from phonestereo.errors import InputError

M_PER_INCH = 0.0254
_CHUNK_POINTS = 4_000_000
_LUT_LEVELS = 65536  # reflectance quantised to 1/65535 before the 8-bit print look-up


@dataclass(frozen=True, eq=False)
class PrintedChart:
    """What an export wrote."""

    #: The file written.
    path: Path
    #: (width, height) of the chart on the page, metres.
    chart_size_m: tuple[float, float]
    #: (width, height) of the page: the chart plus the strip below it, metres.
    page_size_m: tuple[float, float]
    #: Height of the scale-bar strip, metres (0 for PNG).
    strip_m: float
    #: Resolution of the embedded raster, dots per inch; None if drawn as vectors only.
    raster_dpi: float | None
    #: dict. The chart's parameters (JSON-friendly).
    parameters: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly summary (sizes also in millimetres)."""
        return {
            "path": str(self.path),
            "chart_size_m": list(self.chart_size_m),
            "page_size_m": list(self.page_size_m),
            "page_size_mm": [round(1000 * s, 3) for s in self.page_size_m],
            "strip_m": self.strip_m,
            "raster_dpi": self.raster_dpi,
            "parameters": self.parameters,
        }


def chart_parameters(chart: Chart) -> dict[str, Any]:
    """The public dataclass fields of ``chart`` as a JSON-friendly dict (sizes in metres).

    >>> chart_parameters(VerificationChart())["squares"]
    [40, 28]
    """
    out: dict[str, Any] = {"name": chart.name, "size_m": list(chart.size_m)}
    if dataclasses.is_dataclass(chart):
        for f in dataclasses.fields(chart):
            if f.init and not f.name.startswith("_"):
                val = getattr(chart, f.name)
                out[f.name] = list(val) if isinstance(val, tuple) else val
    return out


def _gray(reflectance: float) -> str:
    """Matplotlib grey string that prints as ``reflectance``."""
    return f"{float(reflectance_to_print(reflectance)):.4f}"


def _draw_board(ax: Any, chart: Chessboard | VerificationChart) -> None:
    """Chessboard squares (and circles) as vector patches in chart coordinates (metres)."""
    w, h = chart.size_m
    s, m = chart.square_m, chart.margin_m
    cols, rows = chart.squares
    r, c = np.nonzero((np.add.outer(np.arange(rows), np.arange(cols)) % 2) == 0)
    paper = Rectangle((0, 0), w, h)
    ax.add_collection(PatchCollection([paper], facecolor=_gray(chart.white), linewidth=0))
    squares = [Rectangle((m + j * s, m + i * s), s, s) for i, j in zip(r, c, strict=True)]
    ax.add_collection(PatchCollection(squares, facecolor=_gray(chart.black), linewidth=0))
    if isinstance(chart, VerificationChart):
        for pair in chart.circle_pairs:
            color = chart.black if pair.polarity == "dark" else chart.white
            circles = [Circle((cu, cv), pair.radius_m) for cu, cv in pair.centers_uv]
            ax.add_collection(PatchCollection(circles, facecolor=_gray(color), linewidth=0))


def raster(chart: Chart, px_per_m: float, *, supersample: int = 1) -> NDArray[np.uint8]:
    """8-bit grey print values of ``chart`` (H, W), pixel centres on a ``px_per_m`` grid.

    Parameters
    ----------
    chart : Chart
        Any chart.
    px_per_m : float
        Pixels per metre (300 dpi = 11811 px/m).
    supersample : int
        Samples per pixel along each axis, averaged in reflectance (box filter).

    Returns
    -------
    ndarray of uint8, shape (round(h · px_per_m), round(w · px_per_m))
        Pixel (x, y) covers [x, x + 1] · w / W metres (the grid spans the chart exactly).
    """
    if not (np.isfinite(px_per_m) and px_per_m > 0):
        raise InputError(f"px_per_m must be a positive number, got {px_per_m}")
    if int(supersample) < 1:
        raise InputError(f"supersample must be an integer >= 1, got {supersample}")
    k = int(supersample)
    w, h = chart.size_m
    nx, ny = max(1, round(w * px_per_m)), max(1, round(h * px_per_m))
    lut = np.round(255.0 * reflectance_to_print(np.linspace(0, 1, _LUT_LEVELS))).astype(np.uint8)
    sub = (np.arange(k) + 0.5) / k
    us = ((np.arange(nx)[:, None] + sub).ravel()) * (w / nx)
    out = np.empty((ny, nx), dtype=np.uint8)
    rows_per_chunk = max(1, _CHUNK_POINTS // (nx * k * k))
    for y0 in range(0, ny, rows_per_chunk):  # chunks of rows bound memory; not a pixel loop
        y1 = min(ny, y0 + rows_per_chunk)
        vs = ((np.arange(y0, y1)[:, None] + sub).ravel()) * (h / ny)
        uu, vv = np.meshgrid(us, vs)
        refl = chart.intensity(np.stack([uu, vv], axis=-1))
        refl = refl.reshape(y1 - y0, k, nx, k).mean(axis=(1, 3))
        level = np.clip(refl * (_LUT_LEVELS - 1) + 0.5, 0, _LUT_LEVELS - 1)
        out[y0:y1] = lut[np.nan_to_num(level).astype(np.intp)]
    return out


def export_pdf(
    chart: Chart,
    path: str | Path,
    *,
    scale_bar_m: float = 0.1,
    strip_m: float = 0.03,
    raster_dpi: float = 300.0,
) -> PrintedChart:
    """Write ``chart`` as a PDF at physical size, with a scale-bar strip below it.

    Parameters
    ----------
    chart : Chart
        The chart; chessboards are drawn as vectors, other charts as a raster.
    path : str or Path
        Output file (``.pdf``).
    scale_bar_m : float
        Length of the scale bar, metres (check it with a ruler after printing).
    strip_m : float
        Height of the strip under the chart, metres.
    raster_dpi : float
        Resolution of the embedded raster for non-vector charts, dots per inch.

    Returns
    -------
    PrintedChart
        Page size = (w, h + strip_m) in metres; figure size in inches = size / 0.0254.
    """
    w, h = chart.size_m
    if not 0 < scale_bar_m <= w - 0.02:
        raise InputError(f"scale_bar_m must be in (0, {w - 0.02:.3f}] m for this chart")
    if not strip_m >= 0.015:
        raise InputError(f"strip_m must be at least 0.015 m to hold the scale bar, got {strip_m}")
    if not raster_dpi > 0:
        raise InputError(f"raster_dpi must be positive, got {raster_dpi}")
    out = Path(path)
    page_h = round(h + strip_m, 12)
    fig = Figure(figsize=(w / M_PER_INCH, page_h / M_PER_INCH), facecolor="white")
    ax = fig.add_axes((0.0, strip_m / page_h, 1.0, h / page_h))
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)
    ax.set_axis_off()
    dpi: float | None = None
    if isinstance(chart, (Chessboard, VerificationChart)):
        _draw_board(ax, chart)
    else:
        dpi = float(raster_dpi)
        img = raster(chart, dpi / M_PER_INCH)
        ax.imshow(
            img,
            cmap="gray",
            vmin=0,
            vmax=255,
            extent=(0, w, h, 0),
            interpolation="none",
            aspect="auto",
        )
    params = chart_parameters(chart)
    _draw_strip(fig, w, strip_m, page_h, scale_bar_m, params, dpi)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, format="pdf", dpi=dpi or 300)
    return PrintedChart(out, (w, h), (w, page_h), strip_m, dpi, params)


def _draw_strip(
    fig: Figure,
    w: float,
    strip_m: float,
    page_h: float,
    bar_m: float,
    params: dict[str, Any],
    dpi: float | None,
) -> None:
    """Scale bar (1 cm ticks) and the parameters, in a strip of the page (metres)."""
    ax = fig.add_axes((0.0, 0.0, 1.0, strip_m / page_h))
    ax.set_xlim(0, w)
    ax.set_ylim(strip_m, 0)
    ax.set_axis_off()
    x0, y0, thick = 0.01, 0.4 * strip_m, 0.002
    ax.add_patch(Rectangle((x0, y0), bar_m, thick, facecolor="black", linewidth=0))
    for t in np.arange(0.0, bar_m + 1e-9, 0.01):
        ax.plot([x0 + t, x0 + t], [y0 - 0.002, y0], color="black", linewidth=0.5)
    ax.text(x0 + bar_m / 2, y0 + thick + 0.001, f"{bar_m * 1000:g} mm", ha="center", va="top")
    ax.text(x0, y0 - 0.003, "print at 100 % (actual size, no fit-to-page)", va="bottom")
    shown = {k: v for k, v in params.items() if k not in ("name", "faces")}
    text = f"{params['name']}  " + "  ".join(f"{k}={v}" for k, v in shown.items())
    if dpi is not None:
        text += f"  raster {dpi:g} dpi"
    ax.text(x0 + bar_m + 0.01, y0, text, va="center", fontsize=7, wrap=True)


def export_png(
    chart: Chart, path: str | Path, px_per_m: float, *, supersample: int = 2
) -> PrintedChart:
    """Write ``chart`` as an 8-bit grey PNG, ``px_per_m`` pixels per metre (DPI stored).

    >>> import tempfile, os
    >>> d = tempfile.mkdtemp()
    >>> info = export_png(Chessboard((4, 3), 0.02, 0.01), os.path.join(d, "b.png"), 1000)
    >>> Image.open(info.path).size                  # (5·20 + 2·10) mm × (4·20 + 2·10) mm
    (120, 100)
    """
    out = Path(path)
    img = raster(chart, px_per_m, supersample=supersample)
    out.parent.mkdir(parents=True, exist_ok=True)
    dpi = px_per_m * M_PER_INCH
    Image.fromarray(img).save(out, dpi=(dpi, dpi))
    return PrintedChart(out, chart.size_m, chart.size_m, 0.0, dpi, chart_parameters(chart))
