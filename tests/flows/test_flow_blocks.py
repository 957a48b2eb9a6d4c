"""Blocks of the Phase 0 flows: majority, plane, coarse disparity, gates, corrector, focus fix."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.fixes.distortion import radial_geometry
from phonestereo.fixes.focus import ScaleOffset
from phonestereo.fixes.radial_residual import fit_capture_radial, pool_radial, radial_shift
from phonestereo.flows import application
from phonestereo.flows.coarse import coarse_disparity
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.corrector import Corrector
from phonestereo.flows.focus_stack import FocusCorrection
from phonestereo.flows.gates import capture_gates, first_failed
from phonestereo.flows.roi_disparity import fit_plane, majority, measure_roi
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.io import Calibration, CaptureEntry
from phonestereo.learning.observation import Observation


def _entry(**kw: object) -> CaptureEntry:
    base = {
        "id": "c0",
        "wide": "w.png",
        "tele": "t.png",
        "time_s": 600.0,
        "focus_mode": "manual",  # a locked focus (the manifest default is now "unknown")
        "gravity": (0.0, 1.0, 0.0),
        "kind": "verification",
        "roi": (900, 650, 200, 150),
    }
    base.update(kw)
    return CaptureEntry(**base)  # type: ignore[arg-type]


def _rig() -> Rig:
    wide = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    return Rig(wide, wide.scaled(3.0), Transform.from_rotvec([0, 0, 0], [0.0, -0.012, 0.0]))


def test_majority_picks_the_dominant_surface() -> None:
    rng = np.random.default_rng(0)
    d = np.concatenate([rng.normal(9.0, 0.05, 60), rng.normal(4.0, 0.05, 30)])
    v, mask = majority(d, bin_px=0.5, tol_px=0.5, tol_rel=0.0)
    # 60 matches on the near plane: its median, to its noise / √60 ≈ 0.01 px.
    assert abs(v - 9.0) < 0.03 and mask.sum() == 60


def test_plane_fit_recovers_a_slanted_plane_with_honest_sigma() -> None:
    rng = np.random.default_rng(1)
    xy = rng.uniform(0, 300, (200, 2))
    d_true = 10.0 + 0.01 * (xy[:, 0] - 150) - 0.005 * (xy[:, 1] - 150)
    d = d_true + rng.normal(0, 0.05, 200)
    d[:10] += 3.0  # mismatches
    p = fit_plane(xy, d, np.full(200, 0.05))
    pred, sig = p.predict([[150.0, 150.0]])
    # 0.05 px noise over 190 inliers: σ of the centre ≈ 0.05/√190 ≈ 0.004 px; 4σ.
    assert abs(pred[0] - 10.0) < 4 * sig[0] + 1e-3
    assert 0.002 < sig[0] < 0.01


def test_coarse_disparity_finds_the_shift_of_a_texture() -> None:
    rng = np.random.default_rng(2)
    import cv2

    left = cv2.GaussianBlur(rng.uniform(0, 255, (200, 300)).astype(np.float32), (0, 0), 2.0)
    shift = 12.3
    M = np.float32([[1, 0, -shift], [0, 1, 0]])
    right = cv2.warpAffine(left, M, (300, 200), flags=cv2.INTER_CUBIC)
    d, peak, second, e = coarse_disparity(left, right, (60, 40, 150, 120), 0, 40)
    # Whole-window ZNCC + parabola: a coarse start, ±0.3 px is all the fine search needs.
    assert abs(d - shift) < 0.3 and peak > 0.95 and second < peak and e == 0


def test_gates_name_what_failed() -> None:
    cold = first_failed(capture_gates(_entry(time_s=20.0), warmup_s=180.0))
    assert cold is not None and cold.name == "heated" and "cold" in cold.reason
    af = first_failed(capture_gates(_entry(focus_mode="auto"), warmup_s=180.0))
    assert af is not None and af.name == "fixed-focus"
    assert first_failed(capture_gates(_entry(), warmup_s=180.0)) is None


def _obs(n: int = 40, offset: float = -2.5, gain: float = 0.01) -> list[Observation]:
    rng = np.random.default_rng(3)
    out = []
    for i in range(n):
        x, y, d = rng.uniform(200, 500), rng.uniform(200, 600), rng.uniform(6, 20)
        c = offset + gain * d
        out.append(Observation(x, y, d, d + c, 1.5, "landscape", "g", 300.0 + i, None,
                               f"cap{i // 2}", "face-chart", 0.02))
    return out


def test_corrector_learns_offset_and_gain_and_keys_by_bucket() -> None:
    corr = Corrector(_obs(), FlowConfig())
    c = corr.correct([[350.0, 400.0, 4.5]], "landscape")
    # Noise-free offset + gain: the extrapolation to d = 4.5 px is exact to 1e-3 px.
    assert c.ok and abs(c.value_px[0] - (-2.5 + 0.045)) < 1e-3
    assert not corr.correct([[350.0, 400.0, 4.5]], "landscape-flipped").ok
    merged = Corrector(_obs(), FlowConfig(orientation_buckets=False))
    assert merged.correct([[350.0, 400.0, 9.0]], "portrait").ok


def test_application_gates_and_failures_are_results() -> None:
    cal = Calibration(_rig())
    img = np.full((1500, 2000), 128, np.uint8)
    cold = application.run(
        FlowConfig(), application.ApplicationInputs(cal, _entry(time_s=5.0), img, img)
    )
    assert not cold.ok and cold.gate == "heated" and np.isnan(cold.depth_m)
    empty = application.run(FlowConfig(), application.ApplicationInputs(cal, _entry(), img, img))
    assert not empty.ok and empty.gate == "learned" and "learn" in empty.reason
    cfg = FlowConfig(learned_correction=False)
    flat = application.run(cfg, application.ApplicationInputs(cal, _entry(), img, img))
    assert not flat.ok and flat.gate == "measure" and "texture" in flat.reason


def test_the_roi_search_reaches_where_a_positive_learned_correction_puts_far_points(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    """A far point reads d = −correction: the application lowers the searched far end by a
    positive typical correction (+6.3 px here: −2 → −8) and leaves a negative one's alone."""
    seen = []

    def measure(*args: object, **kw: object) -> object:
        seen.append(args[4])
        raise RuntimeError("stop")

    monkeypatch.setattr(application, "measure_roi", measure)
    cal = Calibration(_rig())
    img = np.zeros((1500, 2000), np.uint8)
    for offset, far in ((6.2, -8), (-2.5, -2)):
        corr = Corrector(_obs(offset=offset), FlowConfig())
        assert abs(corr.typical_px("landscape") - offset - 0.01 * 13) < 0.05  # + gain · d̄
        with pytest.raises(RuntimeError, match="stop"):
            application.run(FlowConfig(), application.ApplicationInputs(
                cal, _entry(), img, img, corrector=corr))
        assert seen[-1].far_disparity_px == far


def test_roi_outside_the_image_is_an_input_error() -> None:
    img = np.zeros((1500, 2000), np.uint8)
    with pytest.raises(Exception, match="not inside"):
        measure_roi(_rig(), img, img, (1950, 10, 100, 100))


def test_focus_correction_scales_the_cameras() -> None:
    rig = _rig()
    c = np.array([rig.tele.cx, rig.tele.cy])
    fc = FocusCorrection(ScaleOffset.identity([rig.wide.cx, rig.wide.cy]),
                         ScaleOffset(1.001, np.array([5.0, 0.0]), c))
    out = fc.apply(rig)
    # This attempt's tele is 1/1.001 of the median; the hand's offset is not applied.
    assert out.tele.fx == pytest.approx(rig.tele.fx / 1.001, rel=1e-12)
    assert out.tele.cx == rig.tele.cx and out.wide.fx == rig.wide.fx


def test_coarse_box_stays_inside_a_rotated_narrow_tele() -> None:
    """A diagonal baseline turns the rectified frame by 45°: the bounding box of a raw box
    then holds corners the tele never saw. The coarse box is shrunk into the raw box's outline
    and the tele's view over the whole disparity range."""
    from matplotlib.path import Path

    from phonestereo.flows.view_box import inscribed_box

    t = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    diamond = np.column_stack([500 + 200 * np.cos(t), 500 + 200 * np.sin(t)])  # a disc
    tele = np.array([[350.0, 350.0], [700.0, 350.0], [700.0, 700.0], [350.0, 700.0]])
    box = inscribed_box(diamond, tele, (-2.0, 40.0), (2000, 2000))
    assert box is not None
    x, y, w, h = box
    corners = np.array([[x, y], [x + w - 1, y], [x + w - 1, y + h - 1], [x, y + h - 1]], float)
    assert Path(diamond).contains_points(corners).all()
    for d in (-2.0, 40.0):  # the tele counterparts x − d at both ends of the range
        assert Path(tele).contains_points(corners - [d, 0.0], radius=1.0).all()
    # and not needlessly small: ≥ 60 % of the largest square in the disc (side 283 px) that
    # fits the tele's 350 − 42 px wide view
    assert min(w, h) >= 0.6 * min(283, 308)


def test_faces_carry_the_pooled_radial_fit_not_their_own() -> None:
    # The application takes the pooled fit out of a ROI; a face whose own capture's fit took
    # out another shift is re-referred to the pooled one, exactly (a re-referral, not a fit).
    rng = np.random.default_rng(1)
    q = rng.uniform(0.0, 1000.0, size=(400, 2))
    r, u = radial_geometry(q, (500.0, 500.0))
    fit = fit_capture_radial(q, u[:, 1] * 0.3 * (r / 500.0) ** 2, (500.0, 500.0))
    pooled = pool_radial([fit, fit])
    assert pooled is not None
    own = [0.2, -0.15, float("nan")]  # the third: a store before schema 5 (not recorded)
    obs = [Observation(x, 300.0, 10.0 - a if np.isfinite(a) else 10.0, 10.5, 1.8, "landscape",
                       "", 600.0, None, f"c{i}", radial_px=a)
           for i, (x, a) in enumerate(zip([900.0, 200.0, 700.0], own, strict=True))]
    corr = Corrector(obs, FlowConfig(), radial_fits=[fit, fit])
    want = 10.0 - radial_shift(pooled, [[900.0, 300.0], [200.0, 300.0]])[:, 0]
    got = corr.observations["d_measured_px"]
    assert np.allclose(got[:2], want, atol=1e-12) and got[2] == 10.0
    # with the fix off nothing is re-referred
    off = Corrector(obs, FlowConfig(radial_residual=False), radial_fits=[fit, fit])
    assert np.allclose(off.observations["d_measured_px"][:2], [9.8, 10.15], atol=1e-12)
