"""`phonestereo calibrate` on the OpenCV stereo sample, and its clear errors."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

from phonestereo.cli import app

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "opencv_stereo"
pytestmark = pytest.mark.skipif(not DATA.exists(), reason="shared/data not beside the clone")


def _run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(app, list(args))
    return res.exit_code, " ".join(res.output.split())  # Rich may wrap long messages


def test_stereo_calibration_json(tmp_path: Path) -> None:
    code, out = _run(
        "calibrate",
        "--board",
        "9x6",
        "--square-m",
        "1",
        "--wide",
        str(DATA / "left*.jpg"),
        "--tele",
        str(DATA / "right*.jpg"),
        "--out",
        str(tmp_path / "calibration.json"),
        "--json",
    )
    assert code == 0, out
    summary = json.loads(out.strip().splitlines()[-1])
    # Issue #3: with outlier rejection ≤ 0.14 px per coordinate (mrcal 0.129 px, 2.4 % out).
    assert summary["rms_px_per_coordinate"] <= 0.14
    assert summary["outliers"] / summary["points"] < 0.03
    assert abs(abs(summary["T_tele_wide"]["t"][0]) - 3.33) < 0.05  # square units
    # |t| with its σ (first order): the sample's 3.33 squares, known to ~1e-3 of a square.
    assert summary["baseline"]["norm"] == pytest.approx(np.linalg.norm(summary["T_tele_wide"]["t"]))
    assert 1e-4 < summary["baseline"]["std"] < 0.01
    # The corner σ: from the image noise alone these JPEGs read ~0.002 px (nearly noise-free),
    # with the saddle fit's own odd misfit (features/saddle_misfit.py) 0.03-0.04 px; still under
    # the residual RMS (0.12 px per coordinate), which also holds the lens model's and the
    # board's misfit.
    sig = summary["corner_sigma_px"]
    assert set(sig) == {"wide", "tele"} and all(0.015 < v < 0.08 for v in sig.values()), sig
    assert summary["rms_px_per_coordinate"] > 1.5 * max(sig.values())
    saved = json.loads((tmp_path / "calibration.json").read_text())
    assert saved["rms_px"] == pytest.approx(summary["rms_px_per_point"])


def test_view_weights_keep_the_noisier_views(tmp_path: Path) -> None:
    summaries = {}
    for flag in ("--view-weights", "--no-view-weights"):
        code, out = _run(
            "calibrate", "--board", "9x6", "--square-m", "1", "--wide", str(DATA / "left*.jpg"),
            "--tele", str(DATA / "right*.jpg"), "--out", str(tmp_path / f"c{flag}.json"),
            "--json", flag,
        )
        assert code == 0, out
        summaries[flag] = json.loads(out.strip().splitlines()[-1])
    on, off = summaries["--view-weights"], summaries["--no-view-weights"]
    # measured on the real JPEGs: 9 of 1402 corners rejected by default, 0.126 px per
    # coordinate over the kept ones; every corner alike (OpenCV's criterion): 18, 0.120 px.
    # The view whose σ differs beyond chance keeps its corners.
    assert on["outliers"] / on["points"] < 0.0075 and off["outliers"] > on["outliers"]
    assert on["rms_px_per_coordinate"] <= 0.14
    # the views given their own σ are named: left08.jpg (a steeply tilted board) alone, at 2.3×
    # the pooled σ; none with every corner alike
    own = {Path(v["image"]).name: v["sigma_ratio"] for v in on["views_own_sigma"]}
    assert own.get("left08.jpg", 0.0) > 1.8 and len(own) <= 4, own
    assert off["views_own_sigma"] == []
    for s in (on, off):
        assert abs(abs(s["T_tele_wide"]["t"][0]) - 3.33) < 0.05  # square units


def test_mono_calibration_names_its_noisier_view(tmp_path: Path) -> None:
    code, out = _run(
        "calibrate", "--board", "9x6", "--square-m", "1", "--wide", str(DATA / "left*.jpg"),
        "--out", str(tmp_path / "c.json"), "--json",
    )
    assert code == 0, out
    summary = json.loads(out.strip().splitlines()[-1])
    # measured: the 13 left images alone give left08.jpg its own σ, 1.4× the pooled one (the
    # view index of a mono solve counts the images with a board, named as the table names it)
    own = summary["views_own_sigma"]
    assert [(Path(v["image"]).name, v["camera"]) for v in own] == [("left08.jpg", "camera")]
    assert 1.2 < own[0]["sigma_ratio"] < 3.0


def test_wrong_board_size_names_the_fix(tmp_path: Path) -> None:
    code, out = _run(
        "calibrate",
        "--board",
        "8x6",
        "--square-m",
        "1",
        "--wide",
        str(DATA / "left*.jpg"),
        "--out",
        str(tmp_path / "c.json"),
    )
    assert code == 2
    assert "more inner corners than 8x6" in out


def test_empty_glob_and_mixed_sizes(tmp_path: Path) -> None:
    code, out = _run(
        "calibrate",
        "--board",
        "9x6",
        "--square-m",
        "1",
        "--wide",
        str(tmp_path / "none*.jpg"),
        "--out",
        str(tmp_path / "c.json"),
    )
    assert code == 2 and "no wide images match" in out
    for name in ("left01.jpg", "left02.jpg"):
        shutil.copy(DATA / name, tmp_path / name)
    small = cv2.resize(cv2.imread(str(DATA / "left03.jpg")), (320, 240))
    cv2.imwrite(str(tmp_path / "left03.jpg"), small)
    code, out = _run(
        "calibrate",
        "--board",
        "9x6",
        "--square-m",
        "1",
        "--wide",
        str(tmp_path / "left*.jpg"),
        "--out",
        str(tmp_path / "c.json"),
    )
    assert code == 2 and "must share a size" in out
