"""Essential-matrix focus scales and the Figure 3-26 variants (thesis §3.5.3, eq. 8–9)."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.errors import InputError
from phonestereo.fixes.essential import (
    FocusScales,
    match_essential,
    match_rotation,
    match_rotation_keep_translation,
    scales_eq9,
)
from phonestereo.fixes.essential_compare import (
    StackAttempt,
    compare_variants,
    essential_from_points,
)
from phonestereo.geometry import Camera, Rig, Transform, essential_from_pose

WIDE = Camera((2000, 1500), 1500.0, 1500.0, 1003.8, 746.4)
TELE = Camera((2000, 1500), 4500.0, 4500.0, 993.3, 754.9)
R0 = Transform.from_rotvec(np.deg2rad([0.25, -0.3, 0.4]), np.zeros(3)).R
C_TELE = np.array([0.4, 12.0, 1.5]) * 1e-3  # folded-x3: baseline along y, t_z = 1.5 mm
RIG = Rig(WIDE, TELE, Transform(R0, -R0 @ C_TELE))


def _depth_scene(rng: np.random.Generator, n: int = 300) -> np.ndarray:
    """Points at 1–4 m filling the tele's view (the thesis's simulated depth scene)."""
    z = rng.uniform(1.0, 4.0, n)
    return np.c_[rng.uniform(-0.12, 0.12, n) * z, rng.uniform(-0.09, 0.09, n) * z, z]


def _capture(
    points: np.ndarray,
    s_wide: float,
    s_tele: float,
    *,
    motion: Transform | None = None,
    noise: float = 0.0,
    rng: np.random.Generator | None = None,
    shift: tuple[float, float, float, float] = (0, 0, 0, 0),
) -> tuple[np.ndarray, np.ndarray]:
    p = points if motion is None else motion.apply(points)
    true = Rig(WIDE.scaled(s_wide).shifted(*shift[:2]), TELE.scaled(s_tele).shifted(*shift[2:]),
               RIG.T_tele_wide)
    qw, qt = true.project(p)
    if noise and rng is not None:
        qw = qw + rng.normal(0, noise, qw.shape)
        qt = qt + rng.normal(0, noise, qt.shape)
    return qw, qt


def test_thesis_simulation_scales_recovered_exactly() -> None:
    """Figures 3-22/3-23: both cameras moved by one random rigid motion, wide scaled by 1.0518,
    tele by 0.91532, E estimated with the nominal K: eq. 9 gives the scales back."""
    rng = np.random.default_rng(0)
    pts = _depth_scene(rng)
    motion = Transform.from_rotvec(rng.normal(size=3) * 0.05, rng.normal(size=3) * 0.05)
    e0 = essential_from_points(*_capture(pts, 1.0, 1.0), RIG)
    e1 = essential_from_points(*_capture(pts, 1.0518, 0.91532, motion=motion), RIG)
    assert e0.method == e1.method == "8-point"
    # acceptance: within 1e-4 (measured ~1e-12: exact projections)
    for r in (scales_eq9(e0.E, e1.E), match_essential(e0.E, e1.E, WIDE.f, TELE.f)):
        assert r.ok and abs(r.s_wide - 1.0518) < 1e-4 and abs(r.s_tele - 0.91532) < 1e-4, r
        assert r.condition < 100  # t_z = 1.5 mm and t_x = 0.4 mm make eq. 9 solvable
    om = match_rotation(e0.R, e0.t, e1.E, WIDE.f, TELE.f)
    assert abs(om.s_wide - 1.0518) < 1e-4 and abs(om.s_tele - 0.91532) < 1e-4  # measured 2e-6
    # against the calibration directly (E of the rig) the same holds
    r = scales_eq9(RIG.essential(), e1.E)
    assert abs(r.s_wide - 1.0518) < 1e-4 and abs(r.s_tele - 0.91532) < 1e-4


def test_keep_translation_variant_is_not_exact() -> None:
    """OmT keeps the uncorrected attempt's translation direction, which a scale change moves:
    it cannot recover the scales even on exact data (why it ranks low in Figure 3-26)."""
    rng = np.random.default_rng(0)
    pts = _depth_scene(rng)
    e0 = essential_from_points(*_capture(pts, 1.0, 1.0), RIG)
    e1 = essential_from_points(*_capture(pts, 1.0518, 0.91532), RIG)
    r = match_rotation_keep_translation(e0.R, e0.t, e1.E, WIDE.f, TELE.f)
    assert abs(r.s_wide - 1.0518) > 1e-3 or abs(r.s_tele - 0.91532) > 1e-3


def test_conditioning_is_reported() -> None:
    """A canonical rig (R = I, t along the baseline only) leaves eq. 9 unsolvable: E₃₃, the
    2×2 block and half the border are 0 (the warning of docs/equations.md)."""
    E = essential_from_pose(np.eye(3), [0.0, -0.012, 0.0])
    D = np.diag([1 / 1.01, 1 / 1.01, 1.0])
    r = scales_eq9(E, D @ E @ D)
    assert not r.ok and "condition" in r.reason and np.isnan(r.s_wide)
    rng = np.random.default_rng(1)
    pts = _depth_scene(rng)
    e0 = essential_from_points(*_capture(pts, 1.0, 1.0), RIG)
    e1 = essential_from_points(*_capture(pts, 1.001, 0.999, shift=(0.5, 0, 0, -0.5)), RIG)
    with_off = match_essential(e0.E, e1.E, WIDE.f, TELE.f, with_offset=True)
    # an offset along each epipole direction does not change E: 2 of 6 unknowns not separable
    assert with_off.condition == float("inf")
    assert with_off.label == "EAndOffset"


def test_corrections_map_into_the_reference_geometry() -> None:
    s = FocusScales("E", True, 1.002, 0.997, (0.4, -0.2), (-1.0, 0.5), 1.0, 0.0)
    rng = np.random.default_rng(2)
    pts = _depth_scene(rng, 50)
    qw0, qt0 = _capture(pts, 1.0, 1.0)
    qw1, qt1 = _capture(pts, 1.002, 0.997, shift=(0.4, -0.2, -1.0, 0.5))
    cw, ct = s.corrections(RIG)
    np.testing.assert_allclose(cw.apply(qw1), qw0, atol=1e-9)  # pinhole: exact
    np.testing.assert_allclose(ct.apply(qt1), qt0, atol=1e-9)
    bad = FocusScales("E", False, np.nan, np.nan, (0, 0), (0, 0), np.inf, np.nan, False, "x")
    assert bad.corrections(RIG)[0].scale == 1.0  # a failed result corrects nothing


def _stack(rng, pts, n=5, noise=0.0, scene="depth"):
    ids = np.c_[np.arange(len(pts)), np.zeros(len(pts), np.int64)]
    atts, true = [], []
    for k in range(n):
        sw, st = 1 + rng.normal() * 2e-4, 1 + rng.normal() * 8e-4  # manual-focus noise (§3.5.3)
        qw, qt = _capture(pts, sw, st, noise=noise, rng=rng)
        atts.append(StackAttempt(f"{scene}{k}", ids, qw, qt))
        true.append((sw, st))
    return atts, np.array(true)


def test_compare_variants_exact_stack() -> None:
    """Only focal scales change: the E methods against the calibration are exact, and so is
    the same-camera normalisation."""
    rng = np.random.default_rng(4)
    atts, true = _stack(rng, _depth_scene(rng))
    cmp = compare_variants(atts, RIG)
    none = cmp.row("none").median_range_px
    assert none > 0.02  # 8e-4 tele scale noise: ~0.04 px median range (in wide pixels)
    for label in ("calib eq9", "calib E", "focus eq9", "focus E"):
        row = cmp.row(label)
        assert row.attempts_ok == 5 and row.median_range_px < 1e-5, label  # exact data
    got = np.array([[a.s_wide, a.s_tele] for a in cmp.row("calib E").per_attempt])
    np.testing.assert_allclose(got, true, atol=1e-6)
    assert cmp.row("focus opt").median_range_px < 1e-3
    assert set(cmp.ranking[:2]) <= {"calib eq9", "calib E", "focus eq9", "focus E", "focus opt"}
    assert len(cmp.rows) == 2 + 2 * 7  # none, opt, and per reference eq9 + 3 variants × 2


def test_compare_variants_noisy_stack_ranks_optimal_first() -> None:
    """Corner noise 0.02 px (the chart ruler's): the E methods fall apart, the same-camera
    normalisation does not — the thesis's Figure 3-26 conclusion, reproduced honestly."""
    rng = np.random.default_rng(5)
    atts, _ = _stack(rng, _depth_scene(rng), noise=0.02)
    cmp = compare_variants(atts, RIG)
    assert cmp.ranking[0] == "focus opt"
    opt, none = cmp.row("focus opt").median_range_px, cmp.row("none").median_range_px
    assert opt < 0.5 * none
    assert cmp.row("calib eq9").median_range_px > none  # measured 2.4 px vs 0.18 px
    d = cmp.row("calib E").to_dict()
    assert d["attempts_ok"] == 5 and len(d["per_attempt"]) == 5


def test_planar_scene_uses_the_homography() -> None:
    rng = np.random.default_rng(6)
    xy = rng.uniform(-0.2, 0.2, (200, 2))
    pts = np.c_[xy, np.full(200, 1.5)]  # a fronto-parallel chart at 1.5 m
    est = essential_from_points(*_capture(pts, 1.0, 1.0), RIG)
    assert est.method == "homography" and est.plane_rms_px < 1e-4
    # the calibrated pose comes back from the plane (exact data)
    assert np.degrees(np.arccos(np.clip((np.trace(est.R @ R0.T) - 1) / 2, -1, 1))) < 1e-4
    t = RIG.T_tele_wide.t / np.linalg.norm(RIG.T_tele_wide.t)
    assert float(est.t @ t) > 0.9999


def test_input_errors() -> None:
    rng = np.random.default_rng(7)
    atts, _ = _stack(rng, _depth_scene(rng, 40), n=2)
    with pytest.raises(InputError, match=">= 2 attempts"):
        compare_variants(atts[:1], RIG)
    with pytest.raises(InputError, match="unknown reference/variant"):
        compare_variants(atts, RIG, variants=("E", "F"))
    few = [StackAttempt(a.id, a.ids[:5], a.q_wide[:5], a.q_tele[:5]) for a in atts]
    with pytest.raises(InputError, match="seen in every attempt"):
        compare_variants(few, RIG)
    est = essential_from_points(atts[0].q_wide[:5], atts[0].q_tele[:5], RIG)
    assert not est.ok and "needs >= 8" in est.reason
    with pytest.raises(InputError, match="no method"):
        compare_variants(atts, RIG, references=("calib",), variants=("eq9",)).row("focus E")
