"""The wide↔tele (W-T) scale (thesis §3.5.1–2).

The tele scale s about its (rectified) principal point and the offset along the
non-disparity axis that minimise the spread of the non-disparity error e over the matched
points: :func:`fit_wt_scale` over all points (§3.5.1), :func:`fit_wt_scale_per_cluster` once
per disparity cluster (§3.5.2 dual-depth scene). A robust linear fit (soft-L1) shared with the
same-camera focus fixes of :mod:`phonestereo.fixes.focus`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.errors import ShapeError
from phonestereo.fixes.focus import MIN_POINTS, _center, _pair, _robust_linear
from phonestereo.geometry.checks import Array, as_points


@dataclass(frozen=True)
class WTScale:
    """The W-T scale (thesis §3.5.1): tele scale s about its (rectified) principal point and
    the offset o along the non-disparity axis that minimise the spread of e.

    After rectification (disparity along x), ``y_w − c_y ≈ s·(y_t − c_y) + o``; the same s
    applies along x, so the corrected tele point is ``(c_x + s·(x_t − c_x), c_y + s·(y_t −
    c_y) + o)`` and the corrected disparity ``d' = x_w − c_x − s·(x_t − c_x)``.
    """

    #: ``scale``, ``offset_px``: s and o (pixels, non-disparity axis).
    scale: float
    #: See ``scale`` above.
    offset_px: float
    #: (2,) float64. The tele principal point in the rectified frame, pixels.
    center_px: Array
    #: ``sigma_scale``, ``sigma_offset_px``: 1σ of s and o.
    sigma_scale: float = 0.0
    #: See ``sigma_scale`` above.
    sigma_offset_px: float = 0.0
    #: Spread (RMS) of e after the fix, inliers.
    rms_e_px: float = 0.0
    #: Spread (RMS about the mean) of e before.
    rms_e_before_px: float = 0.0
    #: Points used.
    n: int = 0
    ok: bool = True
    reason: str = ""

    def apply_tele(self, q_tele_rect: Any) -> Array:
        """Corrected rectified tele pixels (..., 2)."""
        q = as_points(q_tele_rect, 2, "q_tele_rect")
        out = self.scale * (q - self.center_px) + self.center_px
        out[..., 1] += self.offset_px
        return np.asarray(out)

    def disparity(self, q_wide_rect: Any, q_tele_rect: Any) -> tuple[Array, Array]:
        """Corrected (d, e) of rectified pairs (...,), pixels."""
        qw = as_points(q_wide_rect, 2, "q_wide_rect")
        diff = qw - self.apply_tele(q_tele_rect)
        return np.asarray(diff[..., 0]), np.asarray(diff[..., 1])

    def correct_disparity(self, x_wide_rect: Any, d: Any) -> Array:
        """Corrected disparity from the wide x and the measured d (``x_t = x_w − d``)."""
        xw = np.asarray(x_wide_rect, dtype=np.float64)
        xt = xw - np.asarray(d, dtype=np.float64)
        return np.asarray(xw - self.center_px[0] - self.scale * (xt - self.center_px[0]))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "scale": float(self.scale), "offset_px": float(self.offset_px),
            "center_px": [float(v) for v in self.center_px],
            "sigma_scale": float(self.sigma_scale), "sigma_offset_px": float(self.sigma_offset_px),
            "rms_e_px": float(self.rms_e_px), "rms_e_before_px": float(self.rms_e_before_px),
            "n": int(self.n), "ok": self.ok, "reason": self.reason,
        }


def _fit_wt(qw: Array, qt: Array, c: Array, w: Array, f_scale: float, min_spread: float) -> WTScale:
    n = len(qw)
    e0 = qw[:, 1] - qt[:, 1]
    before = float(np.sqrt(np.mean((e0 - e0.mean()) ** 2))) if n else float("nan")
    if n < MIN_POINTS:
        return WTScale(1.0, 0.0, c, np.inf, np.inf, float("nan"), before, n, False,
                       f"{n} matches; the W-T scale needs >= {MIN_POINTS}")
    u = qt[:, 1] - c[1]
    if float(np.std(u)) < min_spread:
        return WTScale(1.0, float(np.median(e0)), c, np.inf, np.inf, before, before, n, False,
                       f"the matches span {np.std(u):.1f} px (std) across the disparity axis; "
                       f"the W-T scale needs >= {min_spread} px")
    A = np.column_stack([u, np.ones(n)]) * w[:, None]
    rhs = (qw[:, 1] - c[1]) * w
    p, sig, _, r = _robust_linear(A, rhs, f_scale)
    resid = r / np.where(w > 0, w, 1.0)
    inl = np.abs(resid) <= 3.0 * max(f_scale, 1.4826 * float(np.median(np.abs(resid))))
    rms = float(np.sqrt(np.mean(resid[inl] ** 2))) if inl.any() else float("nan")
    return WTScale(float(p[0]), float(p[1]), c, float(sig[0]), float(sig[1]), rms, before, n)


def _weighted_pair(
    q_wide_rect: Any, q_tele_rect: Any, sigma_px: Any
) -> tuple[Array, Array, Array, Array]:
    """Finite pairs, their weights (1/σ, median 1) and the mask of kept input rows."""
    qw, qt = _pair(q_wide_rect, q_tele_rect, ("q_wide_rect", "q_tele_rect"))
    raw_w = as_points(q_wide_rect, 2, "q_wide_rect").reshape(-1, 2)
    keep = np.isfinite(raw_w).all(1) & np.isfinite(
        as_points(q_tele_rect, 2, "q_tele_rect").reshape(-1, 2)
    ).all(1)
    w = np.ones(raw_w.shape[0])
    if sigma_px is not None:
        s = np.asarray(sigma_px, dtype=np.float64).reshape(-1)
        if s.shape != w.shape:
            raise ShapeError(f"sigma_px must have one value per match ({w.size}), got {s.shape}")
        w = 1.0 / np.clip(s, 1e-4, None)
        w = w / np.median(w[keep]) if keep.any() else w
    return qw, qt, w[keep], keep


def fit_wt_scale(
    q_wide_rect: Any,
    q_tele_rect: Any,
    center_px: Any,
    *,
    sigma_px: Any = None,
    f_scale_px: float = 0.05,
    min_spread_px: float = 5.0,
) -> WTScale:
    """The W-T scale and non-disparity offset minimising the spread of e (thesis §3.5.1).

    Parameters
    ----------
    q_wide_rect, q_tele_rect : array_like, shape (N, 2)
        Matched points, rectified (disparity along x).
    center_px : array_like, shape (2,)
        The tele principal point in the rectified frame.
    sigma_px : array_like, shape (N,), optional
        Per-match 1σ of e (weights 1/σ); default equal weights.
    f_scale_px : float
        Soft-L1 scale of e residuals (pixels, in weighted units when ``sigma_px`` is given).
    min_spread_px : float
        Smallest std of the tele y about the centre for a scale to be measurable.

    See Also
    --------
    fit_wt_scale_per_cluster : one fit per disparity cluster (§3.5.2).

    Examples
    --------
    Tele scaled by 1 − 8·10⁻⁴ (a refocus) about its centre: recovered from e alone.

    >>> rng = np.random.default_rng(2)
    >>> qw = rng.uniform([300, 300], [700, 700], (300, 2))
    >>> c = np.array([500.0, 480.0])
    >>> qt = qw - [12.0, 0.0]
    >>> qt = (1 - 8e-4) * (qt - c) + c + [0.0, 0.4]
    >>> fit = fit_wt_scale(qw, qt, c)
    >>> round(1 / fit.scale, 6), round(fit.offset_px + 0.4 / (1 - 8e-4), 6), fit.ok
    (0.9992, 0.0, True)
    """
    qw, qt, w, _ = _weighted_pair(q_wide_rect, q_tele_rect, sigma_px)
    return _fit_wt(qw, qt, _center(center_px), w, f_scale_px, min_spread_px)


def fit_wt_scale_per_cluster(
    q_wide_rect: Any,
    q_tele_rect: Any,
    center_px: Any,
    clusters: Any,
    *,
    sigma_px: Any = None,
    f_scale_px: float = 0.05,
    min_spread_px: float = 5.0,
) -> dict[Any, WTScale]:
    """:func:`fit_wt_scale` once per disparity cluster (§3.5.2 dual-depth scene).

    Parameters
    ----------
    clusters : array_like, shape (N,)
        Disparity-cluster label per match.
    q_wide_rect, q_tele_rect, center_px, sigma_px, f_scale_px, min_spread_px
        As for :func:`fit_wt_scale`.

    Returns
    -------
    dict
        Label → :class:`WTScale`, for every label with a finite pair.
    """
    qw, qt, w, keep = _weighted_pair(q_wide_rect, q_tele_rect, sigma_px)
    lab = np.asarray(clusters).reshape(-1)
    if lab.shape != keep.shape:
        raise ShapeError(f"clusters must have one label per match ({keep.size}), got {lab.shape}")
    lab = lab[keep]
    c = _center(center_px)
    return {
        k: _fit_wt(qw[lab == k], qt[lab == k], c, w[lab == k], f_scale_px, min_spread_px)
        for k in np.unique(lab)
    }


__all__ = ["WTScale", "fit_wt_scale", "fit_wt_scale_per_cluster"]
