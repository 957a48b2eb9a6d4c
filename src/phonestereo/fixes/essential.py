"""Essential-matrix focus scales (thesis §3.5.3 option 2.b.2, eq. 8–9, Figures 3-22 to 3-26).

If a refocus changed only the focal lengths (K′ = K·D(s), D(s) = diag(s, s, 1)), the essential
matrix estimated with the nominal K would be E′ ∝ D(s_tele)⁻¹ E D(s_wide)⁻¹ (eq. 8), and the
per-camera scales would follow from a reference E and E′ alone (eq. 9,
:func:`~phonestereo.geometry.epipolar.essential_scales`). The thesis found this exact in
simulation (Figure 3-23: 1.0518 and 0.91532 recovered) and not in practice (Figure 3-24), and
tried the optimisation variants of Figure 3-26, each against the first attempt of the refocus
stack (``focus``) or against the calibration (``calib``), each with and without a
principal-point offset (``AndOffset``):

* ``eq9`` — the closed form of eq. 9 (the "naive essential fix" of Figure 3-24);
* ``E`` — :func:`match_essential`: scales (and offsets) making E′ equal the reference E up to
  scale;
* ``Om`` — :func:`match_rotation`: making the rotation decomposed from E′ equal the reference
  rotation;
* ``OmT`` — :func:`match_rotation_keep_translation`: the same while keeping the translation
  direction of the uncorrected attempt (after Figure 3-25: the optimal fix moved R, not t).

Conventions. ``s`` is the focal scale of the current state relative to the reference
(f_cur = s·f_ref, eq. 8's s) and ``o`` the principal-point shift (c_cur = c_ref + o), pixels.
The correction maps a current pixel into the reference geometry, ``q_ref = (q − c − o)/s + c``
(:meth:`FocusScales.corrections`). In normalised coordinates of the nominal K that is
x_ref = M x with M = [[1/s, 0, −o_x/(f s)], [0, 1/s, −o_y/(f s)], [0, 0, 1]], so the corrected
E is M_teleᵀ⁻¹ E′ M_wide⁻¹. The variants are solved by Gauss–Newton with minimum-norm steps
(parameters: 1000·ln s and o in pixels, so a unit is ~1 px at the image edge); the condition
number of the Jacobian at the solution is reported (∞: the data cannot separate the unknowns —
e.g. the 6 unknowns of ``OmAndOffset`` against 3 rotation residuals).
:func:`phonestereo.fixes.essential_compare.compare_variants` runs them all on a refocus stack
and ranks them by the per-corner disparity range after the correction, beside the same-camera
"optimal" normalisation of :mod:`phonestereo.fixes.focus`.

Planar scenes (one flat chart) make the 8-point estimate of E degenerate; there E is taken
from the decomposition of the plane's homography instead. Warning: for a fronto-parallel plane
a focal scale is indistinguishable from a translation along the optical axis, so eq. 9 and the
E-based variants cannot work there — the comparison reports it rather than hiding it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from phonestereo.fixes.focus import ScaleOffset
from phonestereo.geometry import Rig, essential_scales
from phonestereo.geometry.checks import Array, as_matrix

VARIANTS = ("eq9", "E", "Om", "OmT")
REFERENCES = ("focus", "calib")
MAX_LOG_SCALE = 0.2  # a refocus changes f by < 2 % (thesis §3.5); beyond 20 % a fit diverged
MAX_OFFSET_PX = 100.0  # likewise for a principal-point offset
MAX_STEP = 50.0  # largest Gauss–Newton step per parameter (5 % in scale, 50 px)


# --- E algebra -------------------------------------------------------------------------------
def _unit(E: Array) -> Array:
    return np.asarray(E / np.linalg.norm(E))


def _rot_angle(R: Array) -> float:
    return float(np.linalg.norm(cv2.Rodrigues(np.asarray(R, dtype=np.float64))[0]))


def decompose_essential(E: Any, R_hint: Any, t_hint: Any) -> tuple[Array, Array]:
    """The (R, t̂) of E nearest a hint: the rotation closest to ``R_hint``, t̂·t_hint > 0.

    Small changes of a calibrated rig (a refocus, a shake) keep the pose near the calibration,
    so the hint replaces the cheirality test of a full decomposition.
    """
    R1, R2, t = cv2.decomposeEssentialMat(as_matrix(E, (3, 3), "E"))
    Rh = as_matrix(R_hint, (3, 3), "R_hint")
    R = min((R1, R2), key=lambda r: _rot_angle(r @ Rh.T))
    t = t.reshape(3)
    if float(t @ np.asarray(t_hint, dtype=np.float64).reshape(3)) < 0:
        t = -t
    return np.asarray(R, dtype=np.float64), np.asarray(t / np.linalg.norm(t))


# --- the variants ------------------------------------------------------------------------------
@dataclass(frozen=True)
class FocusScales:
    """Per-camera focal scales and principal-point offsets of one attempt, from one variant."""

    #: {"eq9", "E", "Om", "OmT", "optimal", "none"}.
    variant: str
    with_offset: bool
    #: ``s_wide``, ``s_tele``: f_cur / f_ref per camera (NaN when not ok).
    s_wide: float
    #: See ``s_wide`` above.
    s_tele: float
    #: ``offset_wide_px``, ``offset_tele_px``: (float, float). c_cur − c_ref per camera, pixels.
    offset_wide_px: tuple[float, float]
    #: See ``offset_wide_px`` above.
    offset_tele_px: tuple[float, float]
    #: Condition number of the solved system (∞: unknowns not separable by these residuals).
    condition: float
    #: RMS residual at the solution (units of the variant's residuals).
    residual: float
    ok: bool = True
    reason: str = ""

    @property
    def label(self) -> str:
        """The variant name of Figure 3-26, e.g. ``OmTAndOffset``."""
        return self.variant + ("AndOffset" if self.with_offset else "")

    def corrections(self, rig: Rig) -> tuple[ScaleOffset, ScaleOffset]:
        """(wide, tele) pixel corrections into the reference geometry: q_ref = (q − c − o)/s + c.

        A failed result gives identities.
        """
        out = []
        for cam, s, o in ((rig.wide, self.s_wide, self.offset_wide_px),
                          (rig.tele, self.s_tele, self.offset_tele_px)):
            c = np.array([cam.cx, cam.cy])
            if not (self.ok and np.isfinite(s)):
                out.append(ScaleOffset.identity(c))
                continue
            out.append(ScaleOffset(1.0 / s, -np.asarray(o, dtype=np.float64) / s, c))
        return out[0], out[1]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN/∞ → None)."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {"variant": self.label, "s_wide": num(self.s_wide), "s_tele": num(self.s_tele),
                "offset_wide_px": [num(v) for v in self.offset_wide_px],
                "offset_tele_px": [num(v) for v in self.offset_tele_px],
                "condition": num(self.condition), "residual": num(self.residual),
                "ok": self.ok, "reason": self.reason}


def _failed(variant: str, with_offset: bool, reason: str) -> FocusScales:
    nan = float("nan")
    return FocusScales(variant, with_offset, nan, nan, (nan, nan), (nan, nan), math.inf, nan,
                       False, reason)


def corrected_essential(E_cur: Any, p: Any, f_wide_px: float, f_tele_px: float) -> Array:
    """E of the corrected coordinates: M_teleᵀ⁻¹ E′ M_wide⁻¹ (module docstring).

    ``p`` = (1000·ln s_wide, 1000·ln s_tele[, o_wide (2), o_tele (2) in pixels]).
    """
    q = np.zeros(6)
    q[: len(p)] = p
    q[:2] = np.clip(q[:2], -1e3, 1e3)  # |ln s| ≤ 1: keeps a diverging fit finite
    sw, st = math.exp(q[0] * 1e-3), math.exp(q[1] * 1e-3)
    Mw_inv = np.array([[sw, 0, q[2] / f_wide_px], [0, sw, q[3] / f_wide_px], [0, 0, 1.0]])
    Mt_inv = np.array([[st, 0, q[4] / f_tele_px], [0, st, q[5] / f_tele_px], [0, 0, 1.0]])
    return np.asarray(Mt_inv.T @ as_matrix(E_cur, (3, 3), "E_cur") @ Mw_inv)


def _gauss_newton(
    fun: Callable[[Array], Array], n: int, *, iters: int = 30, h: float = 1e-3
) -> tuple[Array, float, float]:
    """Minimum-norm Gauss–Newton from 0 with central differences: (p, condition, rms)."""
    p = np.zeros(n)

    def jac(x: Array) -> Array:
        cols = []
        for k in range(n):  # n ≤ 6 parameters
            dx = np.zeros(n)
            dx[k] = h
            cols.append((fun(x + dx) - fun(x - dx)) / (2 * h))
        return np.stack(cols, axis=1)

    r = fun(p)
    for _ in range(iters):
        J = jac(p)
        if not np.isfinite(J).all():
            break
        step = -np.linalg.lstsq(J, r, rcond=1e-9)[0]
        step *= min(1.0, MAX_STEP / max(float(np.max(np.abs(step))), 1e-300))  # trust region
        cost, lam = float(r @ r), 1.0
        while lam > 1e-4:
            r_new = fun(p + lam * step)
            if np.isfinite(r_new).all() and float(r_new @ r_new) <= cost:
                break
            lam *= 0.5
        else:
            break
        p, r = p + lam * step, r_new
        if float(np.max(np.abs(lam * step))) < 1e-7:
            break
    sv = np.linalg.svd(jac(p), compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 1e-9 * sv[0] and len(sv) == n else math.inf
    return p, cond, float(np.sqrt(np.mean(r**2)))


def _result(variant: str, p: Array, cond: float, rms: float, with_offset: bool) -> FocusScales:
    q = np.zeros(6)
    q[: len(p)] = p
    ok = bool(np.all(np.abs(q[:2]) < 1e3 * MAX_LOG_SCALE) and np.all(np.abs(q[2:]) < MAX_OFFSET_PX))
    why = (
        ""
        if ok
        else (
            f"no plausible solution (|ln s| < {MAX_LOG_SCALE}, |o| < {MAX_OFFSET_PX} px): "
            f"ln s = {q[0] * 1e-3:+.3g}, {q[1] * 1e-3:+.3g}, o = {np.round(q[2:], 1).tolist()} px"
        )
    )
    return FocusScales(
        variant, with_offset, math.exp(q[0] * 1e-3), math.exp(q[1] * 1e-3),
        (float(q[2]), float(q[3])), (float(q[4]), float(q[5])), cond, rms, ok, why,
    )


def _aligned(E: Array, E_ref: Array) -> Array:
    u = _unit(E)
    return u if float(np.sum(u * E_ref)) >= 0 else -u


def scales_eq9(E_ref: Any, E_cur: Any) -> FocusScales:
    """The closed form of eq. 9 (Figure 3-24's "naive essential fix"), no offsets.

    Examples
    --------
    >>> from phonestereo.geometry import essential_from_pose
    >>> E = essential_from_pose(np.eye(3), [0.0004, -0.012, 0.0015])
    >>> D = lambda s: np.diag([1 / s, 1 / s, 1.0])
    >>> r = scales_eq9(E, D(0.91532) @ E @ D(1.0518))
    >>> round(r.s_wide, 6), round(r.s_tele, 6), r.condition < 1e3
    (1.0518, 0.91532, True)
    """
    r = essential_scales(E_ref, E_cur)
    if not np.isfinite(r.s_wide):
        return _failed("eq9", False, f"eq. 9 not solvable (condition {r.condition})")
    res = _result("eq9", 1e3 * np.log([r.s_wide, r.s_tele]), r.condition, r.residual_rms, False)
    if res.ok and not r.well_conditioned:
        return _failed("eq9", False, f"eq. 9 ill-conditioned (condition {r.condition:.3g})")
    return res


def match_essential(
    E_ref: Any, E_cur: Any, f_wide_px: float, f_tele_px: float, *, with_offset: bool = False
) -> FocusScales:
    """Scales (and offsets) making the corrected E′ equal E_ref up to scale (Fig. 3-26 "E").

    Residuals: the 9 entries of E′/‖E′‖ − E_ref/‖E_ref‖ (sign aligned).

    Examples
    --------
    >>> from phonestereo.geometry import essential_from_pose
    >>> E = essential_from_pose(np.eye(3), [0.0004, -0.012, 0.0015])
    >>> D = lambda s: np.diag([1 / s, 1 / s, 1.0])
    >>> r = match_essential(E, D(0.91532) @ E @ D(1.0518), 1500.0, 4500.0)
    >>> round(r.s_wide, 6), round(r.s_tele, 6)
    (1.0518, 0.91532)
    """
    e_ref = _unit(as_matrix(E_ref, (3, 3), "E_ref"))
    e_cur = as_matrix(E_cur, (3, 3), "E_cur")

    def fun(p: Array) -> Array:
        return (
            _aligned(corrected_essential(e_cur, p, f_wide_px, f_tele_px), e_ref) - e_ref
        ).ravel()

    p, cond, rms = _gauss_newton(fun, 6 if with_offset else 2)
    return _result("E", p, cond, rms, with_offset)


def _pose_residual(
    E_cur: Array, p: Array, f: tuple[float, float], R_ref: Array, t_ref: Array,
    t_keep: Array | None,
) -> Array:
    R, t = decompose_essential(corrected_essential(E_cur, p, *f), R_ref, t_ref)
    r = cv2.Rodrigues(np.asarray(R @ R_ref.T))[0].reshape(3)
    return r if t_keep is None else np.concatenate([r, t - t_keep])


def match_rotation(
    R_ref: Any, t_ref: Any, E_cur: Any, f_wide_px: float, f_tele_px: float,
    *, with_offset: bool = False,
) -> FocusScales:
    """Scales (and offsets) making the rotation of the corrected E′ equal R_ref (Fig. 3-26 "Om").

    Residuals: the rotation vector of R(p)·R_refᵀ (radians). ``t_ref`` only picks the
    decomposition (:func:`decompose_essential`).
    """
    Rr, tr = as_matrix(R_ref, (3, 3), "R_ref"), np.asarray(t_ref, dtype=np.float64).reshape(3)
    e = as_matrix(E_cur, (3, 3), "E_cur")
    p, cond, rms = _gauss_newton(
        lambda x: _pose_residual(e, x, (f_wide_px, f_tele_px), Rr, tr, None),
        6 if with_offset else 2,
    )
    return _result("Om", p, cond, rms, with_offset)


def match_rotation_keep_translation(
    R_ref: Any, t_ref: Any, E_cur: Any, f_wide_px: float, f_tele_px: float,
    *, with_offset: bool = False,
) -> FocusScales:
    """Rotation to R_ref while the translation direction stays the uncorrected attempt's
    (Fig. 3-26 "OmT", after Figure 3-25). Residuals: rotation vector (rad) and Δt̂."""
    Rr, tr = as_matrix(R_ref, (3, 3), "R_ref"), np.asarray(t_ref, dtype=np.float64).reshape(3)
    e = as_matrix(E_cur, (3, 3), "E_cur")
    _, t_keep = decompose_essential(e, Rr, tr)
    p, cond, rms = _gauss_newton(
        lambda x: _pose_residual(e, x, (f_wide_px, f_tele_px), Rr, tr, t_keep),
        6 if with_offset else 2,
    )
    return _result("OmT", p, cond, rms, with_offset)


__all__ = [
    "REFERENCES",
    "VARIANTS",
    "FocusScales",
    "corrected_essential",
    "decompose_essential",
    "match_essential",
    "match_rotation",
    "match_rotation_keep_translation",
    "scales_eq9",
]
