"""Each effect of the virtual module in isolation: magnitudes in the true state and ground truth."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.geometry import Transform
from phonestereo.sim import effects as fx
from phonestereo.sim.capture import CaptureConditions, calibration_rig, true_state
from phonestereo.sim.factory import factory_calibration
from phonestereo.sim.lensfit import fit_even_lens, fit_residual_px
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import plan_scenario

SPEC = load_module("folded-x3")
IDEAL = SPEC.all_effects_off()


def _state(spec, *, t=300.0, mode="manual", focus=1.5, handheld=False, seed=0, pose=None):
    cond = CaptureConditions("c", "scene", t, pose or Transform.identity(), handheld, mode, focus)
    return true_state(spec, cond, np.random.default_rng(seed))


def _thin_lens_scale(f_mm: float, s: float, s_cal: float = 0.6) -> float:
    f = f_mm * 1e-3
    return (f * s / (s - f)) / (f * s_cal / (s_cal - f))


def test_ideal_module_is_the_calibration_rig() -> None:
    st = _state(IDEAL, handheld=True, mode="auto")
    ref = calibration_rig(IDEAL)
    assert st.wide.focal_scale == 1.0 and st.tele.focal_scale == 1.0
    assert st.wide.principal_point_shift_px == (0.0, 0.0)
    assert st.tele.principal_point_shift_px == (0.0, 0.0)
    assert np.allclose(st.T_tele_wide.matrix, ref.T_tele_wide.matrix, atol=1e-15)
    assert np.allclose(st.T_world_device.matrix, np.eye(4))
    assert not st.wide.af_failed and not st.tele.af_failed


def test_focus_breathing_follows_the_thin_lens() -> None:
    spec = IDEAL.with_effects(focus_breathing=True)
    st = _state(spec, focus=1.5)
    # Calibrated at 0.6 m, used at 1.5 m: wide −0.42 %, tele −1.27 % (v = f·s/(s − f)).
    assert st.wide.focal_scale == pytest.approx(_thin_lens_scale(4.2, 1.5), abs=1e-12)
    assert st.tele.focal_scale == pytest.approx(_thin_lens_scale(12.6, 1.5), abs=1e-12)
    assert st.wide.focal_scale == pytest.approx(0.99579, abs=1e-5)
    assert st.tele.focal_scale == pytest.approx(0.98729, abs=1e-5)
    # The tele's optical centre moves with its lens travel: t_z changes by Δv_tele − Δv_wide.
    dz = st.rig.tele_center_in_wide[2] - calibration_rig(spec).tele_center_in_wide[2]
    assert dz * 1e6 == pytest.approx(-163.4 + 17.8, abs=0.5)


def test_manual_focus_noise_has_the_stated_sigma() -> None:
    spec = IDEAL.with_effects(focus_breathing=True, focus_noise=True)
    scales = np.array(
        [
            [s.wide.focal_scale, s.tele.focal_scale]
            for s in (_state(spec, seed=k) for k in range(400))
        ]
    )
    rel = scales / scales.mean(axis=0) - 1
    # σ of the lens position 2e-4 (wide), 8e-4 (tele); 400 draws → σ known to ±7 % (1σ), 20 % band.
    assert rel[:, 0].std() == pytest.approx(2e-4, rel=0.2)
    assert rel[:, 1].std() == pytest.approx(8e-4, rel=0.2)


def test_autofocus_error_and_failures() -> None:
    spec = IDEAL.with_effects(focus_noise=True, af_failures=True)
    states = [_state(spec, mode="auto", focus=2.0, seed=k) for k in range(600)]
    failed = np.array([s.tele.af_failed for s in states])
    # 5 % failure rate: binomial 600 draws, 3σ band ±2.7 %.
    assert 0.023 < failed.mean() < 0.077
    ok = np.array([1 / s.tele.focus_distance_m for s in states])[~failed]
    assert ok.mean() == pytest.approx(0.5, abs=0.01)  # aims at the subject (0.5 D)
    assert ok.std() == pytest.approx(0.03, rel=0.2)  # 0.03 D aim error
    none = [_state(IDEAL.with_effects(focus_noise=True), mode="auto", seed=k) for k in range(200)]
    assert not any(s.tele.af_failed or s.wide.af_failed for s in none)


def test_heating_drift_and_temperature_curve() -> None:
    spec = IDEAL.with_effects(heating=True)
    for t in (0.0, 70.0, 180.0, 600.0):
        st = _state(spec, t=t)
        frac = 1 - np.exp(-t / 70.0)
        for role in ("wide", "tele"):
            a = np.array(getattr(SPEC, role).heating_drift_px)
            assert np.allclose(st.camera(role).principal_point_shift_px, a * frac, atol=1e-12)
        assert st.temperature_c == pytest.approx(25 + 15 * frac)
    # Saturated after ~3 min (thesis §3.1): > 92 % of the drift at 180 s.
    assert fx.heating_fraction(spec, 180.0) > 0.92
    assert _state(IDEAL, t=600.0).temperature_c == 25.0


def test_heating_visible_in_the_heating_scenario_ground_truth() -> None:
    gt = plan_scenario(
        "heating", SPEC.all_effects_off().with_effects(heating=True), 0
    ).ground_truth()
    t = np.array([c.time_s for c in gt.captures])
    dy = np.array([c.tele.principal_point_shift_px[1] for c in gt.captures])
    assert len(t) == 61 and t[-1] == 600.0  # every 10 s for 10 min
    assert np.allclose(dy, -3.3 * (1 - np.exp(-t / 70.0)), atol=1e-9)
    assert np.all(np.diff(dy) < 0)  # monotone, saturating drift


def test_sag_shifts_the_tele_principal_point_half_a_pixel_per_g() -> None:
    gt = plan_scenario("orientation", IDEAL.with_effects(sag=True), 0, quick=True).ground_truth()
    land, flip = gt.captures
    assert land.orientation == "landscape" and flip.orientation == "landscape-flipped"
    assert np.allclose(flip.gravity, (0, -1, 0), atol=1e-12)
    # Calibrated in landscape: flipped moves the tele by 2 × 0.5 px along y; the wide not at all.
    assert flip.tele.principal_point_shift_px == pytest.approx((0.0, -1.0), abs=1e-12)
    assert land.tele.principal_point_shift_px == pytest.approx((0.0, 0.0), abs=1e-12)
    assert flip.wide.principal_point_shift_px == pytest.approx((0.0, 0.0), abs=1e-12)


def test_handheld_moves_the_rig_tripod_does_not() -> None:
    spec = IDEAL.with_effects(handheld=True)
    poses = [_state(spec, handheld=True, seed=k).T_world_device for k in range(300)]
    rot = np.rad2deg(np.array([p.rotvec for p in poses]))
    trans = np.array([p.t for p in poses]) * 1e3
    assert rot.std() == pytest.approx(0.3, rel=0.15)  # 0.3° per axis (1σ)
    assert trans.std() == pytest.approx(2.0, rel=0.15)  # 2 mm per axis (1σ)
    tripod = _state(spec, handheld=False, seed=3).T_world_device
    assert np.allclose(tripod.matrix, np.eye(4))


def test_distortion_and_principal_point_change_with_focus() -> None:
    spec = IDEAL.with_effects(distortion_vs_focus=True)
    st = _state(spec, focus=1.5)
    cal = calibration_rig(spec)
    travel_tele = fx.lens_travel_um(spec, "tele", st.tele.image_distance_m)
    assert travel_tele == pytest.approx(-163.4, abs=0.5)  # from 0.6 m to 1.5 m focus
    assert st.tele.principal_point_shift_px == pytest.approx(
        (0.002 * travel_tele, 0.003 * travel_tele), abs=1e-9
    )
    dk = np.subtract(st.wide.camera.lens.coefficients, cal.wide.lens.coefficients)
    assert np.abs(dk).max() > 1e-4  # the wide's distortion changes with lens position


def test_non_baseline_translation_switch() -> None:
    c_on = calibration_rig(IDEAL.with_effects(non_baseline_translation=True)).tele_center_in_wide
    c_off = calibration_rig(IDEAL).tele_center_in_wide
    assert c_on * 1e3 == pytest.approx([0.4, 12.0, 1.5], abs=1e-9)
    assert c_off * 1e3 == pytest.approx([0.0, 12.0, 0.0], abs=1e-9)


def test_factory_calibration_fits_an_even_model_to_the_odd_lens() -> None:
    true = calibration_rig(IDEAL.with_effects(odd_distortion=True))
    cal = factory_calibration(IDEAL.with_effects(odd_distortion=True), np.random.default_rng(0))
    assert cal.rig.wide.lens.name == "opencv5"
    # The even model cannot follow the odd terms: a residual of a few tenths of a pixel.
    residual = fit_residual_px(true.wide, cal.rig.wide)
    assert 0.05 < residual < 2.0
    # With the odd terms switched off the true lens is even and the fit is exact.
    even = calibration_rig(IDEAL)
    assert fit_residual_px(even.wide, fit_even_lens(even.wide, free_intrinsics=True)) < 1e-6
    exact = factory_calibration(IDEAL, np.random.default_rng(0))
    assert exact.covariance is None
    assert np.allclose(exact.rig.T_tele_wide.matrix, even.T_tele_wide.matrix, atol=1e-15)


def test_factory_noise_has_the_stated_sigma() -> None:
    spec = IDEAL.with_effects(factory_noise=True)
    exact = factory_calibration(IDEAL, np.random.default_rng(0)).rig
    cals = [factory_calibration(spec, np.random.default_rng(k)) for k in range(300)]
    dcx = np.array([c.rig.wide.cx - exact.wide.cx for c in cals])
    dc = np.array([c.rig.tele_center_in_wide - exact.tele_center_in_wide for c in cals]) * 1e3
    assert dcx.std() == pytest.approx(0.3, rel=0.15)
    assert dc.std(axis=0) == pytest.approx([0.05, 0.1, 0.3], rel=0.15)
    assert cals[0].std("wide.cx") == pytest.approx(0.3)
