"""Point rectification in the three modes on the virtual module's true rigs (issue #4, part 1).

The sim is used read-only, for the true rigs only; the points are projected here with a Rig.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from phonestereo.errors import InputError, PhysicsError, ShapeError
from phonestereo.geometry import Camera, Rig, Transform, make_lens
from phonestereo.rectification import (
    MODES,
    Rectification,
    RectifyOptions,
    canonical_rotation,
    quarter_turn,
    quarter_turn_camera,
)
from phonestereo.sim.capture import calibration_rig
from phonestereo.sim.module import load_module

PRESETS = ("folded-x3", "nonfolded-x2")
EXACT = 1e-9  # px: the chains are closed-form plus Newton undistortion at rounding level


def true_rig(name: str, non_baseline_translation: bool = True) -> Rig:
    spec = load_module(name).with_effects(non_baseline_translation=non_baseline_translation)
    return calibration_rig(spec)


def scene_points(rig: Rig, n: int = 1500, z_range=(0.5, 5.0), seed: int = 0):
    """Wide-frame points seen by the tele (depth along the tele axis in z_range), and Z."""
    rng = np.random.default_rng(seed)
    q = rng.uniform([20, 20], [rig.tele.width - 20, rig.tele.height - 20], (n, 2))
    z = rng.uniform(*z_range, n)
    p_tele = rig.tele.unproject(q) * z[:, None]
    return rig.T_tele_wide.inverse().apply(p_tele)


@pytest.mark.parametrize("name", PRESETS)
def test_canonical_e_is_zero_at_every_depth(name: str) -> None:
    """§3.3: with the true calibration, t_y and t_z included, e ≡ 0 and Z = f·B/d exactly."""
    rig = true_rig(name)
    rect = Rectification.from_rig(rig, "canonical")
    P = scene_points(rig)
    d, e = rect.disparity(*rig.project(P))
    assert np.all(np.isfinite(e))
    assert np.max(np.abs(e)) <= EXACT  # acceptance: |e| ≤ 0.01 px
    z_rect = (P @ rect.R_rect_wide.T)[:, 2]
    np.testing.assert_allclose(rect.depth(d), z_rect, rtol=1e-10)
    q_rect = rect.points_wide(rig.project(P)[0])
    np.testing.assert_allclose(rect.backproject(q_rect, d), P, atol=1e-10)  # metres
    assert rect.baseline_m == pytest.approx(rig.baseline_m, rel=1e-12)  # the full |t|


@pytest.mark.parametrize("mode", ["undistort-both", "tele-to-wide"])
def test_rotation_only_modes_leave_depth_dependent_e(mode: str) -> None:
    """§3.3: without the canonical rotation, t_y and t_z make e depend on depth."""
    rig = true_rig("folded-x3")
    rect = Rectification.from_rig(rig, mode)
    near, far = scene_points(rig, 400, (0.5, 0.6), 1), scene_points(rig, 400, (4.0, 5.0), 2)
    e_near = np.median(rect.disparity(*rig.project(near))[1])
    e_far = np.median(rect.disparity(*rig.project(far))[1])
    # folded-x3: c_rect ≈ (12, −0.4, 1.5) mm → f·c_y/Z ≈ 1510·0.4e-3/0.55 ≈ 1.1 px near, 0.1 far
    assert abs(e_near - e_far) > 0.5
    if mode == "undistort-both":  # pinhole: the offset is exactly the translation parallax
        P = scene_points(rig, 300, seed=3)
        _, e = rect.disparity(*rig.project(P))
        pr = P @ rect.R_rect_wide.T
        c = rect.tele_center_rect
        f = rect.f_px
        expected = f * (pr[:, 1] / pr[:, 2] - (pr[:, 1] - c[1]) / (pr[:, 2] - c[2]))
        np.testing.assert_allclose(e, expected, atol=EXACT)


@pytest.mark.parametrize("name", PRESETS)
def test_rotation_only_modes_exact_without_non_baseline_translation(name: str) -> None:
    rig = true_rig(name, non_baseline_translation=False)
    P = scene_points(rig)
    for mode in ("undistort-both", "canonical"):
        _, e = Rectification.from_rig(rig, mode).disparity(*rig.project(P))
        assert np.max(np.abs(e)) <= EXACT, mode  # acceptance: |e| ≤ 0.01 px


def test_tele_to_wide_keeps_the_wide_distortion_mismatch() -> None:
    """§3.2 issue 1: tele-to-wide resamples the tele into the wide's distortion, so a point is
    distorted at two different radii; e ≠ 0 even for a perfect rig, 0 with a pinhole wide."""
    rig = true_rig("folded-x3", non_baseline_translation=False)
    P = scene_points(rig)
    _, e = Rectification.from_rig(rig, "tele-to-wide").disparity(*rig.project(P))
    # folded-x3's odd-order wide lens: measured max 0.13 px, median 0.008 px at 0.5–5 m.
    assert 0.05 < np.max(np.abs(e)) < 0.3
    far = scene_points(rig, z_range=(1000.0, 2000.0))
    _, e_far = Rectification.from_rig(rig, "tele-to-wide").disparity(*rig.project(far))
    assert np.max(np.abs(e_far)) < 1e-3  # vanishes with the disparity
    pinhole = rig.with_cameras(wide=rig.wide.with_lens(make_lens("opencv5")))
    _, e0 = Rectification.from_rig(pinhole, "tele-to-wide").disparity(*pinhole.project(P))
    assert np.max(np.abs(e0)) <= EXACT


@pytest.mark.parametrize("name", PRESETS)
def test_tele_to_wide_points_are_the_wide_camera_at_the_tele_centre(name: str) -> None:
    rig = true_rig(name)
    rect = Rectification.from_rig(rig, "tele-to-wide")
    P = scene_points(rig, 300)
    qw, qt = rig.project(P)
    c = rig.tele_center_in_wide
    expected = rect.tele_rect.project((P - c) @ rect.R_rect_wide.T)
    np.testing.assert_allclose(rect.points_tele(qt), expected, atol=EXACT)
    # The wide is only cropped (and quarter-turned): a constant integer shift of the turned pixel.
    turned = quarter_turn_camera(rig.wide, rect.quarter_turns)
    shift = rect.points_wide(qw) - turned.project(P @ quarter_turn(rect.quarter_turns).T)
    np.testing.assert_allclose(shift, np.broadcast_to(shift[0], shift.shape), atol=EXACT)
    assert np.allclose(shift[0], np.round(shift[0]), atol=EXACT)


@pytest.mark.parametrize("name", PRESETS)
@pytest.mark.parametrize("mode", MODES)
def test_disparity_positive_in_front_and_orientation(name: str, mode: str) -> None:
    rig = true_rig(name)
    rect = Rectification.from_rig(rig, mode)
    d, _ = rect.disparity(*rig.project(scene_points(rig, 300)))
    assert np.all(d > 0)  # docs/conventions.md: d = x_wide − x_tele > 0 in front
    assert rect.tele_center_rect[0] > 0
    w, h = rect.wide_rect.size
    if name == "folded-x3":  # vertical baseline: turned by 90°, portrait rectified images
        assert rect.quarter_turns == 1 and h > w
    else:
        assert rect.quarter_turns == 0 and w > h


@pytest.mark.parametrize("mode", MODES)
def test_inverse_maps_round_trip(mode: str) -> None:
    rig = true_rig("folded-x3")
    rect = Rectification.from_rig(rig, mode)
    q = np.random.default_rng(4).uniform([0, 0], [1999, 1499], (500, 2))
    np.testing.assert_allclose(rect.unrectify_tele(rect.points_tele(q)), q, atol=1e-8)
    inside = q[np.hypot(q[:, 0] - 1000, q[:, 1] - 750) < 600]
    np.testing.assert_allclose(rect.unrectify_wide(rect.points_wide(inside)), inside, atol=1e-8)


def test_tele_resolution_keeps_depth() -> None:
    rig = true_rig("folded-x3")
    low = Rectification.from_rig(rig, "canonical")
    full = Rectification.from_rig(rig, "canonical", RectifyOptions(resolution="tele"))
    assert full.f_px == pytest.approx(rig.tele.f) and low.f_px == pytest.approx(rig.wide.f)
    # The full-resolution window is the tele's view at the tele's scale: ≈ the tele image.
    assert abs(full.wide_rect.size[1] - rig.tele.width) < 0.1 * rig.tele.width
    P = scene_points(rig, 200)
    d_low, _ = low.disparity(*rig.project(P))
    d_full, _ = full.disparity(*rig.project(P))
    np.testing.assert_allclose(d_full / d_low, rig.zoom, rtol=1e-10)
    np.testing.assert_allclose(full.depth(d_full), low.depth(d_low), rtol=1e-10)


@pytest.mark.parametrize("model", ["opencv5", "opencv8", "radial-odd"])
@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_quarter_turned_camera_is_pixel_exact(model: str, k: int) -> None:
    coeffs = {
        "opencv5": [-0.1, 0.03, 1e-3, -2e-3, 0.01],
        "opencv8": [-0.1, 0.03, 1e-3, -2e-3, 0.01, 0.02, 0.0, 0.0],
        "radial-odd": [-0.03, 0.02, -0.06, 1e-3, -2e-3],
    }[model]
    cam = Camera((2000, 1500), 1500.0, 1510.0, 1003.8, 746.4, make_lens(model, coeffs))
    turned = quarter_turn_camera(cam, k)
    P = np.random.default_rng(k).uniform([-0.5, -0.4, 1.0], [0.5, 0.4, 2.0], (200, 3))
    q, qk = cam.project(P), turned.project(P @ quarter_turn(k).T)
    w, h = cam.size
    x, y = q[:, 0], q[:, 1]
    expected = [(x, y), (y, w - 1 - x), (w - 1 - x, h - 1 - y), (h - 1 - y, x)][k]
    np.testing.assert_allclose(qk, np.stack(expected, axis=-1), atol=1e-9)


def test_canonical_rotation_keeps_the_wide_axis_closest_to_z() -> None:
    c = np.array([0.0004, 0.012, 0.0015])
    R = canonical_rotation(c)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ c, [np.linalg.norm(c), 0, 0], atol=1e-15)
    # Any other rotation about the baseline tilts the wide axis further from z.
    for a in np.deg2rad([-20, -1, 1, 20]):
        ca, sa = np.cos(a), np.sin(a)
        spin = np.array([[1, 0, 0], [0, ca, -sa], [0, sa, ca]])
        assert (spin @ R)[2, 2] < R[2, 2]


def test_bad_inputs_raise_typed_errors() -> None:
    rig = true_rig("nonfolded-x2")
    with pytest.raises(InputError, match="unknown rectification mode"):
        Rectification.from_rig(rig, "stereoRectify")
    with pytest.raises(InputError, match="outside the 2000×1500 wide image"):
        Rectification.from_rig(rig, "canonical", RectifyOptions(roi=(1900, 100, 200, 100)))
    with pytest.raises(InputError, match="width and height must be > 0"):
        RectifyOptions(roi=(0, 0, 0, 10))
    with pytest.raises(PhysicsError, match="scale"):
        RectifyOptions(scale=0.0)
    with pytest.raises(InputError, match="resolution"):
        RectifyOptions(resolution="max")  # type: ignore[arg-type]
    along_axis = Rig(rig.wide, rig.tele, Transform(np.eye(3), [0.001, 0.0, -0.012]))
    with pytest.raises(PhysicsError, match="along the optical"):
        Rectification.from_rig(along_axis, "canonical")
    rect = Rectification.from_rig(rig, "canonical")
    with pytest.raises(ShapeError, match="same shape"):
        rect.disparity(np.zeros((3, 2)), np.zeros((4, 2)))


def test_roi_window_and_json_round_trip() -> None:
    rig = true_rig("nonfolded-x2")
    roi = (900, 600, 200, 150)
    rect = Rectification.from_rig(rig, "undistort-both", RectifyOptions(roi=roi, margin_px=3))
    corners = np.array([[900, 600], [1099, 749]], dtype=float)
    q = rect.points_wide(corners)
    w, h = rect.wide_rect.size
    assert np.all(q >= 2.5) and np.all(q <= [w - 3.5, h - 3.5])  # inside, margin kept
    data = json.loads(json.dumps(rect.to_dict()))
    again = Rectification.from_dict(data)
    assert again.wide_rect == rect.wide_rect and again.mode == rect.mode
    np.testing.assert_array_equal(again.R_rect_tele, rect.R_rect_tele)


def test_canonical_matches_opencv_stereo_rectify() -> None:
    """Reference: OpenCV's stereoRectify is also a full-baseline rectification; on an opencv5
    rig with a mis-calibrated tele both give the same e (rescaled to the wide's f), while
    OpenCV puts both cameras at the mean focal length (the ×2 tele downscaled by 1.33)."""
    cv2 = pytest.importorskip("cv2")
    lens_w = make_lens("opencv5", [-0.05, 0.03, 1e-4, -2e-4, 0.0])
    lens_t = make_lens("opencv5", [0.02, -0.1, -1e-4, 1e-4, 0.0])
    wide = Camera((2000, 1500), 1500.0, 1500.0, 1003.8, 746.4, lens_w)
    tele = Camera((2000, 1500), 3000.0, 3000.0, 995.2, 752.1, lens_t)
    T = Transform.from_rotvec([-0.0035, 0.0052, -0.0044], [-0.010, -0.0003, -0.0003])
    rig = Rig(wide, tele, T)
    truth = rig.with_cameras(tele=tele.scaled(1.0005).shifted(0.4, -0.3))
    qw, qt = truth.project(scene_points(truth, 1000))
    _, e = Rectification.from_rig(rig, "canonical").disparity(qw, qt)
    dist = [np.asarray(c.lens.coefficients) for c in (wide, tele)]
    R1, R2, P1, P2 = cv2.stereoRectify(wide.K, dist[0], tele.K, dist[1], wide.size, T.R, T.t)[:4]
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-14)
    rw = cv2.undistortPointsIter(qw[:, None], wide.K, dist[0], R1, P1, crit)[:, 0]
    rt = cv2.undistortPointsIter(qt[:, None], tele.K, dist[1], R2, P2, crit)[:, 0]
    e_cv = (rw[:, 1] - rt[:, 1]) * wide.f / P1[0, 0]
    assert np.max(np.abs(e)) > 0.1  # the mis-calibration is visible...
    # ...and both agree to 2e-4 px (measured; they differ only in the small rotation about the
    # baseline that each picks).
    np.testing.assert_allclose(e, e_cv, atol=1e-3)
    assert P1[0, 0] == pytest.approx((wide.f + tele.f) / 2, rel=0.05)


def test_forced_size_and_scale() -> None:
    rig = true_rig("nonfolded-x2")
    base = Rectification.from_rig(rig, "canonical")
    half = Rectification.from_rig(rig, "canonical", RectifyOptions(scale=0.5, size=(320, 240)))
    assert half.wide_rect.size == (320, 240)
    assert half.f_px == pytest.approx(0.5 * base.f_px)
    # The forced window is centred on the shared view: the tele's centre pixel lands mid-image.
    centre = half.points_tele([[(rig.tele.width - 1) / 2, (rig.tele.height - 1) / 2]])[0]
    np.testing.assert_allclose(centre, [159.5, 119.5], atol=3.0)
