"""The wide's focus breathing between calibration and use (fixes/breathing.py, thesis §3.5)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from phonestereo.errors import InputError
from phonestereo.fixes.breathing import correct_depth, focal_breathing_scale, focus_sigma_rel
from phonestereo.io import load_calibration
from phonestereo.io.calibration import calibration_from_dict, calibration_to_dict
from phonestereo.sim import effects as fx
from phonestereo.sim.factory import factory_calibration
from phonestereo.sim.module import load_module
from phonestereo.sim.random_module import random_module


@pytest.mark.parametrize("name", ["folded-x3", "periscope-x5", "random-1005"])
@pytest.mark.parametrize("focus_m", [0.8, 1.5, 4.0])
def test_thin_lens_scale_is_the_simulators_focus_breathing(name: str, focus_m: float) -> None:
    # The simulator moves the lens to v = f·s/(s − f) and images at v / pitch pixels: the
    # product's scale, from the focal length in mm and two focus distances, must be that
    # ratio (the same law written twice; 1e-9 is float rounding).
    spec = random_module(1005) if name.startswith("random") else load_module(name)
    f_cal = fx.focal_px(spec, "wide", fx.calibration_image_distance_m(spec, "wide"))
    f_use = fx.focal_px(spec, "wide", fx.lens_image_distance_m(spec, "wide", focus_m))
    k = focal_breathing_scale(spec.wide.focal_length_mm, spec.calibration.focus_distance_m,
                              focus_m)
    assert k == pytest.approx(f_use / f_cal, abs=1e-9)
    assert k < 1.0  # focused farther than the factory's 0.6 m: a shorter focal length


def test_reported_focus_wins_over_the_measured_depth() -> None:
    # A wide held at 1.5 m while the subject is at 4 m: corrected for 1.5 m (−0.63 % for a
    # 5.85 mm lens calibrated at 0.6 m), not for 4 m (−0.83 %).
    at_reported = correct_depth(4.0, 5.85, 0.6, focus_dioptre=1 / 1.5)
    assert at_reported == pytest.approx(4.0 * focal_breathing_scale(5.85, 0.6, 1.5), rel=1e-12)
    assert correct_depth(4.0, 5.85, 0.6) == pytest.approx(4.0 * 0.99170, rel=2e-5)
    assert correct_depth(4.0, 5.85, 0.6, focus_dioptre=0.0) < 4.0  # infinity
    assert correct_depth(float("nan"), 5.85, 0.6) != correct_depth(float("nan"), 5.85, 0.6)
    with pytest.raises(InputError, match="focal_length_mm"):
        focal_breathing_scale(-1.0, 0.6, 2.0)


def test_calibration_keeps_the_wide_focal_length(tmp_path: Path) -> None:
    cal = factory_calibration(load_module("folded-x3"), np.random.default_rng(0))
    assert cal.conditions.wide_focal_length_mm == 4.2
    back = calibration_from_dict(calibration_to_dict(cal))
    assert back.conditions.wide_focal_length_mm == 4.2
    d = calibration_to_dict(cal)
    d["conditions"]["wide_focal_length_mm"] = 400.0
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps(d))
    with pytest.raises(InputError, match="wide_focal_length_mm"):
        load_calibration(path)
    del d["conditions"]["wide_focal_length_mm"]  # optional: older files load unchanged
    path.write_text(json.dumps(d))
    assert load_calibration(path).conditions.wide_focal_length_mm is None


def test_focus_sigma_is_the_scale_derivative_times_the_report_sigma() -> None:
    # σ_rel = |d ln(scale)/dD|·σ_D: checked against the thin-lens scale's own numerical
    # derivative (central difference, step 1e-4 D; agreement to 1e-6 relative).
    f_mm, cal_m, d = 5.85, 0.6, 0.5
    h = 1e-4
    lo, hi = (focal_breathing_scale(f_mm, cal_m, 1.0 / (d + s)) for s in (-h, h))
    dlog = (np.log(hi) - np.log(lo)) / (2 * h)
    assert abs(focus_sigma_rel(f_mm, d, 0.3) - abs(dlog) * 0.3) < 1e-6 * 0.3
    assert focus_sigma_rel(f_mm, d, 0.0) == 0.0
    with pytest.raises(InputError, match="focal length"):
        focus_sigma_rel(0.0, d, 0.3)
