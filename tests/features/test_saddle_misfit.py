"""The corner σ on processed images: the saddle fit's odd misfit (features/saddle_misfit.py).

Before it, a corner's σ came from the image noise alone. On a phone ISP's JPEG it was 16–35×
too small (the denoiser leaves almost no noise to see, while demosaicing, sharpening and JPEG
displace each corner by a few hundredths of a pixel), and on the OpenCV sample's JPEGs it read
0.002 px per coordinate.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import erf

from phonestereo.charts.verification import Chessboard, VerificationChart
from phonestereo.features.chessboard import find_chessboard
from phonestereo.features.noise_level import NoiseLevel
from phonestereo.features.saddle import refine_saddle
from phonestereo.features.saddle_misfit import misfit_variance, white_noise_odd_m2
from phonestereo.features.verification import detect_verification_chart
from phonestereo.geometry import Camera, Transform
from phonestereo.sim.isp import IspSpec, gray_of_file, isp_file
from phonestereo.sim.module import load_module
from phonestereo.sim.render import render_view
from phonestereo.sim.scene import PlanarObject, Scene, facing_pose
from phonestereo.sim.sensor import SensorModel


def _corner_grid(noise: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """A 400 × 400 blurred chessboard (30 px squares, point-symmetric corners) + white noise,
    and its 81 true corners."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:400, 0:400].astype(float)
    ox, oy = rng.uniform(0, 1, 2)

    def edge(t: np.ndarray) -> np.ndarray:  # odd about every multiple of 30 px, 1 px blur
        return np.asarray(erf(np.sin(np.pi * t / 30) * 30 / np.pi / np.sqrt(2)))

    img = 128 + 100 * edge(xx - 200 - ox) * edge(yy - 200 - oy)
    img += rng.normal(0.0, noise, img.shape)
    k = np.arange(-4, 5) * 30.0
    gx, gy = np.meshgrid(k, k)
    return img, np.column_stack([200 + ox + gx.ravel(), 200 + oy + gy.ravel()])


def test_white_noise_keeps_the_noise_sigma() -> None:
    # an ideal corner with white noise: the misfit reads ≈ 0.9 of the noise variance (the
    # median of a skewed spread), so max(noise, misfit) leaves σ as the noise gives it
    ratios, z = [], []
    for seed in range(4):
        img, truth = _corner_grid(2.0, seed)
        res = refine_saddle(img, truth + 0.3, radius_px=6.0, noise=NoiseLevel(4.0, 0.0))
        assert res.ok.all()
        ratios.append(res.misfit_var / 4.0)
        z.append((res.points - truth) / res.sigma_px[:, None])
    assert 0.7 < float(np.median(ratios)) < 1.0, ratios
    rms_z = float(np.sqrt(np.mean(np.concatenate(z) ** 2)))
    assert 0.85 < rms_z < 1.15, rms_z  # 324 corners: known to ~6 %; measured 1.074 either way


def test_a_noise_free_ideal_corner_has_almost_no_misfit() -> None:
    img, truth = _corner_grid(0.0, 0)
    res = refine_saddle(img, truth + 0.3, radius_px=6.0, noise=NoiseLevel(4.0, 0.0))
    assert res.misfit_var < 0.1  # DN²: the spline's own error, against 4 DN² of noise above


def test_white_noise_reference_is_cached_and_scales_with_the_blur() -> None:
    a = white_noise_odd_m2(6.0, 1.5)
    assert white_noise_odd_m2(6.0, 1.5) == a  # cached: the same number
    # a blur averages the noise: its odd residual per unit pixel variance falls
    assert white_noise_odd_m2(6.0, 0.0) > 5 * a > 0
    assert misfit_variance(np.zeros((20, 20)), np.zeros((0, 2)), 6.0, 1.5) == 0.0


def _through_the_isp(radiance: np.ndarray, camera: str, seed: int) -> np.ndarray:
    """A radiance image (0–1) through ``folded-x3``'s phone ISP of ``camera``: the grey JPEG."""
    spec = getattr(load_module("folded-x3"), camera)
    data, _ = isp_file(radiance, IspSpec(**spec.isp.model_dump()), SensorModel(),
                       np.random.default_rng(seed))
    return gray_of_file(data)


def _view(chart: object, f: float, dist: float, tilt: tuple[float, float, float]) -> tuple:
    cam = Camera((1000, 750), f, f, 499.5, 374.5)
    T = facing_pose(chart.size_m, dist, tilt_rad=tilt)  # type: ignore[attr-defined]
    scene = Scene((PlanarObject(chart, T, "chart"),), background=0.5)  # type: ignore[arg-type]
    rad = render_view(cam, Transform.identity(), scene).radiance
    uv = chart.corners_uv()  # type: ignore[attr-defined]
    return rad, cam.project(T.apply(np.c_[uv, np.zeros(len(uv))]))


@pytest.mark.parametrize("camera", ["wide", "tele"])
def test_chessboard_sigma_is_honest_on_phone_isp_jpegs(camera: str) -> None:
    # RMS z, noise-only σ → with the misfit: here (two tilted boards, 216 corners) 23.0 → 0.87
    # (wide ISP) and 83.4 → 1.03 (tele ISP); on folded-x3's calibration renders 19.4 → 1.05 and
    # 37.5 → 0.97. The band allows the ±15 % a 216-corner RMS z has with correlated corners.
    z = []
    for seed, tilt in enumerate([(0.3, 0.2, 0.1), (-0.25, 0.35, -0.2)]):
        board = Chessboard((12, 9), square_m=0.02, margin_m=0.02)
        rad, truth = _view(board, 1400.0, 0.55, tilt)
        det = find_chessboard(_through_the_isp(rad, camera, seed), board.pattern)
        assert det.found, det.reason
        z.append((det.points - truth[det.ids]) / det.sigma_px[:, None])
    rms = float(np.sqrt(np.mean(np.concatenate(z) ** 2)))
    assert 0.7 < rms < 1.4, rms


def test_verification_chart_sigma_is_honest_on_a_phone_isp_jpeg() -> None:
    chart = VerificationChart()
    rad, truth = _view(chart, 750.0, 1.0, (0.25, 0.35, 0.1))
    det = detect_verification_chart(_through_the_isp(rad, "wide", 0))
    assert det.found, det.reason
    err = det.points - truth[det.ids[:, 0] * chart.pattern[0] + det.ids[:, 1]]
    z = err / det.sigma_px[:, None]
    rms = float(np.sqrt(np.mean(z**2)))
    # measured: 1040 corners, error 0.040 px RMS per coordinate; σ median 0.0014 px from the
    # noise alone (RMS z 30.1), 0.0374 px with the misfit (RMS z 1.06)
    assert len(z) > 800 and 0.7 < rms < 1.4, rms
