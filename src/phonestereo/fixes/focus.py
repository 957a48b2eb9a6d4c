"""Focus fixes (thesis §3.5): per-attempt scale and offset, stack normalisation, W-T scale.

Focus breathing changes each camera's focal length (a scale of the image about its principal
point) and a refocus never lands on the same lens position twice (§3.5.3), so every attempt
of a refocus stack has its own scale. Small corrections, used by the focus-calibration
flow (Fig. 4-1) and the learning and application phases (Fig. 4-2 to 4-4):

* :func:`fit_scale_offset` — the scale s and offset o with ``q_to ≈ s·(q_from − c) + c + o``
  (same camera, one attempt against another, §3.5.3 "same-camera scale/offset");
* :func:`normalise_to_median` — per attempt, the correction into the stack's median geometry
  (§3.5.3 option 2.b.1);
* the wide↔tele (W-T) scale of §3.5.1–2 is in :mod:`phonestereo.fixes.wt_scale`.

All fits are linear least squares made robust by SciPy's ``least_squares`` (soft-L1 loss);
σ of each parameter comes from the Jacobian and the residual scale.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from phonestereo.errors import InputError, ShapeError
from phonestereo.features.crlb import solve_spd
from phonestereo.geometry.checks import Array, as_points

#: Fewest point pairs for a scale + offset fit (3 unknowns, some redundancy).
MIN_POINTS = 6


def _pair(q_a: Any, q_b: Any, names: tuple[str, str]) -> tuple[Array, Array]:
    a = as_points(q_a, 2, names[0]).reshape(-1, 2)
    b = as_points(q_b, 2, names[1]).reshape(-1, 2)
    if a.shape != b.shape:
        raise ShapeError(
            f"{names[0]} and {names[1]} must pair up row by row, got {a.shape}, {b.shape}"
        )
    ok = np.isfinite(a).all(axis=1) & np.isfinite(b).all(axis=1)
    return a[ok], b[ok]


def _center(center_px: Any) -> Array:
    c = np.asarray(center_px, dtype=np.float64).reshape(-1)
    if c.shape != (2,) or not np.isfinite(c).all():
        raise ShapeError(f"center_px must be a finite (x, y) pixel, got {center_px!r}")
    return c


def _robust_linear(A: Array, b: Array, f_scale: float) -> tuple[Array, Array, float, Array]:
    """Robust solve of A·p ≈ b: (p, σ_p, rms of inliers, residuals)."""
    p0, *_ = np.linalg.lstsq(A, b, rcond=None)
    res = least_squares(
        lambda p: A @ p - b, p0, jac=lambda p: A, loss="soft_l1", f_scale=f_scale, method="trf"
    )
    r = A @ res.x - b
    inl = np.abs(r) <= 3.0 * max(f_scale, 1.4826 * float(np.median(np.abs(r))))
    dof = max(int(inl.sum()) - A.shape[1], 1)
    s2 = float(np.sum(r[inl] ** 2)) / dof
    # (AᵀA)⁻¹ by the vectorised Cholesky: LAPACK's inverse wakes OpenBLAS's second thread,
    # which then spins for milliseconds after this 2 × 2 or 3 × 3 call
    p = A.shape[1]
    ata = A[inl].T @ A[inl]
    inv, spd = solve_spd(ata[None], np.eye(p)[None])
    sig = np.sqrt(np.clip(np.diag(inv[0]) * s2, 0.0, None)) if spd[0] else np.full(p, np.inf)
    rms = float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else float("nan")
    return np.asarray(res.x), sig, rms, r


@dataclass(frozen=True)
class ScaleOffset:
    """``q' = s·(q − c) + c + o``: an isotropic scale about ``c`` plus an offset (pixels).

    Examples
    --------
    >>> t = ScaleOffset(1.001, np.array([0.5, 0.0]), np.array([1000.0, 750.0]))
    >>> t.apply([[2000.0, 750.0]]).round(3).tolist()
    [[2001.5, 750.0]]
    >>> t.inverse().apply(t.apply([[10.0, 20.0]])).round(9).tolist()
    [[10.0, 20.0]]
    """

    #: s (1 = no change).
    scale: float
    #: (2,) float64. o, pixels.
    offset_px: Array
    #: (2,) float64. c, pixels (the camera's principal point).
    center_px: Array
    #: 1σ of s (0 for an exact/constructed transform).
    sigma_scale: float = 0.0
    #: (2,) float64. 1σ of o.
    sigma_offset_px: Array = field(default_factory=lambda: np.zeros(2))
    #: RMS residual of the fit over its inliers (per coordinate).
    rms_px: float = 0.0
    #: Point pairs used.
    n: int = 0
    #: False when the data could not give the fit (``reason``).
    ok: bool = True
    reason: str = ""

    @classmethod
    def identity(cls, center_px: Any) -> ScaleOffset:
        """s = 1, o = 0 about ``center_px``."""
        return cls(1.0, np.zeros(2), _center(center_px))

    def apply(self, q: Any) -> Array:
        """Map pixels (..., 2) → (..., 2)."""
        p = as_points(q, 2, "q")
        return np.asarray(self.scale * (p - self.center_px) + self.center_px + self.offset_px)

    def inverse(self) -> ScaleOffset:
        """The transform that undoes this one (same centre)."""
        s = self.scale
        return ScaleOffset(
            1.0 / s, -np.asarray(self.offset_px) / s, self.center_px,
            self.sigma_scale / s**2, np.asarray(self.sigma_offset_px) / s, self.rms_px, self.n,
            self.ok, self.reason,
        )

    def then(self, other: ScaleOffset) -> ScaleOffset:
        """``other ∘ self`` (apply self, then other); both must share the centre."""
        if not np.allclose(self.center_px, other.center_px, atol=1e-9):
            raise InputError("compose scale/offset transforms about the same centre only")
        s = other.scale * self.scale
        o = other.scale * np.asarray(self.offset_px) + np.asarray(other.offset_px)
        return ScaleOffset(s, o, self.center_px, n=min(self.n, other.n))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "scale": float(self.scale), "offset_px": [float(v) for v in self.offset_px],
            "center_px": [float(v) for v in self.center_px],
            "sigma_scale": float(self.sigma_scale),
            "sigma_offset_px": [float(v) for v in self.sigma_offset_px],
            "rms_px": float(self.rms_px), "n": int(self.n), "ok": self.ok, "reason": self.reason,
        }


def fit_scale_offset(
    q_from: Any, q_to: Any, center_px: Any, *, f_scale_px: float = 0.3
) -> ScaleOffset:
    """Scale and offset mapping ``q_from`` onto ``q_to`` about ``center_px`` (thesis §3.5.3).

    Same camera, two focus attempts: ``q_to ≈ s·(q_from − c) + c + o``. A robust linear
    least-squares fit (soft-L1, ``f_scale_px``); with fewer than :data:`MIN_POINTS` pairs or
    no spread about ``c`` the result is not ok (with the reason), never an exception.

    Parameters
    ----------
    q_from, q_to : array_like, shape (N, 2)
        Matched pixels of the same scene points in the two attempts.
    center_px : array_like, shape (2,)
        The camera's principal point, pixels.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> q = rng.uniform(0, 2000, (200, 2))
    >>> c = np.array([1000.0, 750.0])
    >>> fit = fit_scale_offset(q, 1.0008 * (q - c) + c + [0.3, -0.2], c)
    >>> round(fit.scale, 6), fit.offset_px.round(6).tolist()
    (1.0008, [0.3, -0.2])
    """
    a, b = _pair(q_from, q_to, ("q_from", "q_to"))
    c = _center(center_px)
    if len(a) < MIN_POINTS:
        return ScaleOffset(
            1.0, np.zeros(2), c, np.inf, np.full(2, np.inf), float("nan"), len(a), False,
            f"{len(a)} point pairs; a scale/offset fit needs >= {MIN_POINTS}",
        )
    u = a - c
    if float(np.sqrt(np.mean(np.sum((u - u.mean(0)) ** 2, axis=1)))) < 1.0:
        return ScaleOffset(
            1.0, np.zeros(2), c, np.inf, np.full(2, np.inf), float("nan"), len(a), False,
            "the points do not spread (< 1 px): no scale can be measured",
        )
    n = len(a)
    A = np.zeros((2 * n, 3))
    A[:n, 0], A[n:, 0] = u[:, 0], u[:, 1]
    A[:n, 1], A[n:, 2] = 1.0, 1.0
    rhs = np.concatenate([b[:, 0] - c[0], b[:, 1] - c[1]])
    p, sig, rms, _ = _robust_linear(A, rhs, f_scale_px)
    return ScaleOffset(float(p[0]), p[1:3].copy(), c, float(sig[0]), sig[1:3].copy(), rms, n)


def normalise_to_median(fits: Sequence[ScaleOffset]) -> list[ScaleOffset]:
    """Per attempt, the correction into the refocus stack's median geometry (§3.5.3, 2.b.1).

    ``fits[i]`` maps the reference attempt onto attempt i (:func:`fit_scale_offset` of the
    reference's points to attempt i's). The median attempt has scale median(s_i) and offset
    median(o_i); the correction of attempt i maps its pixels there:
    ``q_med = (s_m/s_i)·(q_i − c − o_i) + c + o_m``. Failed fits get an identity (not ok).

    Examples
    --------
    >>> c = np.array([0.0, 0.0])
    >>> fits = [ScaleOffset(s, np.zeros(2), c) for s in (1.0, 1.002, 0.999)]
    >>> [round(f.scale, 6) for f in normalise_to_median(fits)]
    [1.0, 0.998004, 1.001001]
    """
    if not fits:
        raise InputError("normalise_to_median needs at least one attempt's fit")
    good = [f for f in fits if f.ok]
    if not good:
        return [ScaleOffset.identity(f.center_px) for f in fits]
    c = good[0].center_px
    s_m = float(np.median([f.scale for f in good]))
    o_m = np.median(np.array([f.offset_px for f in good]), axis=0)
    out = []
    for f in fits:
        if not f.ok:
            out.append(ScaleOffset(1.0, np.zeros(2), c, ok=False, reason=f.reason))
            continue
        k = s_m / f.scale
        out.append(
            ScaleOffset(k, o_m - k * np.asarray(f.offset_px), c, f.sigma_scale * k / f.scale,
                        np.asarray(f.sigma_offset_px), f.rms_px, f.n)
        )
    return out


__all__ = [
    "MIN_POINTS",
    "ScaleOffset",
    "fit_scale_offset",
    "normalise_to_median",
]
