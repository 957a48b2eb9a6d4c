"""Residual distortion (thesis §3.2): odd-degree lens models, undistort-both, the e-axis fix.

Three fixes of docs/architecture.md:

(a) **Odd-degree radial terms** in the lens model (§3.2 fix 3): calibrate with ``radial-odd``
    instead of the even-only ``opencv5``; the comparison is in
    :mod:`~phonestereo.fixes.lens_model_compare`.
(b) **Undistort-both** rectification (§3.2 fix 2): a mode of
    :class:`~phonestereo.rectification.Rectification`; :func:`nondisparity_spread_by_mode`
    compares the spread of e in each mode on the same matches.
(c) **The non-disparity-axis fix** (§3.2 fix "non-disparity axis constraint", Figure 3-7):
    after rectification the non-disparity error e = y_wide − y_tele of a flat or deep scene
    should be a constant; a residual radial distortion δ(q) = P(r)·û about the distortion
    centre c (û = (q − c)/r, r = |q − c|) shows in e as its y component, so

        e = o + û_y · P(r),   P(r) = Σₖ aₖ (r/ρ)ᵏ, k = 1..n,

    with o the non-disparity offset. For any offset the best polynomial is a linear least
    squares problem, so the thesis's search for "the offset that makes the radial component
    best fit a polynomial in radius" is solved jointly and exactly by
    :meth:`RadialResidualFix.fit`. The fitted P is then a residual radial correction of both
    d and e (:meth:`RadialResidualFix.correct`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.errors import InputError, ShapeError
from phonestereo.geometry.checks import as_points
from phonestereo.rectification import MODES, Rectification

F64 = np.ndarray
MIN_SHARE = 0.3  # smallest |û_y| at which e is converted to a radial error dr (plots)
_REJECT_SIGMA = 4.0  # robust rejection: residuals beyond this many MAD-sigmas are dropped


def _center(center: Any) -> F64:
    c = np.asarray(center, dtype=np.float64).reshape(-1)
    if c.shape != (2,) or not np.all(np.isfinite(c)):
        raise InputError(f"center must be a finite pixel (x, y), got {center!r}")
    return c


def radial_geometry(q: Any, center: Any) -> tuple[F64, F64]:
    """Radius r (N,) px and unit radial direction û (N, 2) of pixels q (N, 2) about ``center``.

    û is (0, 0) at r = 0.

    Examples
    --------
    >>> r, u = radial_geometry([[3.0, 4.0]], (0.0, 0.0))
    >>> float(r[0]), u[0].tolist()
    (5.0, [0.6, 0.8])
    """
    p = as_points(q, 2, "q").reshape(-1, 2) - _center(center)
    r = np.hypot(p[:, 0], p[:, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(r[:, None] > 0, p / r[:, None], 0.0)
    return r, u


def radial_projection(q: Any, e: Any, center: Any) -> F64:
    """The radial component e·û_y of the non-disparity error vector (0, e), px (thesis
    Figure 3-7 middle: the tangential part discarded). q (N, 2) rectified px, e (N,) px."""
    _, u = radial_geometry(q, center)
    return np.asarray(np.asarray(e, dtype=np.float64).reshape(-1) * u[:, 1])


@dataclass(frozen=True)
class RadialResidualFix:
    """The non-disparity-axis fix (thesis §3.2, Figure 3-7): offset o and radial polynomial P.

    Model: e = o + û_y·P(r) over rectified wide pixels (module docstring). Build it with
    :meth:`fit` (or :meth:`from_rectification`); apply with :meth:`correct` / :meth:`apply`.

    Examples
    --------
    A residual radial error P(r) = 0.2·(r/400)² px and a 0.3 px offset, seen through e only:

    >>> rng = np.random.default_rng(0)
    >>> q = rng.uniform(200.0, 800.0, size=(300, 2))
    >>> r, u = radial_geometry(q, (500.0, 500.0))
    >>> e = 0.3 + u[:, 1] * 0.2 * (r / 400.0) ** 2
    >>> fix = RadialResidualFix.fit(q, e, (500.0, 500.0), degree=3)
    >>> round(fix.offset_px, 6), round(float(fix.radial(400.0)), 6), round(fix.rms_after_px, 9)
    (0.3, 0.2, 0.0)
    """

    #: Distortion centre in rectified pixels (the wide's principal point, rectified).
    center_px: tuple[float, float]
    #: o: the constant non-disparity offset, px.
    offset_px: float
    #: tuple of float. a₁..aₙ of P(r) = Σ aₖ (r/ρ)ᵏ, px.
    coefficients: tuple[float, ...]
    #: ρ: the largest radius in the fit, px (keeps the fit well conditioned).
    radius_scale_px: float
    #: ``rms_before_px``, ``rms_after_px``: RMS of e − mean(e) and of the fit residual over the
    #: points used, px.
    rms_before_px: float
    #: See ``rms_before_px`` above.
    rms_after_px: float
    #: ``n_used``, ``n_total``: Points kept after robust rejection, points given.
    n_used: int
    #: See ``n_used`` above.
    n_total: int

    @staticmethod
    def _design(r: F64, u: F64, degree: int, rho: float) -> F64:
        cols = [np.ones_like(r)] + [u[:, 1] * (r / rho) ** k for k in range(1, degree + 1)]
        return np.stack(cols, axis=1)

    @classmethod
    def fit(
        cls,
        q: Any,
        e: Any,
        center: Any,
        *,
        degree: int = 4,
        offset: float | None = None,
        robust: bool = True,
    ) -> RadialResidualFix:
        """Fit o and P to the non-disparity error of matched points.

        Parameters
        ----------
        q : array_like, shape (N, 2)
            Rectified wide pixels of the matches.
        e : array_like, shape (N,)
            Their non-disparity error y_wide − y_tele, px.
        center : (x, y)
            Distortion centre, rectified px (:meth:`from_rectification` uses the wide's
            principal point).
        degree : int
            n, the highest power of r (1..8; 4 covers a phone lens over the tele's field).
        offset : float or None
            None fits o; a number fixes it (0: the fit without the offset, Figure 3-7 middle).
        robust : bool
            Refit once without points beyond 4 MAD-sigmas (mismatched corners).

        Raises
        ------
        ShapeError, InputError
            Mismatched shapes, non-finite values, a degree outside 1..8, or fewer than
            degree + 3 points.
        """
        pts = as_points(q, 2, "q").reshape(-1, 2)
        ev = np.asarray(e, dtype=np.float64).reshape(-1)
        if ev.shape[0] != pts.shape[0]:
            raise ShapeError(f"q (N, 2) and e (N,) must match, got {pts.shape} and {ev.shape}")
        if not isinstance(degree, int | np.integer) or not 1 <= degree <= 8:
            raise InputError(f"degree must be an integer in 1..8, got {degree!r}")
        ok = np.isfinite(pts).all(axis=1) & np.isfinite(ev)
        if ok.sum() < degree + 3:
            raise InputError(
                f"the radial residual fit of degree {degree} needs >= {degree + 3} matched "
                f"points with finite e, got {int(ok.sum())}; detect more chart corners"
            )
        c = _center(center)
        r, u = radial_geometry(pts, c)
        rho = float(np.max(r[ok])) or 1.0
        A = cls._design(r, u, int(degree), rho)
        y = ev.copy()
        if offset is not None:
            y, A = y - float(offset), A[:, 1:]
        keep = ok.copy()
        for _ in range(2 if robust else 1):
            sol = np.linalg.lstsq(A[keep], y[keep], rcond=None)[0]
            res = A @ sol - y
            mad = 1.4826 * float(np.median(np.abs(res[keep] - np.median(res[keep]))))
            new = ok & (np.abs(res) <= max(_REJECT_SIGMA * mad, 1e-9))
            if new.sum() < degree + 3 or np.array_equal(new, keep):
                break
            keep = new
        sol = np.linalg.lstsq(A[keep], y[keep], rcond=None)[0]
        res = A[keep] @ sol - y[keep]
        o = float(sol[0]) if offset is None else float(offset)
        coefs = sol[1:] if offset is None else sol
        return cls(
            (float(c[0]), float(c[1])),
            o,
            tuple(float(a) for a in coefs),
            rho,
            float(np.std(ev[keep])),
            float(np.sqrt(np.mean(res**2))),
            int(keep.sum()),
            int(pts.shape[0]),
        )

    @classmethod
    def from_rectification(
        cls, rect: Rectification, q_wide: Any, q_tele: Any, **kwargs: Any
    ) -> RadialResidualFix:
        """Rectify raw matches (N, 2) with ``rect`` and :meth:`fit` about the wide's principal
        point (rectified); keyword arguments go to :meth:`fit`."""
        qw = rect.points_wide(q_wide)
        _, e = rect.disparity(qw, rect.points_tele(q_tele), rectified=True)
        return cls.fit(qw, e, principal_point_rect(rect), **kwargs)

    @property
    def degree(self) -> int:
        """n, the highest power of r."""
        return len(self.coefficients)

    def radial(self, r_px: Any) -> F64:
        """P(r): the residual radial displacement at radius r (any shape), px."""
        s = np.asarray(r_px, dtype=np.float64) / self.radius_scale_px
        return np.asarray(sum(a * s ** (k + 1) for k, a in enumerate(self.coefficients)))

    def displacement(self, q: Any) -> F64:
        """δ(q) = P(r)·û at rectified pixels q (N, 2) → (N, 2), px."""
        r, u = radial_geometry(q, self.center_px)
        return np.asarray(self.radial(r)[:, None] * u)

    def radial_error(self, q: Any, e: Any, *, min_share: float = MIN_SHARE) -> F64:
        """dr = (e − o)/û_y per point (N,), px; NaN where |û_y| < ``min_share`` (Figure 3-7
        right: the radial error with the optimal offset)."""
        _, u = radial_geometry(q, self.center_px)
        ev = np.asarray(e, dtype=np.float64).reshape(-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(np.abs(u[:, 1]) >= min_share, (ev - self.offset_px) / u[:, 1], np.nan)

    def correct(self, q_wide_rect: Any, d: Any, e: Any) -> tuple[F64, F64]:
        """Corrected (d, e) of rectified matches: d − δ_x(q), e − o − δ_y(q), px (N,)."""
        delta = self.displacement(q_wide_rect)
        dv = np.asarray(d, dtype=np.float64).reshape(-1)
        ev = np.asarray(e, dtype=np.float64).reshape(-1)
        return dv - delta[:, 0], ev - self.offset_px - delta[:, 1]

    def apply(self, q_wide_rect: Any, q_tele_rect: Any) -> tuple[F64, F64]:
        """Corrected rectified pair (N, 2) each: the wide point moved by −δ(q) − (0, o), the
        tele point unchanged (the residual is attributed to the wide; d and e follow)."""
        qw = as_points(q_wide_rect, 2, "q_wide_rect").reshape(-1, 2)
        qt = as_points(q_tele_rect, 2, "q_tele_rect").reshape(-1, 2)
        out = qw - self.displacement(qw)
        out[:, 1] -= self.offset_px
        return out, qt.copy()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready description."""
        return {
            "center_px": list(self.center_px),
            "offset_px": self.offset_px,
            "coefficients": list(self.coefficients),
            "radius_scale_px": self.radius_scale_px,
            "rms_before_px": self.rms_before_px,
            "rms_after_px": self.rms_after_px,
            "n_used": self.n_used,
            "n_total": self.n_total,
        }


def principal_point_rect(rect: Rectification) -> tuple[float, float]:
    """The wide's principal point in rectified pixels: the centre of its residual distortion."""
    w = rect.rig.wide
    c = rect.points_wide(np.array([[w.cx, w.cy]]))[0]
    return float(c[0]), float(c[1])


def nondisparity_spread_by_mode(
    rig: Any, q_wide: Any, q_tele: Any, modes: Sequence[str] = MODES
) -> dict[str, float]:
    """Std of e (px) of the same raw matches (N, 2) rectified in each mode (§3.2 fix 2)."""
    rects = {mode: Rectification.from_rig(rig, mode) for mode in modes}
    return {m: float(np.nanstd(r.disparity(q_wide, q_tele)[1])) for m, r in rects.items()}


# --- (a) odd-degree lens models ---------------------------------------------------------------


__all__ = [
    "MIN_SHARE",
    "RadialResidualFix",
    "nondisparity_spread_by_mode",
    "principal_point_rect",
    "radial_geometry",
    "radial_projection",
]
