"""Non-baseline translation (thesis §3.3, Figures 3-8 to 3-10): its effect on e and the fix.

The rotation-only rectifications (``tele-to-wide``, ``undistort-both``) leave the tele optical
centre at c = (B, t_y, t_z) in the rectified frame (metres). For a point at depth Z with
rectified wide pixel offset v = y − c_y,px from the principal row, to first order in 1/Z

    d ≈ f·B/Z − (x − c_x,px)·t_z/Z,        e ≈ f·t_y/Z − v·t_z/Z,

so e depends on depth: e ≈ d·t_y/B − v·d·t_z/(f·B) (:func:`predicted_nondisparity_px`). Two
charts at different depths then show different mean e in the same part of the sensor
(Figure 3-10, first row). **The fix** is the ``canonical`` rectification
(:func:`canonical_rectification`): both cameras rotated so that the full baseline vector is
the x axis, which sets t_y = t_z = 0 and makes e independent of depth — exactly so with a
perfect calibration, up to the calibration's error on t otherwise (§3.3: "our accuracy in
estimating translation isn't great").

Beyond the thesis, :func:`fit_translation` measures t_y/B and t_z/B from the e of a scene with
at least two depths (a rotation-only rectification), which says how far a calibration's
translation is off; :func:`depth_agreement` is the acceptance measure (mean e per depth group).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from phonestereo.errors import InputError, ShapeError
from phonestereo.geometry import Rig
from phonestereo.rectification import (
    Rectification,
    RectifyOptions,
    canonical_rotation,
    quarter_turn,
    quarter_turns_for,
)

F64 = np.ndarray


@dataclass(frozen=True)
class TranslationComponents:
    """The tele optical centre in the rotation-only rectified frame (thesis Figure 3-8).

    Examples
    --------
    The folded ×3 module: tele 12 mm below the wide, 0.4 mm to the side, 1.5 mm in front of the
    wide's centre (device frame); after the quarter turn the baseline is x.

    >>> from phonestereo.geometry import Camera, Transform
    >>> wide = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> c = np.array([0.0004, 0.012, 0.0015])
    >>> rig = Rig(wide, wide.scaled(3.0), Transform(np.eye(3), -c))
    >>> tc = TranslationComponents.from_rig(rig)
    >>> round(tc.baseline_m * 1e3, 3), round(tc.non_baseline_m * 1e3, 3), round(tc.z_m * 1e3, 3)
    (12.0, -0.4, 1.5)
    >>> round(tc.tilt_deg, 2)
    7.37
    """

    #: B: the component along the disparity axis (rectified x).
    baseline_m: float
    #: t_y: along the non-disparity axis (rectified y).
    non_baseline_m: float
    #: t_z: along the optical axis (positive: tele in front of the wide).
    z_m: float
    #: Angle between the full baseline and the rectified x axis: how far ``canonical`` turns the
    #: rectified frame.
    tilt_deg: float

    @classmethod
    def from_rig(cls, rig: Rig) -> TranslationComponents:
        """Components of ``rig.tele_center_in_wide`` after the rotation-only quarter turn."""
        c = np.asarray(rig.tele_center_in_wide, dtype=np.float64)
        b, ty, tz = quarter_turn(quarter_turns_for(c)) @ c
        tilt = float(np.degrees(np.arctan2(np.hypot(ty, tz), b)))
        return cls(float(b), float(ty), float(tz), tilt)

    def to_dict(self) -> dict[str, float]:
        """JSON-ready dict (metres, degrees)."""
        return asdict(self)


def predicted_nondisparity_px(
    components: TranslationComponents, f_px: float, depth_m: Any, v_px: Any = 0.0
) -> F64:
    """e a rotation-only rectification shows at depth Z from the translation alone, px.

    e ≈ f·t_y/Z − v·t_z/Z (first order in 1/Z); ``v_px`` is the rectified row offset from
    the principal point; shapes broadcast.

    Examples
    --------
    0.4 mm of non-baseline translation: 0.6 px at 1 m, 0.3 px at 2 m — the two charts of
    Figure 3-10 disagree by 0.3 px.

    >>> tc = TranslationComponents(0.012, 0.0004, 0.0, 1.9)
    >>> predicted_nondisparity_px(tc, 1500.0, [1.0, 2.0]).round(3).tolist()
    [0.6, 0.3]
    """
    z = np.asarray(depth_m, dtype=np.float64)
    v = np.asarray(v_px, dtype=np.float64)
    return np.asarray((f_px * components.non_baseline_m - v * components.z_m) / z)


def canonical_rectification(rig: Rig, options: RectifyOptions | None = None) -> Rectification:
    """The translation fix (thesis §3.3): rectify so the full baseline vector is x.

    Equivalent to ``Rectification.from_rig(rig, "canonical", options)``; its rotation is
    :func:`~phonestereo.rectification.canonical_rotation` of the tele centre.
    """
    return Rectification.from_rig(rig, "canonical", options)


@dataclass(frozen=True)
class TranslationFit:
    """Non-baseline translation measured from e: e = o + α·d + β·v·d/f + s·v.

    The last term is a tele/wide scale difference (focus breathing, §3.5: e ≈ s·v at every
    depth), fitted so that it is not mistaken for t_z.
    """

    #: False when the scene cannot separate the terms (``reason`` says why).
    ok: bool
    reason: str
    #: α = t_y / B.
    ty_over_b: float
    #: −β = t_z / B.
    tz_over_b: float
    #: o, px.
    offset_px: float
    #: s, the relative scale difference (0 when not fitted).
    scale: float
    #: RMS of the fit residual, px.
    rms_px: float
    #: Points used.
    n: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict (NaN → None)."""
        return {
            k: (None if isinstance(v, float) and not np.isfinite(v) else v)
            for k, v in self.__dict__.items()
        }


def fit_translation(
    v_px: Any,
    d: Any,
    e: Any,
    f_px: float,
    *,
    min_disparity_range_px: float = 1.0,
    with_scale: bool = True,
) -> TranslationFit:
    """Measure t_y/B and t_z/B from the e of matches at several depths (beyond the thesis).

    Parameters
    ----------
    v_px : array_like, shape (N,)
        Rectified wide row offset from the principal point (y − c_y), px.
    d, e : array_like, shape (N,)
        Disparity and non-disparity error from a rotation-only rectification, px.
    f_px : float
        Rectified focal length, px.
    min_disparity_range_px : float
        Smallest spread of d (max − min) that separates the terms; a flat scene at one depth
        gives a result with ok=False.
    with_scale : bool
        Also fit the scale term s·v (default; without it a W-T scale difference between the
        cameras, §3.5, reads as a large false t_z).

    Examples
    --------
    >>> tc = TranslationComponents(0.012, 0.0004, 0.0015, 2.0)
    >>> z = np.repeat([1.0, 2.0], 50)
    >>> v = np.tile(np.linspace(-300.0, 300.0, 50), 2)
    >>> d = 1500.0 * 0.012 / z
    >>> e = 0.1 + predicted_nondisparity_px(tc, 1500.0, z, v)
    >>> fit = fit_translation(v, d, e, 1500.0)
    >>> round(fit.ty_over_b * 0.012 * 1e3, 4), round(fit.tz_over_b * 0.012 * 1e3, 4)
    (0.4, 1.5)
    """
    vv, dv, ev = (np.asarray(a, dtype=np.float64).reshape(-1) for a in (v_px, d, e))
    if not (vv.shape == dv.shape == ev.shape):
        raise ShapeError(f"v_px, d, e must be (N,) alike, got {vv.shape}, {dv.shape}, {ev.shape}")
    if not np.isfinite(f_px) or f_px <= 0:
        raise InputError(f"f_px must be a positive focal length in pixels, got {f_px}")
    ok = np.isfinite(vv) & np.isfinite(dv) & np.isfinite(ev)
    nan = float("nan")
    n = int(ok.sum())
    if n < 5:
        return TranslationFit(False, f"needs >= 5 matches, got {n}", nan, nan, nan, nan, nan, n)
    spread = float(np.ptp(dv[ok]))
    if spread < min_disparity_range_px:
        why = (
            f"disparities span {spread:.2f} px < {min_disparity_range_px} px: a scene at one "
            "depth cannot separate t_y from the offset; use two charts at different depths"
        )
        return TranslationFit(False, why, nan, nan, nan, nan, nan, n)
    cols = [np.ones(n), dv[ok], vv[ok] * dv[ok] / f_px] + ([vv[ok]] if with_scale else [])
    A = np.stack(cols, axis=1)
    sol, *_ = np.linalg.lstsq(A, ev[ok], rcond=None)
    res = A @ sol - ev[ok]
    scale = float(sol[3]) if with_scale else 0.0
    rms = float(np.sqrt(np.mean(res**2)))
    return TranslationFit(True, "", float(sol[1]), float(-sol[2]), float(sol[0]), scale, rms, n)


@dataclass(frozen=True)
class DepthAgreement:
    """Mean e per depth group and how far they disagree (thesis Figure 3-10).

    ``labels``: the group names in order; ``mean_e_px``, ``n``: per group; ``spread_px``:
    max − min of the group means (0 when e does not depend on depth).
    """

    labels: tuple[str, ...]
    mean_e_px: tuple[float, ...]
    n: tuple[int, ...]
    spread_px: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return {
            "groups": {
                lab: {"mean_e_px": m, "n": k}
                for lab, m, k in zip(self.labels, self.mean_e_px, self.n, strict=True)
            },
            "spread_px": self.spread_px,
        }


def depth_agreement(e: Any, groups: Any) -> DepthAgreement:
    """Mean non-disparity error per group (e.g. per chart) and the spread of those means.

    Parameters
    ----------
    e : array_like, shape (N,)
        Non-disparity error, px (NaN skipped).
    groups : array_like, shape (N,)
        A label per point (chart name or depth cluster).

    Examples
    --------
    >>> depth_agreement([0.6, 0.62, 0.3, 0.28], ["near", "near", "far", "far"]).spread_px
    0.32
    """
    ev = np.asarray(e, dtype=np.float64).reshape(-1)
    gv = np.asarray(groups).reshape(-1)
    if gv.shape != ev.shape:
        raise ShapeError(f"e and groups must both be (N,), got {ev.shape} and {gv.shape}")
    labels, means, counts = [], [], []
    for g in dict.fromkeys(gv.tolist()):  # groups in order of first appearance
        sel = (gv == g) & np.isfinite(ev)
        if sel.any():
            labels.append(str(g))
            means.append(float(np.mean(ev[sel])))
            counts.append(int(sel.sum()))
    if not means:
        raise InputError("depth_agreement needs at least one finite e")
    return DepthAgreement(
        tuple(labels), tuple(means), tuple(counts), round(float(np.ptp(means)), 12)
    )


__all__ = [
    "DepthAgreement",
    "TranslationComponents",
    "TranslationFit",
    "canonical_rectification",
    "canonical_rotation",
    "depth_agreement",
    "fit_translation",
    "predicted_nondisparity_px",
]
