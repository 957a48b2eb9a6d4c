"""The Figure 3-26 comparison of the essential-matrix focus scales (thesis §3.5.3).

:func:`essential_from_points` estimates E′ of one capture from matched pixels with the nominal
calibration (8-point; the plane's homography for a planar scene, see
:mod:`phonestereo.fixes.essential` for why eq. 9 cannot work there).
:func:`compare_variants` runs every method of :mod:`phonestereo.fixes.essential` (eq. 9, match
E, match rotation, match rotation keeping translation; against the first attempt and against
the calibration; with and without offset) on one refocus stack, beside no correction and the
same-camera "optimal" normalisation of :mod:`phonestereo.fixes.focus`, corrects every attempt
into its reference geometry, rectifies it (canonical) and ranks the methods by the per-corner
disparity range over the stack — the thesis's Figures 3-24 and 3-26.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from phonestereo.errors import InputError, ShapeError
from phonestereo.fixes.essential import (
    REFERENCES,
    VARIANTS,
    FocusScales,
    _failed,
    _rot_angle,
    _unit,
    decompose_essential,
    match_essential,
    match_rotation,
    match_rotation_keep_translation,
    scales_eq9,
)
from phonestereo.fixes.focus import fit_scale_offset, normalise_to_median
from phonestereo.geometry import Rig
from phonestereo.geometry.checks import Array
from phonestereo.rectification import Rectification

MIN_POINTS = 8
PLANE_RMS_PX = 0.5  # tele pixels: matches this close to one homography come from a plane


# --- estimating E′ from matched pixels --------------------------------------------------------


@dataclass(frozen=True)
class EssentialEstimate:
    """E, R, t between the cameras of one capture, from matched pixels (nominal calibration)."""

    #: (3, 3) float64. E′ for normalised undistorted coordinates of the nominal K, unit Frobenius
    #: norm (rank 2; an exact essential matrix only in the homography case).
    E: Array
    #: ``R``, ``t``: (3, 3), (3,) float64. Its decomposition nearest the hint (t a unit vector).
    R: Array
    #: See ``R`` above.
    t: Array
    #: {"8-point", "homography"}.
    method: str
    #: RMS tele-pixel transfer error of the best single homography (small: a planar scene).
    plane_rms_px: float
    n: int
    ok: bool = True
    reason: str = ""


def _hartley(x: Array) -> Array:
    c = x.mean(0)
    s = math.sqrt(2.0) / max(float(np.mean(np.linalg.norm(x - c, axis=1))), 1e-12)
    return np.array([[s, 0, -s * c[0]], [0, s, -s * c[1]], [0, 0, 1.0]])


def _eight_point(xw: Array, xt: Array) -> Array:
    """Linear E′ from normalised points (Hartley-normalised 8-point, rank 2 enforced).

    Only the rank is enforced, not equal singular values: with wrong focal lengths E′ is not an
    essential matrix (eq. 8), and projecting it onto the essential manifold would erase the
    scales eq. 9 reads.
    """
    Tw, Tt = _hartley(xw), _hartley(xt)
    hw = np.c_[xw, np.ones(len(xw))] @ Tw.T
    ht = np.c_[xt, np.ones(len(xt))] @ Tt.T
    A = (ht[:, :, None] * hw[:, None, :]).reshape(-1, 9)
    e = np.linalg.svd(A)[2][-1].reshape(3, 3)
    e = Tt.T @ e @ Tw
    u, sv, vt = np.linalg.svd(e)
    return np.asarray(u @ np.diag([sv[0], sv[1], 0.0]) @ vt)


def essential_from_points(
    q_wide: Any, q_tele: Any, rig: Rig, *, plane_rms_px: float = PLANE_RMS_PX
) -> EssentialEstimate:
    """Estimate E (and R, t̂) of one capture from matched raw pixels with the nominal ``rig``.

    The pixels are undistorted and normalised with the rig's cameras (eq. 7 for normalised
    coordinates). If one homography explains the matches to ``plane_rms_px`` tele pixels the
    scene is planar and the 8-point estimate degenerate: E = [t]ₓR from the homography's
    decomposition (cv2.decomposeHomographyMat) nearest the rig's pose; else the normalised
    8-point estimate. Fewer than :data:`MIN_POINTS` pairs → not ok (with the reason).
    """
    qw = np.asarray(q_wide, dtype=np.float64).reshape(-1, 2)
    qt = np.asarray(q_tele, dtype=np.float64).reshape(-1, 2)
    if qw.shape != qt.shape:
        raise ShapeError(f"q_wide and q_tele must pair up row by row, got {qw.shape}, {qt.shape}")
    xw, xt = rig.wide.pixel_to_normalized(qw), rig.tele.pixel_to_normalized(qt)
    good = np.isfinite(xw).all(1) & np.isfinite(xt).all(1)
    xw, xt = xw[good], xt[good]
    R0, t0 = rig.T_tele_wide.R, rig.T_tele_wide.t / np.linalg.norm(rig.T_tele_wide.t)
    if len(xw) < MIN_POINTS:
        nan3 = np.full((3, 3), np.nan)
        return EssentialEstimate(nan3, nan3, np.full(3, np.nan), "none", np.nan, len(xw), False,
                                 f"{len(xw)} matches; E needs >= {MIN_POINTS}")
    H, _ = cv2.findHomography(xw, xt, 0)
    hx = np.c_[xw, np.ones(len(xw))] @ H.T
    rms = float(np.sqrt(np.mean(np.sum((hx[:, :2] / hx[:, 2:] - xt) ** 2, 1)))) * rig.tele.f
    if rms < plane_rms_px:
        _, Rs, ts, _ = cv2.decomposeHomographyMat(H, np.eye(3))
        cands = [(np.asarray(r), np.asarray(t).reshape(3)) for r, t in zip(Rs, ts, strict=True)]
        cands = [(r, t / np.linalg.norm(t)) for r, t in cands if np.linalg.norm(t) > 1e-12]
        R, t = min(cands, key=lambda c: _rot_angle(c[0] @ R0.T) + 1.0 - float(c[1] @ t0))
        return EssentialEstimate(_unit(_skew(t) @ R), R, t, "homography", rms, len(xw))
    E = _unit(_eight_point(xw, xt))
    R, t = decompose_essential(E, R0, t0)
    return EssentialEstimate(E, R, t, "8-point", rms, len(xw))


def _skew(v: Array) -> Array:
    x, y, z = np.asarray(v, dtype=np.float64).reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


# --- the comparison --------------------------------------------------------------------------
@dataclass(frozen=True)
class StackAttempt:
    """One attempt of a refocus stack: matched raw pixels with their chart ids.

    ids (N, 2) int64 (chart row, col), q_wide and q_tele (N, 2) float64 pixels.
    """

    id: str
    ids: np.ndarray
    q_wide: Array
    q_tele: Array


@dataclass(frozen=True)
class VariantRow:
    """One method of the comparison: its per-attempt scales and the disparity ranges after it.

    ``label`` e.g. ``"calib OmTAndOffset"``; ``ranges_px`` (K,) per-corner max − min disparity
    over the attempts the method gave a result for; ``median_range_px``/``p90_range_px``
    summarise them (NaN with fewer than 2 such attempts).
    """

    label: str
    variant: str
    reference: str
    with_offset: bool
    per_attempt: tuple[FocusScales, ...]
    ranges_px: Array
    median_range_px: float
    p90_range_px: float
    median_condition: float

    @property
    def attempts_ok(self) -> int:
        """Attempts the method gave a result for."""
        return sum(a.ok for a in self.per_attempt)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary (per-attempt results included)."""

        def num(v: float) -> float | None:
            return round(float(v), 6) if math.isfinite(v) else None

        return {"label": self.label, "variant": self.variant, "reference": self.reference,
                "with_offset": self.with_offset, "median_range_px": num(self.median_range_px),
                "p90_range_px": num(self.p90_range_px),
                "median_condition": num(self.median_condition),
                "attempts_ok": self.attempts_ok,
                "per_attempt": [a.to_dict() for a in self.per_attempt]}


@dataclass(frozen=True)
class VariantComparison:
    """Every method of Figure 3-26 on one refocus stack, best (smallest median range) first."""

    rows: tuple[VariantRow, ...]
    estimates: tuple[EssentialEstimate, ...]
    corner_keys: np.ndarray

    @property
    def ranking(self) -> tuple[str, ...]:
        """Labels, best first (methods that failed on every attempt last)."""
        return tuple(r.label for r in self.rows)

    def row(self, label: str) -> VariantRow:
        """The row of a label (InputError listing the labels if unknown)."""
        for r in self.rows:
            if r.label == label:
                return r
        raise InputError(f"no method {label!r}; methods: {list(self.ranking)}")


def _keys(ids: np.ndarray) -> np.ndarray:
    ids = np.asarray(ids, dtype=np.int64).reshape(-1, 2)
    return np.asarray(ids[:, 0] * 100_000 + ids[:, 1])


def shared_points(attempts: Sequence[StackAttempt]) -> tuple[np.ndarray, list[tuple[Array, Array]]]:
    """Corners seen in every attempt: (keys (K,), per attempt (q_wide, q_tele) (K, 2) each)."""
    keys = _keys(attempts[0].ids)
    for a in attempts[1:]:
        keys = np.intersect1d(keys, _keys(a.ids))
    pts = []
    for a in attempts:
        _, _, ib = np.intersect1d(keys, _keys(a.ids), return_indices=True)
        pts.append((np.asarray(a.q_wide)[ib], np.asarray(a.q_tele)[ib]))
    return keys, pts


def _row(label: str, variant: str, ref: str, off: bool, res: list[FocusScales],
         pts: list[tuple[Array, Array]], rig: Rig, rect: Rectification) -> VariantRow:
    d = np.full((len(pts), len(pts[0][0])), np.nan)
    for i, ((qw, qt), r) in enumerate(zip(pts, res, strict=True)):
        if r.ok:
            cw, ct = r.corrections(rig)
            d[i] = rect.disparity(cw.apply(qw), ct.apply(qt))[0]
    n_ok = int(np.isfinite(d).all(axis=1).sum())
    rng = np.nanmax(d, axis=0) - np.nanmin(d, axis=0) if n_ok >= 2 else np.full(d.shape[1], np.nan)
    finite = rng[np.isfinite(rng)]
    med = float(np.median(finite)) if finite.size else math.nan
    p90 = float(np.percentile(finite, 90)) if finite.size else math.nan
    conds = [r.condition for r in res if r.ok]
    return VariantRow(label, variant, ref, off, tuple(res), rng, med, p90,
                      float(np.median(conds)) if conds else math.inf)


def _optimal(pts: list[tuple[Array, Array]], rig: Rig) -> list[FocusScales]:
    """Same-camera scale/offset normalised to the stack's median (focus opt, §3.5.3 2.b.1)."""
    corr = []
    for role, cam in ((0, rig.wide), (1, rig.tele)):
        c = np.array([cam.cx, cam.cy])
        fits = [fit_scale_offset(pts[0][role], p[role], c) for p in pts]
        corr.append(normalise_to_median(fits))
    out = []
    for cw, ct in zip(*corr, strict=True):
        ok = cw.ok and ct.ok
        # correction q' = k(q − c) + c + b  ⇔  s = 1/k, o = −b/k (module docstring)
        out.append(FocusScales(
            "optimal", True, 1 / cw.scale, 1 / ct.scale,
            tuple(float(v) for v in -cw.offset_px / cw.scale),  # type: ignore[arg-type]
            tuple(float(v) for v in -ct.offset_px / ct.scale),  # type: ignore[arg-type]
            1.0, max(cw.rms_px, ct.rms_px), ok, cw.reason or ct.reason,
        ))
    return out


def compare_variants(
    attempts: Sequence[StackAttempt],
    rig: Rig,
    *,
    references: Sequence[str] = REFERENCES,
    variants: Sequence[str] = VARIANTS,
    offsets: Sequence[bool] = (False, True),
) -> VariantComparison:
    """Run every Figure 3-26 method on a refocus stack and rank them (thesis §3.5.3).

    For each attempt E′ is estimated (:func:`essential_from_points`); each variant gives the
    attempt's per-camera scales (and offsets) against the first attempt (``focus``) or the
    calibration (``calib``, E and pose of ``rig``); the attempt's points are corrected into the
    reference geometry, rectified (canonical) and the per-corner disparity range over the stack
    is taken. Rows: ``none`` (no correction), ``focus opt`` (the same-camera normalisation of
    :mod:`phonestereo.fixes.focus`; its scales are relative to the stack's median), then
    ``{reference} {variant}[AndOffset]``; ``eq9`` has no offset form. Ranked by median range;
    methods that failed on some attempt come after the complete ones, those with fewer than 2
    results last.

    Parameters
    ----------
    attempts : sequence of StackAttempt
        The refocus stack (>= 2 attempts, same static scene); only corners seen in every
        attempt are used.
    rig : Rig
        The (factory) calibration the pixels are interpreted with.

    Raises
    ------
    InputError
        Fewer than 2 attempts, or fewer than :data:`MIN_POINTS` corners seen in all of them;
        an unknown reference or variant.
    """
    if len(attempts) < 2:
        raise InputError(
            f"compare_variants needs a refocus stack of >= 2 attempts, got {len(attempts)}"
        )
    bad = sorted(set(references) - set(REFERENCES)) + sorted(set(variants) - set(VARIANTS))
    if bad:
        raise InputError(
            f"unknown reference/variant {bad}; references {REFERENCES}, variants {VARIANTS}"
        )
    keys, pts = shared_points(attempts)
    if len(keys) < MIN_POINTS:
        raise InputError(
            f"only {len(keys)} corners are seen in every attempt; the comparison needs >= "
            f"{MIN_POINTS} (keep the chart in both views for the whole stack)"
        )
    rect = Rectification.from_rig(rig, "canonical")
    est = [essential_from_points(qw, qt, rig) for qw, qt in pts]
    fw, ft = rig.wide.f, rig.tele.f
    cal_t = rig.T_tele_wide.t / np.linalg.norm(rig.T_tele_wide.t)
    refs = {"calib": (_unit(rig.essential()), rig.T_tele_wide.R, cal_t),
            "focus": (est[0].E, est[0].R, est[0].t)}
    ident = FocusScales("none", False, 1.0, 1.0, (0.0, 0.0), (0.0, 0.0), 1.0, 0.0)
    rows = [
        _row("none", "none", "-", False, [ident] * len(pts), pts, rig, rect),
        _row("focus opt", "optimal", "focus", True, _optimal(pts, rig), pts, rig, rect),
    ]
    for ref in references:
        E_ref, R_ref, t_ref = refs[ref]
        for var in variants:
            for off in (False,) if var == "eq9" else tuple(offsets):
                res = []
                for e in est:
                    if not (e.ok and np.isfinite(E_ref).all()):
                        res.append(_failed(var, off, e.reason or "reference E not estimated"))
                    elif var == "eq9":
                        res.append(scales_eq9(E_ref, e.E))
                    elif var == "E":
                        res.append(match_essential(E_ref, e.E, fw, ft, with_offset=off))
                    elif var == "Om":
                        res.append(match_rotation(R_ref, t_ref, e.E, fw, ft, with_offset=off))
                    else:
                        res.append(match_rotation_keep_translation(
                            R_ref, t_ref, e.E, fw, ft, with_offset=off))
                label = f"{ref} {var}" + ("AndOffset" if off else "")
                rows.append(_row(label, var, ref, off, res, pts, rig, rect))
    n = len(pts)
    rows.sort(key=lambda r: (not math.isfinite(r.median_range_px), r.attempts_ok < n,
                             r.median_range_px))
    return VariantComparison(tuple(rows), tuple(est), keys)


__all__ = [
    "MIN_POINTS",
    "EssentialEstimate",
    "StackAttempt",
    "VariantComparison",
    "VariantRow",
    "compare_variants",
    "essential_from_points",
    "shared_points",
]
