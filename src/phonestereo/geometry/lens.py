"""Lens distortion models on normalised image coordinates (thesis §1.1.1, §3.2).

A lens model maps ideal normalised coordinates ``(x, y) = (X/Z, Y/Z)`` to distorted normalised
coordinates ``(x_d, y_d)``; the camera matrix K then maps those to pixels. Every model shares
the OpenCV tangential terms and differs in its radial factor ``g``::

    x_d = x·g + 2·p1·x·y + p2·(r² + 2x²)
    y_d = y·g + p1·(r² + 2y²) + 2·p2·x·y

Models
------
``opencv5``   g = 1 + k1 r² + k2 r⁴ + k3 r⁶                      coefficients (k1, k2, p1, p2, k3)
``opencv8``   g = (1 + k1 r² + k2 r⁴ + k3 r⁶) / (1 + k4 r² + k5 r⁴ + k6 r⁶)
              coefficients (k1, k2, p1, p2, k3, k4, k5, k6)  — OpenCV's order, so they round-trip
``radial-odd`` g = 1 + Σᵢ kᵢ rⁱ, i = 1..n, odd degrees included (thesis §3.2 fix 1)
              coefficients (k1, …, kn, p1, p2)

Undistortion is Newton's method with the analytic Jacobian; it converges to |distort(u) − x_d|
≤ 1e-12 (normalised units) and then takes one more Newton step, so the result is at rounding
level (≈ 1e-16, far below 1e-9 px at f = 4500 px) inside the valid field. The valid field is the
disc |u| < :attr:`LensModel.valid_radius` around the centre, where the model is one-to-one:
det J > 0 and the radial map increasing along every direction from the centre. Points outside
it (including solutions on the folded-over branch beyond it), or that do not converge, come
back NaN.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property, lru_cache
from typing import Any, ClassVar

import numpy as np

from phonestereo.errors import InputError
from phonestereo.geometry.checks import Array, as_points

UNDISTORT_TOL = 1e-12
MAX_RADIAL_TERMS = 10  # most radial terms k1 … kn of a model with a variable number of them
VALID_RADIUS_MAX = 20.0  # normalised radius scanned for the valid field (87° off axis)


@dataclass(frozen=True)
class LensModel(ABC):
    """Base class: a distortion model with a flat coefficient vector in its documented order."""

    #: tuple of float. Model coefficients in the order of the model's docstring.
    coefficients: tuple[float, ...]
    name: ClassVar[str] = ""
    #: The coefficients' names in their order, for a model with a fixed number of them (OpenCV's);
    #: :attr:`n_range`, :attr:`layout` and :attr:`p1_index` follow from them.
    coefficient_names: ClassVar[tuple[str, ...]] = ()
    #: Or, for a model with n radial terms k1 … kn first (1 ≤ n ≤ :data:`MAX_RADIAL_TERMS`), the
    #: names of the coefficients after them; the same three follow from these.
    after_radial: ClassVar[tuple[str, ...]] = ()
    #: Fewest and most coefficients the model takes.
    n_range: ClassVar[tuple[int, int]] = (0, 0)
    #: The coefficients the model takes, as its count error names them.
    layout: ClassVar[str] = ""
    #: Index of p1 in :attr:`coefficients`, p2 following it (2: OpenCV's order k1, k2, p1, p2, …);
    #: negative: counted from the end.
    p1_index: ClassVar[int] = 2

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Set a model's :attr:`n_range`, :attr:`layout` and :attr:`p1_index` from its names."""
        super().__init_subclass__(**kwargs)
        names, tail = cls.coefficient_names, cls.after_radial
        if names:
            cls.n_range = (len(names), len(names))
            cls.layout = f"{len(names)} coefficients ({', '.join(names)})"
            cls.p1_index = names.index("p1")
        elif tail:
            cls.n_range = (1 + len(tail), MAX_RADIAL_TERMS + len(tail))
            cls.layout = (
                f"(k1, …, kn, {', '.join(tail)}) with 1 <= n <= {MAX_RADIAL_TERMS} radial terms"
            )
            cls.p1_index = tail.index("p1") - len(tail)

    def __post_init__(self) -> None:
        coeffs = tuple(float(c) for c in self.coefficients)
        if not all(np.isfinite(coeffs)):
            raise InputError(f"lens '{self.name}' coefficients must be finite, got {coeffs}")
        self._check_count(len(coeffs))
        object.__setattr__(self, "coefficients", coeffs)

    def _check_count(self, n: int) -> None:
        lo, hi = self.n_range
        if not lo <= n <= hi:
            raise InputError(f"lens '{self.name}' takes {self.layout}, got {n} coefficients")

    # --- model-specific parts -------------------------------------------------------------
    @abstractmethod
    def _radial(self, r2: Array) -> tuple[Array, Array, Array]:
        """Return g, dg/d(r²)·(r² ≠ 0 safe form is handled by callers), dg/dcoeff (…, n)."""

    @property
    def tangential_columns(self) -> tuple[int, int]:
        """Indices of the tangential coefficients (p1, p2) in :attr:`coefficients`."""
        i = self.p1_index % self.n_coefficients
        return i, i + 1

    def _tangential(self) -> tuple[float, float]:
        i1, i2 = self.tangential_columns
        return self.coefficients[i1], self.coefficients[i2]

    # --- shared API -----------------------------------------------------------------------
    @property
    def n_coefficients(self) -> int:
        """Number of coefficients of this model."""
        return len(self.coefficients)

    def is_identity(self) -> bool:
        """True when every coefficient is zero (a pinhole lens)."""
        return not any(self.coefficients)

    def with_coefficients(self, coefficients: Any) -> LensModel:
        """Return the same model with new coefficients."""
        return type(self)(tuple(float(c) for c in np.ravel(coefficients)))

    @cached_property
    def valid_radius(self) -> float:
        """Radius of the valid field in normalised units (computed once per lens).

        The last radius before det J ≤ 0 or |distort(u)| stops increasing, scanned along 16
        directions (step 2e-3 to r = 4, 2e-2 to r = 20); :data:`VALID_RADIUS_MAX` if no fold.

        Examples
        --------
        >>> from phonestereo.geometry import OpenCV5
        >>> round(OpenCV5((-0.1, 0.0, 0.0, 0.0, 0.0)).valid_radius, 2)   # 1/sqrt(3·0.1)
        1.82
        """
        return self._field[0]

    @cached_property
    def _field(self) -> tuple[float, Array, Array]:
        """(valid radius, r grid, radial-only distorted radius r·g(r²)) on [0, valid radius]."""
        # A lens is its type and coefficients: rigs rebuilt per capture (focus or W-T scales,
        # a window rectification) share the scan (~5 ms) instead of repeating it.
        return _lens_field(type(self), self.coefficients)

    def _scan_field(self) -> tuple[float, Array, Array]:
        """The scan behind :attr:`_field` (see :attr:`valid_radius`)."""
        r = np.concatenate([np.arange(0, 2001) * 2e-3, 4.0 + np.arange(1, 801) * 2e-2])
        ang = np.arange(16) * (np.pi / 8)
        pts = r[1:, None, None] * np.stack([np.cos(ang), np.sin(ang)], axis=-1)[None]
        with np.errstate(all="ignore"):
            good = _det(self.jacobian_point(pts)) > 0
            good[1:] &= np.diff(np.linalg.norm(self.distort(pts), axis=-1), axis=0) > 0
            rd = r * self._radial(r * r)[0]
        bad = np.flatnonzero(~np.all(good, axis=1))
        n = bad[0] + 1 if bad.size else r.size  # r[n - 1] is the last good radius
        # The radial-only map seeds Newton; keep its increasing part (tangential terms aside).
        inc = np.flatnonzero(~(np.diff(rd[:n]) > 0))
        m = inc[0] + 1 if inc.size else n
        radius = float(r[n - 1]) if bad.size else VALID_RADIUS_MAX
        return radius, r[:m].copy(), rd[:m].copy()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{"model": name, "coefficients": [...]}``."""
        return {"model": self.name, "coefficients": list(self.coefficients)}

    def distort(self, xy: Any) -> Array:
        """Distort ideal normalised coordinates.

        Parameters
        ----------
        xy : array_like, shape (..., 2)
            Ideal normalised coordinates (X/Z, Y/Z), unitless.

        Returns
        -------
        ndarray, shape (..., 2)
            Distorted normalised coordinates.

        Examples
        --------
        >>> from phonestereo.geometry import OpenCV5
        >>> lens = OpenCV5((0.1, 0.0, 0.0, 0.0, 0.0))
        >>> lens.distort([0.5, 0.0]).round(6).tolist()   # 0.5·(1 + 0.1·0.25)
        [0.5125, 0.0]
        """
        p = as_points(xy, 2, "xy")
        x, y = p[..., 0], p[..., 1]
        r2: Array = np.asarray(x * x + y * y, dtype=np.float64)
        g, _, _ = self._radial(r2)
        p1, p2 = self._tangential()
        xd = x * g + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * g + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def jacobian_point(self, xy: Any) -> Array:
        """Jacobian of :meth:`distort` with respect to the point.

        Returns
        -------
        ndarray, shape (..., 2, 2)
            ``J[..., i, j] = d xd_i / d x_j``.
        """
        p = as_points(xy, 2, "xy")
        x, y = p[..., 0], p[..., 1]
        r2: Array = np.asarray(x * x + y * y, dtype=np.float64)
        g, dg_dr2, _ = self._radial(r2)
        p1, p2 = self._tangential()
        # x²·g' and x·y·g' written so that models with an r¹ term stay finite at r = 0.
        xx = np.where(r2 > 0, x * x * dg_dr2, 0.0)
        xy_ = np.where(r2 > 0, x * y * dg_dr2, 0.0)
        yy = np.where(r2 > 0, y * y * dg_dr2, 0.0)
        j = np.empty((*x.shape, 2, 2))
        j[..., 0, 0] = g + 2 * xx + 2 * p1 * y + 6 * p2 * x
        j[..., 0, 1] = 2 * xy_ + 2 * p1 * x + 2 * p2 * y
        j[..., 1, 0] = 2 * xy_ + 2 * p1 * x + 2 * p2 * y
        j[..., 1, 1] = g + 2 * yy + 6 * p1 * y + 2 * p2 * x
        return j

    def jacobian_coefficients(self, xy: Any) -> Array:
        """Jacobian of :meth:`distort` with respect to the coefficients.

        Returns
        -------
        ndarray, shape (..., 2, n_coefficients)
        """
        p = as_points(xy, 2, "xy")
        x, y = p[..., 0], p[..., 1]
        r2: Array = np.asarray(x * x + y * y, dtype=np.float64)
        _, _, dg_dc = self._radial(r2)
        j = np.empty((*x.shape, 2, self.n_coefficients))
        j[..., 0, :] = x[..., None] * dg_dc
        j[..., 1, :] = y[..., None] * dg_dc
        i1, i2 = self.tangential_columns
        j[..., 0, i1] = 2 * x * y
        j[..., 0, i2] = r2 + 2 * x * x
        j[..., 1, i1] = r2 + 2 * y * y
        j[..., 1, i2] = 2 * x * y
        return j

    def undistort(self, xy_d: Any, *, tol: float = UNDISTORT_TOL, max_iter: int = 50) -> Array:
        """Invert :meth:`distort` by damped Newton iterations.

        Parameters
        ----------
        xy_d : array_like, shape (..., 2)
            Distorted normalised coordinates.
        tol : float
            Convergence threshold on |distort(u) − xy_d| (max norm, normalised units).
        max_iter : int
            Iteration cap.

        Returns
        -------
        ndarray, shape (..., 2)
            Ideal normalised coordinates; NaN where the point lies outside the valid field or
            did not converge to ``tol``.

        Examples
        --------
        >>> from phonestereo.geometry import OpenCV5
        >>> lens = OpenCV5((-0.2, 0.05, 1e-3, -5e-4, 0.0))
        >>> u = lens.undistort(lens.distort([0.3, -0.2]))
        >>> bool(np.allclose(u, [0.3, -0.2], atol=1e-12))
        True
        """
        target = as_points(xy_d, 2, "xy_d")
        if self.is_identity():
            return target.copy()
        shape = target.shape
        t = target.reshape(-1, 2)
        # Start from the inverse of the radial-only map (a 1-D table), so Newton starts on the
        # principal branch anywhere in the valid field, even near the fold.
        _, r_tab, rd_tab = self._field
        rd = np.hypot(t[:, 0], t[:, 1])
        # Far outside the field Newton may diverge to overflow; those points end up NaN.
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            u: Array = t * np.where(rd > 0, np.interp(rd, rd_tab, r_tab) / rd, 1.0)[:, None]
            res = self.distort(u) - t
            err = np.max(np.abs(res), axis=-1)
            active = np.isfinite(err) & (err > tol)
            for _ in range(max_iter):
                if not np.any(active):
                    break
                ua, ta, ea = u[active], t[active], err[active]
                step = _solve2(self.jacobian_point(ua), res[active])
                # Damping: halve the step until the residual does not grow (at most 8 times).
                new_u = ua - step
                new_r = self.distort(new_u) - ta
                new_e = np.max(np.abs(new_r), axis=-1)
                for _ in range(8):
                    worse = ~(new_e <= ea)
                    if not np.any(worse):
                        break
                    step[worse] *= 0.5
                    new_u[worse] = ua[worse] - step[worse]
                    new_r[worse] = self.distort(new_u[worse]) - ta[worse]
                    new_e[worse] = np.max(np.abs(new_r[worse]), axis=-1)
                idx = np.flatnonzero(active)
                improved = new_e <= ea
                u[idx[improved]] = new_u[improved]
                res[idx[improved]] = new_r[improved]
                err[idx[improved]] = new_e[improved]
                active[idx] = improved & (new_e > tol)
            # Outside the valid field the model folds over: reject det J <= 0 and solutions
            # beyond the valid radius (the folded branch can have det J > 0 again, g < 0).
            j = self.jacobian_point(u)
            ok = (err <= tol) & (_det(j) > 0) & (np.hypot(u[:, 0], u[:, 1]) < self.valid_radius)
            # One polishing Newton step on converged points takes the residual from <= tol to
            # rounding level (quadratic convergence); kept only where it does not grow.
            up = u[ok] - _solve2(j[ok], res[ok])
            better = np.max(np.abs(self.distort(up) - t[ok]), axis=-1) <= err[ok]
            u[np.flatnonzero(ok)[better]] = up[better]
        u[~ok] = np.nan
        return u.reshape(shape)


def _solve2(j: Array, res: Array) -> Array:
    """J⁻¹ · res for Jacobians (N, 2, 2) and residuals (N, 2): the Newton step."""
    det = _det(j)
    dx = (j[..., 1, 1] * res[:, 0] - j[..., 0, 1] * res[:, 1]) / det
    dy = (-j[..., 1, 0] * res[:, 0] + j[..., 0, 0] * res[:, 1]) / det
    return np.stack([dx, dy], axis=-1)


@lru_cache(maxsize=64)
def _lens_field(
    cls: type[LensModel], coefficients: tuple[float, ...]
) -> tuple[float, Array, Array]:
    """:meth:`LensModel._scan_field` per (model, coefficients), remembered; arrays read-only."""
    radius, r, rd = cls(coefficients)._scan_field()
    r.flags.writeable = False
    rd.flags.writeable = False
    return radius, r, rd


def _det(j: Array) -> Array:
    """Determinants of 2×2 matrices (..., 2, 2)."""
    return np.asarray(j[..., 0, 0] * j[..., 1, 1] - j[..., 0, 1] * j[..., 1, 0], dtype=np.float64)
