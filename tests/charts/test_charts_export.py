"""Printable export (PDF at physical size, PNG) and the `phonestereo chart` command."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from typer.testing import CliRunner

import phonestereo.cli.charts  # noqa: F401  (registers `chart` until cli/__init__ imports it)
from phonestereo.charts import (
    Chessboard,
    FaceChart,
    TexturedPlane,
    VerificationChart,
    export_pdf,
    export_png,
    reflectance_to_print,
)
from phonestereo.cli import app
from phonestereo.errors import InputError

PT_PER_M = 72 / 0.0254


def media_box_m(path: Path) -> tuple[float, float]:
    """Page (width, height) in metres from the first MediaBox of a PDF."""
    boxes = re.findall(rb"/MediaBox\s*\[\s*([-\d.\s]+)\]", path.read_bytes())
    x0, y0, x1, y1 = (float(v) for v in boxes[0].split())
    return (x1 - x0) / PT_PER_M, (y1 - y0) / PT_PER_M


def test_verification_pdf_page_is_chart_plus_strip(tmp_path: Path) -> None:
    chart = VerificationChart()
    info = export_pdf(chart, tmp_path / "v.pdf")
    w, h = media_box_m(info.path)
    # brief: page = chart + strip within 1 mm (the MediaBox is written to 1e-10 pt)
    assert abs(w - 1.05) < 1e-3 and abs(h - (0.75 + 0.03)) < 1e-3
    assert info.page_size_m == pytest.approx((1.05, 0.78)) and info.raster_dpi is None
    data = info.path.read_bytes()
    assert b"/Subtype /Image" not in data  # the board is vector shapes only
    assert info.path.stat().st_size < 200_000


def test_face_pdf_embeds_raster_at_requested_dpi(tmp_path: Path) -> None:
    chart = FaceChart(grid=(2, 1), cell_m=0.2)  # small chart keeps the test fast
    info = export_pdf(chart, tmp_path / "f.pdf", raster_dpi=100, scale_bar_m=0.05)
    w, h = media_box_m(info.path)
    assert abs(w - 0.4) < 1e-3 and abs(h - 0.23) < 1e-3
    data = info.path.read_bytes()
    width = int(re.search(rb"/Subtype /Image.*?/Width (\d+)", data, re.S).group(1))
    assert width == round(0.4 / 0.0254 * 100)  # 100 dpi over 0.4 m = 1575 px


def test_png_export_size_and_values(tmp_path: Path) -> None:
    board = Chessboard((4, 3), square_m=0.02, margin_m=0.01)
    info = export_png(board, tmp_path / "b.png", 1000.0)
    img = np.asarray(Image.open(info.path))
    assert img.shape == (100, 120)  # (4·20 + 20) mm × (5·20 + 20) mm at 1 px/mm
    assert img[15, 15] == 0 and img[15, 35] == 255 and img[2, 2] == 255  # ink, paper, margin
    # a pixel straddling a square edge averages reflectance, then encodes sRGB
    edge = export_png(Chessboard((4, 3), 0.0205, 0.01), tmp_path / "e.png", 1000.0)
    grey = np.asarray(Image.open(edge.path))
    assert ((grey > 0) & (grey < 255)).any()


def test_texture_png_and_bad_scale_bar(tmp_path: Path) -> None:
    plane = TexturedPlane((0.1, 0.05), seed=1, feature_m=0.005)
    info = export_png(plane, tmp_path / "t.png", 2000.0)
    img = np.asarray(Image.open(info.path)).astype(float)
    # reflectance 0.5 ± 0.2 prints around sRGB 188 (mid-range of ink..paper in linear light)
    assert img.shape == (100, 200) and 20 < img.std() < 60 and 160 < img.mean() < 200
    with pytest.raises(InputError, match="scale_bar_m"):
        export_pdf(plane, tmp_path / "t.pdf", scale_bar_m=0.5)


def test_print_values_round_trip() -> None:
    assert reflectance_to_print(0.05) == pytest.approx(0.0, abs=1e-12)
    assert reflectance_to_print(0.95) == pytest.approx(1.0, abs=1e-12)
    assert 0.4 < reflectance_to_print(0.2) < 0.5  # the face chart's mid-grey background


def test_cli_chart_writes_pdf_and_prints_json(tmp_path: Path) -> None:
    out = tmp_path / "chart.pdf"
    res = CliRunner().invoke(
        app, ["chart", "verification", "--out", str(out), "--square-mm", "20", "--json"]
    )
    assert res.exit_code == 0, res.output
    info = json.loads(res.output)
    # 40 × 28 squares of 20 mm + 2 × 25 mm margin, plus the 30 mm strip
    assert info["page_size_mm"] == [850.0, 640.0]
    assert info["parameters"]["square_m"] == 0.02
    w, h = media_box_m(out)
    assert abs(w - 0.85) < 1e-3 and abs(h - 0.64) < 1e-3


def test_cli_chart_errors(tmp_path: Path) -> None:
    runner = CliRunner()
    res = runner.invoke(app, ["chart", "hexagons", "--out", str(tmp_path / "x.pdf")])
    assert res.exit_code == 2 and "verification" in res.output and "faces" in res.output
    res = runner.invoke(
        app, ["chart", "faces", "--out", str(tmp_path / "x.pdf"), "--square-mm", "20"]
    )
    assert res.exit_code == 2 and "verification chart only" in res.output
    res = runner.invoke(app, ["chart", "verification", "--out", str(tmp_path / "x.svg")])
    assert res.exit_code == 2 and ".pdf or .png" in res.output
