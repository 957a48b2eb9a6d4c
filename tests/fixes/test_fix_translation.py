"""Non-baseline translation (thesis §3.3): its effect on e and the canonical fix, on points."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.errors import InputError, ShapeError
from phonestereo.fixes.translation import (
    TranslationComponents,
    canonical_rectification,
    depth_agreement,
    fit_translation,
    predicted_nondisparity_px,
)
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.rectification import Rectification

WIDE = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
CENTER = np.array([0.0004, 0.012, 0.0015])  # folded ×3: baseline along device y


def _rig(center=CENTER) -> Rig:
    R = Transform.from_rotvec(np.deg2rad([0.25, -0.3, 0.4]), [0, 0, 0]).R
    return Rig(WIDE, WIDE.scaled(3.0), Transform(R, -R @ center))


def _two_depths(rig: Rig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    g = np.linspace(-0.08, 0.08, 9)
    xy = np.array([(x, y) for x in g for y in g])
    pts = [np.column_stack([xy * z / 1.0, np.full(len(xy), z)]) for z in (1.0, 2.0)]
    qw, qt = rig.project(np.concatenate(pts))
    return qw, qt, np.repeat(["near", "far"], len(xy))


def test_components_of_folded_rig() -> None:
    tc = TranslationComponents.from_rig(_rig())
    # quarter turn (x, y) → (y, −x): B = 12 mm, t_y = −0.4 mm, t_z = +1.5 mm
    assert tc.baseline_m == pytest.approx(0.012, abs=1e-9)
    assert tc.non_baseline_m == pytest.approx(-0.0004, abs=1e-9)
    assert tc.z_m == pytest.approx(0.0015, abs=1e-9)
    assert set(tc.to_dict()) == {"baseline_m", "non_baseline_m", "z_m", "tilt_deg"}


def test_rotation_only_depends_on_depth_canonical_does_not() -> None:
    rig = _rig()
    qw, qt, lab = _two_depths(rig)
    before = Rectification.from_rig(rig, "undistort-both")
    after = canonical_rectification(rig)
    assert after.mode == "canonical"
    _, e_b = before.disparity(qw, qt)
    _, e_a = after.disparity(qw, qt)
    ag_b, ag_a = depth_agreement(e_b, lab), depth_agreement(e_a, lab)
    # e ≈ f·t_y/Z − v·t_z/Z: the charts disagree by ~f·0.4 mm·(1 − 1/2) = 0.3 px (plus t_z·v)
    tc = TranslationComponents.from_rig(rig)
    qr = before.points_wide(qw)
    pred = predicted_nondisparity_px(tc, before.f_px, np.repeat([1.0, 2.0], 81),
                                     qr[:, 1] - before.wide_rect.cy)
    assert ag_b.spread_px == pytest.approx(depth_agreement(pred, lab).spread_px, rel=0.05)
    assert ag_b.spread_px > 0.25
    assert ag_a.spread_px < 1e-9  # exact with a perfect calibration


def test_fit_translation_recovers_ty_tz_from_e() -> None:
    rig = _rig()
    qw, qt, _ = _two_depths(rig)
    rect = Rectification.from_rig(rig, "undistort-both")
    d, e = rect.disparity(qw, qt)
    v = rect.points_wide(qw)[:, 1] - rect.wide_rect.cy
    fit = fit_translation(v, d, e, rect.f_px)
    assert fit.ok
    # first-order model: t_y within 2 µm, t_z within 30 µm of 0.4 / 1.5 mm
    assert fit.ty_over_b * 0.012 == pytest.approx(-0.0004, abs=2e-6)
    assert fit.tz_over_b * 0.012 == pytest.approx(0.0015, abs=3e-5)
    flat = fit_translation(v[:81], d[:81], e[:81], rect.f_px)
    assert not flat.ok and "one depth" in flat.reason
    assert flat.to_dict()["ty_over_b"] is None


def test_bad_input() -> None:
    with pytest.raises(ShapeError):
        fit_translation([0.0, 1.0], [1.0], [1.0, 2.0], 1500.0)
    with pytest.raises(InputError, match="f_px"):
        fit_translation([0.0], [1.0], [1.0], -1.0)
    with pytest.raises(ShapeError):
        depth_agreement([0.1, 0.2], ["a"])
    with pytest.raises(InputError):
        depth_agreement([np.nan], ["a"])
    assert not fit_translation([0.0], [1.0], [1.0], 1500.0).ok
