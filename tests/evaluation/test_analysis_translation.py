"""Translation analysis (thesis §3.3, Figure 3-10) on simulated dual-depth capture sets.

Acceptance (issue #5): with t_y, t_z present, canonical rectification makes the mean e of two
charts at different depths agree within 0.02 px (before/after reported); readable figures;
a set lacking the captures → InputError naming what is needed.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from phonestereo.errors import InputError
from phonestereo.evaluation.analyses.translation import analyze_translation, run
from phonestereo.io import load_capture_set, write_image, write_manifest
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import DualDepthConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set


def _write(folder: Path, spec, attempts: int = 1) -> Path:
    write_capture_set(
        folder, plan_scenario("dual-depth", spec, 0, config=DualDepthConfig(attempts=attempts))
    )
    return folder


@pytest.fixture(scope="module")
def trans_only(tmp_path_factory: pytest.TempPathFactory) -> Path:
    spec = load_module("folded-x3").all_effects_off().with_effects(non_baseline_translation=True)
    return _write(tmp_path_factory.mktemp("tr") / "set", spec)


@pytest.fixture(scope="module")
def trans_result(trans_only: Path, tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("tr_out")
    return run(trans_only, out), out


def test_canonical_makes_both_charts_agree(trans_result) -> None:
    res, _ = trans_result
    tb = res.table
    assert res.ok, res.reason
    assert tb["corners"]["near"] > 50 and tb["corners"]["far"] > 500
    # before: t_y = −0.4 mm, t_z = 1.5 mm → the charts at 1 m and 2 m disagree by 0.67 px
    # (the first-order prediction from the calibration: 0.67 px); measured 0.666 px
    assert tb["spread_before_px"] > 0.5
    assert tb["spread_before_px"] == pytest.approx(tb["predicted_before_spread_px"], rel=0.05)
    # acceptance: after (canonical) within 0.02 px; measured 0.0006 px
    assert tb["spread_after_px"] < 0.02
    # the translation measured from e matches the calibration's to ~10 µm
    tf = tb["modes"]["undistort-both"]["translation_from_e"]
    b = tb["calibration_translation"]["baseline_m"]
    assert tf["ty_over_b"] * b == pytest.approx(-0.0004, abs=2e-5)
    assert tf["tz_over_b"] * b == pytest.approx(0.0015, abs=5e-5)
    # the true corners say the same (detection adds < 0.005 px)
    assert tb["truth"]["modes"]["canonical"]["spread_px"] < 1e-3
    assert any("canonical: mean e near − far" in line for line in res.summary)


def test_files(trans_result) -> None:
    res, out = trans_result
    names = sorted(p.name for p in res.files)
    assert names == ["translation.json", "translation_dual_depth.png", "translation_e_by_depth.png"]
    for p in res.files:
        if p.suffix == ".png":
            img = cv2.imread(str(p))
            assert img is not None and img.shape[0] > 400 and img.shape[1] > 700
    table = json.loads((out / "translation.json").read_text())
    assert table["ok"] and "canonical+radial" in table["modes"]


def test_all_effects_on_is_reported(tmp_path: Path) -> None:
    """All effects on: focus breathing and calibration noise dominate (thesis: 'still not
    perfect'); the analysis still runs and reports both; the e-axis fix after canonical
    brings the charts together (measured 2.02 → 2.72 → 0.015 px)."""
    res = run(_write(tmp_path / "set", load_module("folded-x3")), tmp_path)
    tb = res.table
    assert res.ok
    assert tb["modes"]["canonical+radial"]["spread_px"] < 0.05


def test_set_lacking_captures(trans_only: Path, tmp_path: Path) -> None:
    small = tmp_path / "small"
    shutil.copytree(trans_only, small)
    cs = load_capture_set(small)
    caps = [c.model_copy(update={"kind": "scene"}) for c in cs.captures()]
    write_manifest(small, cs.manifest.model_copy(update={"captures": caps}))
    with pytest.raises(InputError, match="two verification charts at two depths"):
        analyze_translation(small)


def test_no_charts_is_a_result_with_reason(trans_only: Path, tmp_path: Path) -> None:
    blank = tmp_path / "blank"
    shutil.copytree(trans_only, blank)
    for c in load_capture_set(blank).captures():
        write_image(blank / c.tele, np.full((1500, 2000), 128, np.uint8))
    res = run(blank, tmp_path)
    assert not res.ok and "two charts found in 0 captures" in res.reason and "tele" in res.reason
