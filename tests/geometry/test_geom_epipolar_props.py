"""Epipolar algebra (eq. 5–9) against exact synthetic data and OpenCV as an independent reference.

Run ``pytest -s -p no:xdist tests/geometry/test_geom_epipolar_props.py`` to see the worst
errors and the conditioning table of eq. (9) for near-canonical rigs.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from phonestereo.geometry import (
    Camera,
    Rig,
    Transform,
    epipolar_residual,
    essential_scales,
    make_lens,
)

SETTINGS = settings(
    derandomize=True,
    max_examples=50,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)

WIDE = Camera(
    (2000, 1500),
    1500.0,
    1500.5,
    999.5,
    749.5,
    make_lens("opencv5", (-0.07, 0.02, 3e-4, -2e-4, -0.003)),
)
TELE = Camera(
    (2000, 1500),
    4500.0,
    4499.0,
    1003.2,
    747.9,
    make_lens("radial-odd", (0.011, -0.052, 0.031, 1e-4, -2e-4)),
)

_f = st.floats(-1.0, 1.0, allow_nan=False)


@st.composite
def rigs(draw: st.DrawFn, max_angle: float = 0.3) -> Rig:
    """Random rigs: rotation up to ``max_angle`` rad per axis, baseline 5 mm–10 cm.

    The baseline has a lateral part (|t_xy| ≥ 0.3·|t|) as in any stereo rig: pure forward
    motion makes the 8-point reference itself ill-conditioned on a narrow field.
    """
    rv = np.array([draw(_f), draw(_f), draw(_f)]) * max_angle
    d = np.array([draw(_f), draw(_f), draw(_f)])
    assume(np.linalg.norm(d) > 0.2 and np.hypot(d[0], d[1]) >= 0.3 * np.linalg.norm(d))
    b = draw(st.floats(0.005, 0.1))
    return Rig(WIDE, TELE, Transform.from_rotvec(rv, b * d / np.linalg.norm(d)))


def _points(rig: Rig, seed: int, n: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """Exact undistorted pixels (q_wide, q_tele) of 3-D points in front of both cameras.

    The points span ±0.9 in normalised coordinates in both cameras (inside both lenses' valid
    fields, beyond the tele's image): the projection maths holds there, and the wide field
    keeps OpenCV's estimators (the references) well conditioned.
    """
    rng = np.random.default_rng(seed)
    z = rng.uniform(0.3, 3.0, n)
    p = np.column_stack([rng.uniform(-0.9, 0.9, n) * z, rng.uniform(-0.9, 0.9, n) * z, z])
    p_t = rig.T_tele_wide.apply(p)
    keep = (p_t[:, 2] > 0.1) & (np.abs(p_t[:, :2] / p_t[:, 2:]).max(axis=1) < 0.9)
    assume(keep.sum() >= 20)
    qw, qt = rig.project(p[keep])
    # Undistorted pixels: K applied to the undistorted normalised coordinates (F acts on these).
    uw = rig.wide.normalized_to_pixel(rig.wide.pixel_to_normalized(qw))
    ut = rig.tele.normalized_to_pixel(rig.tele.pixel_to_normalized(qt))
    return uw, ut


def _line_distance(F: np.ndarray, uw: np.ndarray, ut: np.ndarray) -> np.ndarray:
    """Distance in tele pixels from q_tele to the epipolar line F·q̃_wide."""
    lines = np.column_stack([uw, np.ones(len(uw))]) @ F.T
    return np.abs(epipolar_residual(F, uw, ut)) / np.hypot(lines[:, 0], lines[:, 1])


def _unit(M: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """M scaled to unit Frobenius norm with the sign that best matches ``ref``."""
    m = M / np.linalg.norm(M)
    return m * np.sign(np.sum(m * ref))


def test_epipolar_constraint_and_opencv_references() -> None:
    worst = {"line_px": 0.0, "E": 0.0, "F": 0.0, "F_as_E": 0.0}

    @SETTINGS
    @given(rig=rigs(), seed=st.integers(0, 2**32 - 1))
    def check(rig: Rig, seed: int) -> None:
        uw, ut = _points(rig, seed)
        F = rig.fundamental()
        # Eq. (5) on exact undistorted pixels: distance to the epipolar line, tele pixels.
        d = float(np.max(_line_distance(F, uw, ut)))
        assert d <= 1e-8  # exact data: rounding only (undistortion is at ~1e-16 normalised)
        # E = [t]ₓR vs OpenCV's 5-point solver on exact normalised points (up to scale/sign).
        E = rig.essential() / np.linalg.norm(rig.essential())
        xw = np.column_stack([uw, np.ones(len(uw))]) @ np.linalg.inv(rig.wide.K).T
        xt = np.column_stack([ut, np.ones(len(ut))]) @ np.linalg.inv(rig.tele.K).T
        cv2.setRNGSeed(seed % 2**31)  # OpenCV's RANSAC draws from its global RNG
        E_cv, mask = cv2.findEssentialMat(
            xw[:, :2], xt[:, :2], np.eye(3), method=cv2.RANSAC, prob=0.999999, threshold=1e-8
        )
        assert E_cv is not None and E_cv.shape == (3, 3) and mask.all()
        e_err = float(np.max(np.abs(_unit(E_cv, E) - E)))
        # OpenCV's 5-point solver (E from one minimal sample) on exact data: median 6e-13,
        # max ~1e-6 (R = I is its worst case); a modelling error (Rᵀ for R, −t, swapped
        # cameras) is ≥ 1e-3 on these rigs.
        assert e_err <= 1e-5
        # F vs OpenCV's normalised 8-point on exact undistorted pixels (up to scale/sign).
        F_cv, _ = cv2.findFundamentalMat(uw, ut, cv2.FM_8POINT)
        Fn = F / np.linalg.norm(F)
        f_err = float(np.max(np.abs(_unit(F_cv, Fn) - Fn)))
        # Entries of F differ by ~f² in size; mapped back to E (eq. 7) every entry counts.
        E_from_cv = rig.tele.K.T @ F_cv @ rig.wide.K
        fe_err = float(np.max(np.abs(_unit(E_from_cv, E) - E)))
        # findFundamentalMat works on float32 copies of the points (checked: float32-rounded
        # input gives identical output), so exact data agrees only to ~1e-6 (max 2.6e-5 for
        # F, 3.5e-6 mapped to E over 386 random rigs); a modelling error would be ≥ 1e-3.
        assert f_err <= 1e-4 and fe_err <= 1e-5
        for k, v in (("line_px", d), ("E", e_err), ("F", f_err), ("F_as_E", fe_err)):
            worst[k] = max(worst[k], v)

    check()
    print(
        f"\nepipolar line distance max {worst['line_px']:.1e} px; vs OpenCV: E {worst['E']:.1e}, "
        f"F {worst['F']:.1e}, F mapped to E {worst['F_as_E']:.1e} (unit-norm entries)"
    )


def _D(s: float) -> np.ndarray:
    return np.diag([1.0 / s, 1.0 / s, 1.0])


def test_essential_scales_recovers_random_scales() -> None:
    worst, degenerate = [0.0], [0, 0]

    @SETTINGS
    @given(
        rig=rigs(),
        s_w=st.floats(0.9, 1.1),
        s_t=st.floats(0.9, 1.1),
        A=st.floats(0.1, 10.0),
        sign=st.sampled_from([-1.0, 1.0]),
    )
    def check(rig: Rig, s_w: float, s_t: float, A: float, sign: float) -> None:
        E = rig.essential()
        E_cur = sign * A * _D(s_t) @ E @ _D(s_w)  # eq. (8)
        r = essential_scales(E, E_cur)
        degenerate[1] += 1
        if not np.isfinite(r.condition):
            # E.g. R = I with t ⟂ z: unidentifiable, and said so (NaN, never a wrong value).
            assert np.isnan([r.s_wide, r.s_tele, r.A]).all()
            degenerate[0] += 1
            return
        err = max(abs(r.s_wide / s_w - 1), abs(r.s_tele / s_t - 1))
        assert err <= 1e-6  # exact data (brief: 1e-6)
        assert np.sign(r.A) == sign and r.residual_rms < 1e-9
        worst[0] = max(worst[0], err)

    check()
    assert degenerate[0] <= 0.2 * degenerate[1]  # only special rigs are degenerate
    print(
        f"\nessential_scales max relative scale error {worst[0]:.1e} (random rigs; "
        f"{degenerate[0]} of {degenerate[1]} degenerate, reported as ∞)"
    )


def test_essential_scales_from_refocused_cameras() -> None:
    """End to end: refocus scales each K (K′ = K·D(s), Camera.scaled); E′ from the nominal K."""
    T = Transform.from_rotvec([0.004, -0.003, 0.002], [0.0, -0.012, 0.0015])  # folded-x3-like
    rig = Rig(WIDE, TELE, T)
    for s_w, s_t in ((1.003, 0.996), (0.95, 1.04), (1.0, 1.0)):
        cur = rig.with_cameras(WIDE.scaled(s_w), TELE.scaled(s_t))
        E_cur = TELE.K.T @ cur.fundamental() @ WIDE.K  # what a nominal-K estimate gives
        r = essential_scales(rig.essential(), E_cur)
        assert r.s_wide == pytest.approx(s_w, rel=1e-9) and r.s_tele == pytest.approx(s_t, rel=1e-9)


def test_near_canonical_conditioning_grows_as_tz_vanishes() -> None:
    """Eq. (9) on R ≈ I, t = (B, 0, t_z): only t_z (or a rotation) separates the two scales.

    With R = I the 2×2 block of E is ±t_z and the rest ±B, so the condition number is ∝ B/t_z;
    below t_z = 1e-3·B the block falls under ``min_relative`` and the system is singular (∞).
    A rotation of 0.2° about x adds E₃₃ ≈ B·θ and caps the condition number.
    """
    B = 0.012
    tz_mm = [3.0, 1.5, 0.5, 0.1, 0.03, 0.013, 0.005, 0.0]
    rows = []
    for rot_deg in (0.0, 0.2):
        conds = []
        for tz in tz_mm:
            T = Transform.from_rotvec([np.radians(rot_deg), 0, 0], [B, 0.0, tz * 1e-3])
            E = Rig(WIDE, TELE, T).essential()
            r = essential_scales(E, _D(1.02) @ E @ _D(0.99))
            conds.append(r.condition)
            if np.isfinite(r.condition):
                # Exact data: still recovered while the system is (even badly) conditioned.
                assert r.s_tele == pytest.approx(1.02, rel=1e-6)
                assert r.s_wide == pytest.approx(0.99, rel=1e-6)
        rows.append(conds)
    c0 = np.array(rows[0])
    finite = np.isfinite(c0)
    assert np.all(np.diff(c0[finite]) > 0)  # grows monotonically as t_z shrinks
    assert np.all(~finite[tz_mm.index(0.005) :])  # t_z < 1e-3·B: unsolvable, reported as ∞
    # Small t_z: cond → 3/(√2·ε) with ε = t_z/B (σ_max = √3 from the ±B rows, σ_min = ε·√(2/3)
    # from the ±t_z rows along the null direction (1, 1, 1) of the others).
    small = (np.array(tz_mm) <= 0.5) & finite
    k = c0[small] * np.array(tz_mm)[small] * 1e-3 / B
    np.testing.assert_allclose(k, 3 / np.sqrt(2), rtol=0.01)
    assert rows[0][0] < 1e3  # a 3 mm Z offset is well conditioned
    assert np.all(np.isfinite(rows[1])) and max(rows[1]) < 1e3  # the rotation rescues it
    print("\nt_z (mm)  cond (R = I)  cond (0.2° about x)")
    for tz, a, b in zip(tz_mm, rows[0], rows[1], strict=True):
        print(f"{tz:8.3f}  {a:12.4g}  {b:12.4g}")
