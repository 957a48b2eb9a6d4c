"""`phonestereo rectify`: files written, JSON contents, and clear errors on bad input."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

import phonestereo.cli.rectify  # noqa: F401  (registers the command until cli/__init__ does)
from phonestereo.cli.app import app
from phonestereo.geometry import Camera, Rig, Transform, make_lens
from phonestereo.io import Calibration, save_calibration, write_image

W, H = 400, 300  # small images keep the CLI tests fast


@pytest.fixture()
def pair(tmp_path: Path) -> dict[str, Path]:
    """A folded ×3 pair at 400×300 (tele 12 mm below the wide) with its calibration."""
    wide = Camera((W, H), 300.0, 300.0, 200.3, 149.1, make_lens("opencv5", [-0.05, 0.01, 0, 0, 0]))
    tele = Camera((W, H), 900.0, 900.0, 199.2, 150.6)
    T = Transform.from_rotvec([0.004, -0.005, 0.007], [0.0003, -0.012, -0.0015])
    cal = save_calibration(tmp_path / "calibration.json", Calibration(Rig(wide, tele, T)))
    rng = np.random.default_rng(0)
    tex = cv2.GaussianBlur(rng.integers(0, 256, (H, W)).astype(np.float32), (0, 0), 2.0)
    img = np.clip(tex, 0, 255).astype(np.uint8)
    return {
        "cal": cal,
        "wide": write_image(tmp_path / "wide.png", img),
        "tele": write_image(tmp_path / "tele.png", img),
        "out": tmp_path / "out",
    }


def _run(*args: str) -> tuple[int, str]:
    res = CliRunner().invoke(app, list(args))
    return res.exit_code, " ".join(res.output.split())  # Rich may wrap long messages


def _args(p: dict[str, Path], mode: str = "canonical", wide: str = "wide", tele: str = "tele"):
    return (
        "rectify",
        "--calibration",
        str(p["cal"]),
        "--mode",
        mode,
        str(p[wide]),
        str(p[tele]),
        "--out",
        str(p["out"]),
    )


@pytest.mark.parametrize("mode", ["tele-to-wide", "undistort-both", "canonical"])
def test_rectify_writes_pngs_and_json(pair: dict[str, Path], mode: str) -> None:
    code, out = _run(*_args(pair, mode), "--json")
    assert code == 0, out
    summary = json.loads(out)
    info = json.loads((pair["out"] / "rectification.json").read_text())
    assert info["mode"] == mode and info["quarter_turns"] == 1  # vertical baseline, turned
    assert info["f_px"] == pytest.approx(300.0) and summary["f_px"] == info["f_px"]
    w, h = info["size"]
    assert h > w  # portrait: the 400×300 tele view at ×1/3, turned by 90°
    for name in ("wide_rectified.png", "tele_rectified.png"):
        img = cv2.imread(str(pair["out"] / name), cv2.IMREAD_UNCHANGED)
        assert img.shape == (h, w)
    assert set(info) >= {"R_rect_wide", "R_rect_tele", "wide_rect", "tele_rect", "baseline_m"}


def test_rectify_prints_a_table(pair: dict[str, Path]) -> None:
    code, out = _run(*_args(pair))
    assert code == 0, out
    assert "rectified size" in out and "wide_rectified.png" in out


def test_unreadable_and_empty_images(pair: dict[str, Path], tmp_path: Path) -> None:
    (tmp_path / "bad.png").write_bytes(b"not a png at all")
    (tmp_path / "empty.png").write_bytes(b"")
    pair["bad"], pair["empty"] = tmp_path / "bad.png", tmp_path / "empty.png"
    code, out = _run(*_args(pair, wide="bad"))
    assert code == 2 and "cannot decode image file" in out
    code, out = _run(*_args(pair, tele="empty"))
    assert code == 2 and "is empty" in out
    pair["missing"] = tmp_path / "nope.png"
    code, out = _run(*_args(pair, tele="missing"))
    assert code == 2 and "not found" in out


def test_size_mismatch_and_bad_options(pair: dict[str, Path], tmp_path: Path) -> None:
    pair["half"] = write_image(tmp_path / "half.png", np.zeros((H // 2, W // 2), np.uint8))
    code, out = _run(*_args(pair, tele="half"))
    assert code == 2 and "differ in size" in out and "calibration is for wide 400×300" in out
    code, out = _run(*_args(pair), "--roi", "350,10,100,50")
    assert code == 2 and "outside the 400×300 wide image" in out
    code, out = _run(*_args(pair), "--roi", "1,2,3")
    assert code == 2 and "X,Y,W,H" in out
    code, out = _run(*_args(pair, mode="opencv"))
    assert code == 2 and "unknown rectification mode" in out
    pair["cal"] = tmp_path / "missing.json"
    code, out = _run(*_args(pair))
    assert code == 2 and "calibration file" in out


def test_out_that_is_a_file_is_refused(pair: dict[str, Path]) -> None:
    # Was a FileExistsError traceback (issue #19 sweep); now exit 2, the file untouched.
    pair["out"].write_bytes(b"user data")
    code, out = _run(*_args(pair))
    assert code == 2, out
    assert "--out" in out and "is a file, not a folder" in out and "give a folder path" in out
    assert pair["out"].read_bytes() == b"user data"


def test_earlier_outputs_are_overwritten_only_with_force(pair: dict[str, Path]) -> None:
    assert _run(*_args(pair))[0] == 0
    written = {p.name: p.read_bytes() for p in pair["out"].iterdir()}
    (pair["out"] / "wide_rectified.png").write_bytes(b"edited by the user")
    code, out = _run(*_args(pair, mode="undistort-both"))
    assert code == 2, out
    assert "already holds wide_rectified.png" in out and "--force" in out
    assert (pair["out"] / "wide_rectified.png").read_bytes() == b"edited by the user"
    code, out = _run(*_args(pair), "--force")
    assert code == 0, out
    assert {p.name: p.read_bytes() for p in pair["out"].iterdir()} == written  # same bytes again
