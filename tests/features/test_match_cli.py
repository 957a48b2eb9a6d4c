"""`phonestereo match`: JSON output on a real pair, --calibration on a rendered pair, errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import _support.stereo_eval as bench
import phonestereo.cli.match  # noqa: F401  (registers the command if cli/__init__ does not)
from phonestereo.cli import app
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.io import Calibration, save_calibration, write_image

ADIRONDACK = bench.DATA / "middeval3_Q_Adirondack"


def _run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(app, ["match", *args])
    return res.exit_code, " ".join(res.output.split())


@pytest.mark.skipif(not ADIRONDACK.exists(), reason="shared/data not beside the clone")
def test_rectified_json_on_middlebury() -> None:
    wide, tele = str(ADIRONDACK / "im0.png"), str(ADIRONDACK / "im1.png")
    code, out = _run(
        wide, tele, "--rectified", "--roi", "100,100,300,200", "--max-disparity", "80", "--json"
    )
    assert code == 0, out
    data = json.loads(out)
    assert data["seconds"] > 0 and len(data["matches"]) > 300
    m = data["matches"][0]
    assert set(m) >= {"x", "y", "d", "e", "sigma_d"}
    xs = np.array([m["x"] for m in data["matches"]])
    assert xs.min() >= 100 and xs.max() < 400
    _, _, gt, _ = bench.load_middlebury("Adirondack")
    xy = np.array([[m["x"], m["y"]] for m in data["matches"]])
    err = np.abs(np.array([m["d"] for m in data["matches"]]) - bench.gt_at(gt, xy))
    assert np.nanmedian(err) < 0.05  # px
    code, out = _run(wide, tele, "--rectified", "--max-disparity", "80")
    assert code == 0 and "after matches" in out
    code, out = _run(wide, tele, "--rectified", "--max-disparity", "80", "--fast", "--json")
    assert code == 0 and json.loads(out)["counts"]["keypoints"] == 400


def test_calibration_rectifies_first(tmp_path: Path) -> None:
    left, right, _ = bench.render_pair([(12.4, (0.0, 0.0, 0.0), (0.0, 0.0))], size=(240, 180))
    cam = Camera((240, 180), 600.0, 600.0, 119.5, 89.5)
    rig = Rig(cam, cam, Transform(np.eye(3), np.array([-0.02, 0.0, 0.0])))  # tele 2 cm right
    save_calibration(tmp_path / "calibration.json", Calibration(rig))
    write_image(tmp_path / "wide.png", left)
    write_image(tmp_path / "tele.png", right)
    args = [str(tmp_path / "wide.png"), str(tmp_path / "tele.png")]
    code, out = _run(
        *args,
        "--calibration",
        str(tmp_path / "calibration.json"),
        "--max-disparity",
        "24",
        "--json",
    )
    assert code == 0, out
    data = json.loads(out)
    d = np.array([m["d"] for m in data["matches"]])
    assert data["frame"] == "rectified" and len(d) > 500
    assert abs(np.median(d) - 12.4) < 0.01  # px
    assert {"x_raw", "y_raw"} <= set(data["matches"][0])


def test_errors_exit_2_with_a_message(tmp_path: Path) -> None:
    img = np.random.default_rng(0).integers(0, 255, (80, 100), dtype=np.uint8)
    write_image(tmp_path / "a.png", img)
    (tmp_path / "bad.png").write_bytes(b"not an image")
    (tmp_path / "empty.png").write_bytes(b"")
    a = str(tmp_path / "a.png")
    cases = [
        ((a, a), "exactly one of --rectified"),
        ((a, a, "--rectified", "--calibration", a), "exactly one of --rectified"),
        ((a, str(tmp_path / "bad.png"), "--rectified"), "cannot decode"),
        ((a, str(tmp_path / "empty.png"), "--rectified"), "empty"),
        ((a, str(tmp_path / "missing.png"), "--rectified"), "not found"),
        ((a, a, "--rectified", "--roi", "90,10,50,50"), "not inside"),
        ((a, a, "--rectified", "--max-disparity", "0"), "max_disparity > min_disparity"),
        ((a, a, "--rectified", "--detector", "orb"), "detector"),
    ]
    for args, message in cases:
        code, out = _run(*args)
        assert code == 2, (args, out)
        assert message in out, (args, out)
