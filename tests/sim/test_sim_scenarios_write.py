"""Rendered capture sets: byte-identical for the same seed, readable by io, images match the
ground truth, and the `phonestereo simulate` command."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest
from typer.testing import CliRunner

import phonestereo.cli.simulate  # noqa: F401  (registers `simulate`)
from phonestereo.cli.app import app
from phonestereo.io import load_calibration, load_capture_set, read_gray
from phonestereo.sim.ground_truth import load_ground_truth
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import StackConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set


def _small_module_json(tmp_path: Path) -> Path:
    """folded-x3 on a 4× coarser sensor (500 × 375 px, same optics): fast to render."""
    data = json.loads(load_module("folded-x3").to_json())
    for role in ("wide", "tele"):
        data[role]["size"] = [500, 375]
        data[role]["pixel_pitch_um"] = 11.2
        data[role]["principal_point_offset_px"] = [1.0, -0.5]
    data["name"] = "folded-x3-small"
    path = tmp_path / "small.json"
    path.write_text(json.dumps(data))
    return path


def _files(folder: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def test_same_seed_gives_a_byte_identical_folder(tmp_path: Path) -> None:
    spec = load_module(_small_module_json(tmp_path))
    cfg = StackConfig(attempts=2)
    for name in ("a", "b"):
        write_capture_set(tmp_path / name, plan_scenario("refocus", spec, 7, config=cfg))
    write_capture_set(tmp_path / "c", plan_scenario("refocus", spec, 8, config=cfg))
    a, b, c = (_files(tmp_path / n) for n in "abc")
    assert sorted(a) == [
        "calibration.json",
        "ground_truth.json",
        "images/r00_0_tele.jpg",  # the presets' ISP stores JPEG, as a phone does
        "images/r00_0_wide.jpg",
        "images/r00_1_tele.jpg",
        "images/r00_1_wide.jpg",
        "manifest.json",
    ]
    assert a == b  # every byte, images included
    assert a["images/r00_0_wide.jpg"] != c["images/r00_0_wide.jpg"]  # the seed matters


def test_capture_set_is_readable_by_io(tmp_path: Path) -> None:
    spec = load_module(_small_module_json(tmp_path))
    write_capture_set(tmp_path / "set", plan_scenario("orientation", spec, 0, quick=True))
    cs = load_capture_set(tmp_path / "set")  # checks the images exist
    wide, tele = cs.image_paths("flip_0")
    assert read_gray(wide).shape == (375, 500) and read_gray(tele).dtype == np.uint8
    cal = load_calibration(cs.calibration_path())
    assert cal.conditions.focus_distance_m == 0.6 and cal.conditions.orientation == "landscape"
    assert cal.rig.wide.lens.name == "opencv5"
    assert cs.get("flip_0").orientation == "landscape-flipped"


def test_rendered_corners_sit_on_their_ground_truth(tmp_path: Path) -> None:
    """Full-size folded-x3, noise and defocus on: cornerSubPix finds the chessboard corners
    where ground truth says (the renderer's own test pins the noise-free accuracy at 0.02 px;
    here sensor noise, defocus blur and the phone ISP widen it to ~0.1 px RMS, without bias)."""
    plan = plan_scenario("refocus", load_module("folded-x3"), 0, config=StackConfig(attempts=1))
    write_capture_set(tmp_path, plan)
    truth = load_ground_truth(tmp_path).captures[0].objects[0].keypoints["corners"].arrays()
    for role, px, win in (("wide", truth.wide_px, 5), ("tele", truth.tele_px, 11)):
        img = read_gray(tmp_path / "images" / f"r00_0_{role}.jpg").astype(np.float32)
        p = px[np.isfinite(px).all(axis=1)]
        p = p[(p.min(axis=1) > 30) & (p[:, 0] < 1970) & (p[:, 1] < 1470)]
        start = (p + 0.3).astype(np.float32).reshape(-1, 1, 2)
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-4)
        found = cv2.cornerSubPix(img, start, (win, win), (-1, -1), crit).reshape(-1, 2)
        err = found - p
        assert len(p) > 400
        assert np.sqrt((err**2).sum(axis=1).mean()) < 0.15
        assert np.abs(err.mean(axis=0)).max() < 0.03  # no bias between image and truth


def test_simulate_cli_json_and_reproducible(tmp_path: Path) -> None:
    module = _small_module_json(tmp_path)
    runner = CliRunner()
    outs = []
    for name in ("x", "y"):
        res = runner.invoke(
            app,
            [
                "simulate",
                "dual-depth",
                "--module",
                str(module),
                "--out",
                str(tmp_path / name),
                "--seed",
                "3",
                "--quick",
                "--json",
            ],
        )
        assert res.exit_code == 0, res.output
        outs.append(json.loads(res.output))
    assert outs[0]["captures"] == 2 and outs[0]["images_rendered"] == 4
    assert outs[0]["module"] == "folded-x3-small" and outs[0]["kinds"] == {"verification": 2}
    assert _files(tmp_path / "x") == _files(tmp_path / "y")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["simulate", "warmup"], "choose one of"),
        (["simulate", "refocus", "--module", "folded-x9"], "nonfolded-x2"),
    ],
)
def test_simulate_cli_bad_input(args: list[str], message: str, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, [*args, "--out", str(tmp_path / "o")])
    assert res.exit_code == 2
    assert message in " ".join(res.output.replace("│", " ").split())
    assert not (tmp_path / "o").exists()  # nothing written on bad input
