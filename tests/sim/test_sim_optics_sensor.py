"""Thin-lens optics (focus breathing, circle of confusion) and the sensor model of sim/."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phonestereo.errors import InputError, PhysicsError, ShapeError
from phonestereo.sim.optics import (
    coc_diameter_m,
    defocus_composite,
    defocus_sigma_function,
    defocus_sigma_px,
    focal_px,
    image_distance_m,
)
from phonestereo.sim.sensor import SensorModel, capture

F_WIDE, F_TELE, PITCH = 4.2e-3, 12.6e-3, 2.8e-6  # folded-x3 (docs/architecture.md)


# --- thin lens -------------------------------------------------------------------------------
def test_thin_lens_equation_holds() -> None:
    for s in (0.3, 0.6, 1.5, 4.0):
        v = image_distance_m(F_TELE, s)
        assert 1 / s + 1 / v == pytest.approx(1 / F_TELE, rel=1e-12)


def test_focus_breathing_magnitude() -> None:
    # Refocusing the tele from 0.6 m (factory) to 1.5 m shortens f_px by (v1.5 − v0.6) / v0.6:
    # about −1.3 %, the per-capture scale change that thesis §3.5 fights.
    ratio = focal_px(F_TELE, 1.5, PITCH) / focal_px(F_TELE, 0.6, PITCH)
    assert ratio - 1 == pytest.approx(F_TELE * (1 / 1.5 - 1 / 0.6) / (1 - F_TELE / 1.5), rel=1e-9)
    assert -0.014 < ratio - 1 < -0.012
    assert focal_px(F_WIDE, np.inf, PITCH) == pytest.approx(1500.0)


def test_circle_of_confusion() -> None:
    # In focus: no blur; the blur grows with |1/d − 1/s| and saturates at infinity.
    assert coc_diameter_m(F_TELE, 2.8, 1.5, 1.5) == pytest.approx(0.0, abs=1e-15)
    d = np.array([0.8, 1.0, 1.5, 3.0, np.inf])
    c = coc_diameter_m(F_TELE, 2.8, 1.5, d)
    aperture = F_TELE / 2.8
    expected = aperture * F_TELE * np.abs(1 / 1.5 - 1 / d) / (1 - F_TELE / 1.5)
    assert np.allclose(c, expected, rtol=1e-12)
    # Geometric check: the cone from the aperture to the image of d, cut at the sensor plane.
    v_s, v_d = image_distance_m(F_TELE, 1.5), image_distance_m(F_TELE, 0.8)
    assert c[0] == pytest.approx(aperture * abs(v_d - v_s) / v_d, rel=1e-12)
    assert c[-1] == pytest.approx(aperture * F_TELE / (1.5 - F_TELE), rel=1e-12)


def test_defocus_sigma_is_a_quarter_of_the_coc() -> None:
    # σ = CoC / 4: the per-axis standard deviation of a uniform disc of diameter CoC.
    c = coc_diameter_m(F_TELE, 2.8, 1.5, 3.0)
    assert defocus_sigma_px(F_TELE, 2.8, 1.5, 3.0, PITCH) == pytest.approx(c / 4 / PITCH)
    rng = np.random.default_rng(0)
    r, th = 0.5 * np.sqrt(rng.uniform(0, 1, 400_000)), rng.uniform(0, 2 * np.pi, 400_000)
    assert np.std(r * np.cos(th)) == pytest.approx(0.25, rel=0.01)  # unit disc → σ = 1/4
    sigma = defocus_sigma_function(F_WIDE, 1.8, 1.5, PITCH)
    assert sigma(2.0) == pytest.approx(defocus_sigma_px(F_WIDE, 1.8, 1.5, 2.0, PITCH))


@pytest.mark.parametrize(
    "call",
    [
        lambda: image_distance_m(F_TELE, F_TELE),  # focus at f: image at infinity
        lambda: image_distance_m(F_TELE, 0.005),  # inside the focal length
        lambda: image_distance_m(-1e-3, 1.0),
        lambda: focal_px(F_TELE, 1.0, -2.8e-6),
        lambda: coc_diameter_m(F_TELE, 0.0, 1.0, 2.0),
        lambda: coc_diameter_m(F_TELE, 2.8, 1.0, -2.0),
        lambda: defocus_sigma_function(F_TELE, 2.8, 1.0, 0.0),
    ],
)
def test_non_physical_optics_raise(call) -> None:
    with pytest.raises(PhysicsError):
        call()


def test_defocus_composite_conserves_light_and_orders_layers() -> None:
    a = np.zeros((5, 40), np.float32)
    a[:, 20:] = 1
    out = defocus_composite([(a.copy(), 0.9 * a, 2.0)], background=0.1)
    assert out.sum() == pytest.approx(5 * (20 * 0.1 + 20 * 0.9), rel=1e-5)
    assert out[2, 19] == pytest.approx(0.5 - 0.4 * 0.197, abs=0.01)  # Gaussian CDF at −0.5/2
    with pytest.raises(PhysicsError):
        defocus_composite([(a.copy(), a.copy(), -1.0)], 0.5)


# --- sensor -------------------------------------------------------------------------------------
@pytest.mark.parametrize("radiance", [0.1, 0.5, 0.9])
def test_flat_patch_mean_and_noise_match_the_model(radiance) -> None:
    s = SensorModel()
    img = capture(np.full((400, 500), radiance), np.random.default_rng(7), s)
    mean = s.expected_mean_dn(radiance)
    # Temporal noise: shot + read, then rounding adds a uniform ±½ DN (variance 1/12).
    std = np.sqrt(s.expected_std_dn(radiance) ** 2 + 1 / 12)
    assert img.mean() == pytest.approx(mean, rel=0.05)  # brief: within 5 %
    assert img.astype(float).std() == pytest.approx(std, rel=0.05)
    assert img.astype(float).mean() == pytest.approx(mean, abs=0.05)  # 200k px: ±0.005 DN


def test_noise_grows_as_sqrt_of_signal() -> None:
    s = SensorModel(read_noise_e=0.0, bit_depth=16)  # fine quantisation: the shot noise alone
    dark = capture(np.full((300, 300), 0.1), np.random.default_rng(1), s).astype(float)
    bright = capture(np.full((300, 300), 0.4), np.random.default_rng(1), s).astype(float)
    assert bright.std() / dark.std() == pytest.approx(2.0, rel=0.03)


def test_capture_is_deterministic_and_clean_when_asked() -> None:
    rad = np.random.default_rng(3).uniform(0, 1, (60, 80))
    a = capture(rad, np.random.default_rng(11))
    b = capture(rad, np.random.default_rng(11))
    assert a.dtype == np.uint8 and a.shape == (60, 80) and np.array_equal(a, b)
    assert not np.array_equal(a, capture(rad, np.random.default_rng(12)))
    clean = capture(rad, np.random.default_rng(0), noise=False)
    assert np.array_equal(clean, np.rint(rad * 0.8 * 255).astype(np.uint8))
    white = capture(np.full((4, 4), 2.0), np.random.default_rng(0), SensorModel(exposure=1.0))
    assert np.all(white == 255)  # clipped at the full well / white level


def test_black_level_bit_depth_and_jpeg() -> None:
    s10 = SensorModel(bit_depth=10, black_level_dn=64)
    img = capture(np.zeros((8, 8)), np.random.default_rng(0), s10, noise=False)
    assert img.dtype == np.uint16 and np.all(img == 64)
    rad = cv2.GaussianBlur(np.random.default_rng(5).uniform(0, 1, (64, 64)), (0, 0), 3)
    sj = SensorModel(jpeg_quality=90)
    j = capture(rad, np.random.default_rng(0), sj, noise=False)
    raw = capture(rad, np.random.default_rng(0), noise=False)
    assert j.dtype == np.uint8 and j.shape == raw.shape
    assert 0 < np.abs(j.astype(int) - raw).mean() < 1.5  # q90 on a smooth image: < 1.5 DN


@pytest.mark.parametrize(
    "kwargs, error",
    [
        ({"full_well_e": 0.0}, PhysicsError),
        ({"read_noise_e": -1.0}, PhysicsError),
        ({"bit_depth": 0}, InputError),
        ({"black_level_dn": 300.0}, PhysicsError),
        ({"jpeg_quality": 101}, InputError),
        ({"jpeg_quality": 90, "bit_depth": 12}, InputError),
    ],
)
def test_bad_sensor_parameters_raise(kwargs, error) -> None:
    with pytest.raises(error):
        SensorModel(**kwargs)


def test_capture_needs_a_2d_image() -> None:
    with pytest.raises(ShapeError):
        capture(np.zeros((4, 4, 3)), np.random.default_rng(0))
