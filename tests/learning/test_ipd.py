"""The IPD model: eq. 11 depth, exact ray geometry, the face-chart plane, priors and eq. 10."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phonestereo.errors import InputError, ShapeError
from phonestereo.geometry import Camera, make_lens
from phonestereo.learning.ipd import (
    IPD_M,
    IpdPrior,
    depth_from_ipd,
    error_bound,
    face_depth,
    fit_face_plane,
    population_scale,
    samples_needed,
)

CAM = Camera(
    (2000, 1500), 1500.0, 1500.0, 1003.0, 748.0, make_lens("opencv5", [-0.05, 0.02, 0.0, 0.0, 0.0])
)


def _eyes(mid: np.ndarray, axis: np.ndarray, ipd: float = IPD_M) -> np.ndarray:
    """Pupils (N, 2, 3) of segments of length ``ipd`` centred on ``mid`` along unit ``axis``."""
    return np.stack([mid - 0.5 * ipd * axis, mid + 0.5 * ipd * axis], axis=-2)


def test_eq11_values_and_errors() -> None:
    assert depth_from_ipd([94.5, 47.25, 31.5], 1500.0).tolist() == [1.0, 2.0, 3.0]
    assert np.isnan(depth_from_ipd(0.0, 1500.0))
    # δZ / Z = δIPD / IPD: 1 mm of a 63 mm IPD is 1.6 % of depth at every distance (§3.6)
    z = depth_from_ipd(47.25, 1500.0, IPD_M + 0.001)
    assert float(z) / 2.0 - 1 == pytest.approx(0.001 / IPD_M)
    with pytest.raises(InputError, match="f_px"):
        depth_from_ipd(47.0, -1.0)


@settings(max_examples=40, deadline=None)
@given(
    x=st.floats(-1.2, 1.2), y=st.floats(-0.5, 0.5), z=st.floats(0.8, 4.0),
    yaw=st.floats(-0.6, 0.6),
)
def test_face_depth_is_exact_for_a_turned_face_anywhere(
    x: float, y: float, z: float, yaw: float
) -> None:
    mid = np.array([x * z / 1.5, y * z / 1.5, z])  # within the field of view
    # "image": eye axis turned by yaw out of the image plane (eye 1 farther for yaw > 0)
    axis = np.array([np.cos(yaw), 0.0, np.sin(yaw)])
    q = CAM.project(_eyes(mid, axis))  # distorted pixels, as an image gives them
    assert face_depth(q, CAM, yaw_rad=yaw, relative_to="image") == pytest.approx(z, rel=1e-9)
    # "sight": turned by yaw from the plane perpendicular to the line of sight
    los = mid / np.linalg.norm(mid)
    e = np.cross([0.0, 1.0, 0.0], los)
    e /= np.linalg.norm(e)
    q = CAM.project(_eyes(mid, np.cos(yaw) * e + np.sin(yaw) * los))
    assert face_depth(q, CAM, yaw_rad=yaw) == pytest.approx(z, rel=1e-9)


def test_face_depth_shapes_and_errors() -> None:
    q = CAM.project(_eyes(np.array([[0.0, 0.0, 2.0], [0.3, 0.1, 2.5]]), np.array([1.0, 0, 0])))
    assert face_depth(q, CAM, relative_to="image").shape == (2,)
    with pytest.raises(ShapeError):
        face_depth(np.zeros((3, 2)), CAM)
    with pytest.raises(InputError, match="relative_to"):
        face_depth(q, CAM, relative_to="chart")  # type: ignore[arg-type]


def _chart(tilt_y_deg: float, tilt_x_deg: float, z0: float) -> tuple[np.ndarray, np.ndarray]:
    """A 4 × 2 face chart (pupils (8, 2, 3), depths (8,)) on a tilted plane."""
    ty, tx = np.deg2rad([tilt_y_deg, tilt_x_deg])
    u = np.array([np.cos(ty), 0.0, np.sin(ty)])
    v = np.array([0.0, np.cos(tx), np.sin(tx)])
    grid = [(a, b) for b in (-0.16, 0.16) for a in (-0.49, -0.16, 0.16, 0.49)]
    mids = np.array([[0.0, 0.0, z0] + a * u + b * v for a, b in grid])
    return _eyes(mids, u), mids[:, 2]


@pytest.mark.parametrize(("ty", "tx"), [(0.0, 0.0), (10.0, 0.0), (-8.0, 5.0)])
def test_face_plane_recovers_tilt_and_depths(ty: float, tx: float) -> None:
    eyes, z = _chart(ty, tx, 1.2)
    fit = fit_face_plane(CAM.project(eyes), CAM)
    assert np.allclose(fit.depth_m, z, rtol=2e-4)  # the tilt prior leaves < 0.02 %
    assert np.degrees(fit.tilt_rad) == pytest.approx(np.hypot(ty, tx), abs=0.2)
    assert fit.inliers.all() and fit.reason == ""


def test_face_plane_with_landmark_noise_and_one_bad_face() -> None:
    rng = np.random.default_rng(7)
    eyes, z = _chart(9.0, 2.0, 1.0)
    q = CAM.project(eyes) + rng.normal(0, 0.4, (8, 2, 2))  # 0.4 px per pupil (IPD ≈ 95 px)
    q[5, 1, 0] += 8.0  # one mis-located pupil: IPD 8 % too long
    fit = fit_face_plane(q, CAM)
    good = np.arange(8) != 5
    # 0.4 px per pupil is 0.6 % of IPD per face; the plane averages 7 good faces.
    assert np.max(np.abs(fit.depth_m[good] / z[good] - 1)) < 0.01
    assert not fit.inliers[5] and fit.inliers[good].all()
    # per-face eq. 11 ignores the 9° tilt: up to ~7 % at the chart's edge at 1 m
    per_face = face_depth(q, CAM, relative_to="image")
    assert np.max(np.abs(per_face[good] / z[good] - 1)) > 0.04


def test_face_plane_single_face_and_errors() -> None:
    eyes, z = _chart(0.0, 0.0, 2.0)
    fit = fit_face_plane(CAM.project(eyes[:1]), CAM)
    assert fit.depth_m[0] == pytest.approx(z[0], rel=1e-6) and "one face" in fit.reason
    with pytest.raises(InputError, match="at least one face"):
        fit_face_plane(np.zeros((0, 2, 2)), CAM)
    with pytest.raises(ShapeError):
        fit_face_plane(np.zeros((4, 2)), CAM)


def test_priors() -> None:
    pop = IpdPrior.population()
    assert pop.mean_m == pytest.approx(0.0625)
    # mixture variance = mean within-sex variance + between-sex spread (2.5 mm)²
    assert pop.sd_m == pytest.approx(np.sqrt(0.5 * (3.6**2 + 3.5**2) + 2.5**2) / 1000)
    assert IpdPrior.population(1.0).mean_m == pytest.approx(0.065)
    assert IpdPrior.dodgson().mean_m == IPD_M and IpdPrior.face_chart().sd_m == 0.0
    draws = pop.sample(200_000, np.random.default_rng(0))
    assert draws.mean() == pytest.approx(pop.mean_m, abs=2e-5)  # 3 σ/√n ≈ 3e-5 m
    assert draws.std() == pytest.approx(pop.sd_m, rel=0.01)
    with pytest.raises(InputError):
        IpdPrior(((1.0, 63.0, 3.5),))  # millimetres, not metres
    with pytest.raises(InputError):
        IpdPrior.population(1.5)


def test_sample_sizes_eq10() -> None:
    # Chebyshev: n ≥ σ²/(α ε²); normal: n ≥ (z σ/ε)²
    assert samples_needed(3.6, 1.0, 0.05) == 260  # 12.96 / 0.05 = 259.2
    assert samples_needed(3.6, 1.0, 0.05, "normal") == 50  # (1.96 · 3.6)² = 49.8
    assert samples_needed(3.5, 1.0, 0.01, "normal") == 82  # (2.576 · 3.5)² = 81.3
    n = np.array([1, 10, 100, 1000])
    assert np.allclose(error_bound(n, 3.6, 0.05), 3.6 / np.sqrt(0.05 * n))
    # the two functions invert each other
    for bound in ("chebyshev", "normal"):
        m = samples_needed(4.0, 0.5, 0.1, bound)
        assert error_bound(m, 4.0, 0.1, bound) <= 0.5 < error_bound(m - 1, 4.0, 0.1, bound)
    with pytest.raises(InputError, match="alpha"):
        samples_needed(3.6, 1.0, 1.0)
    with pytest.raises(InputError, match="bound"):
        samples_needed(3.6, 1.0, 0.05, "hoeffding")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="eps"):
        samples_needed(3.6, 0.0)


def test_population_scale_errors() -> None:
    with pytest.raises(InputError):
        population_scale([], IpdPrior.population())
    with pytest.raises(InputError):
        population_scale([0.06, -0.06], IpdPrior.population())
    est = population_scale([0.0625] * 10, IpdPrior.population(), bound="chebyshev")
    assert est.scale == pytest.approx(1.0) and est.n == 10
    assert est.bound_rel == pytest.approx(IpdPrior.population().sd_m / np.sqrt(0.5) / 0.0625)
    assert not est.converged(0.01) and est.converged(0.5)
