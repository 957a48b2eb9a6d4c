"""The lens models: OpenCV 5- and 8-coefficient Brown–Conrady and the odd-degree radial
polynomial (thesis §1.1.1, §3.2), the same about a distortion centre of its own, and the
registry that builds them by name.

The shared distortion/undistortion machinery is :class:`phonestereo.geometry.lens.LensModel`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import numpy as np

from phonestereo.errors import InputError
from phonestereo.geometry.checks import Array, as_points
from phonestereo.geometry.lens import UNDISTORT_TOL, LensModel


def _even_cubic(
    a: float, b: float, c: float, r2: Array
) -> tuple[Array, Array, tuple[Array, Array, Array]]:
    """``1 + a·r² + b·r⁴ + c·r⁶``, its derivative in r² and the powers (r², r⁴, r⁶).

    The radial factor of :class:`OpenCV5`, and the numerator and denominator of
    :class:`OpenCV8`'s; ``r2`` is r² of any shape (...), normalised units, and every output has
    that shape.
    """
    r4, r6 = r2 * r2, r2 * r2 * r2
    return 1 + a * r2 + b * r4 + c * r6, a + 2 * b * r2 + 3 * c * r4, (r2, r4, r6)


@dataclass(frozen=True)
class OpenCV5(LensModel):
    """OpenCV's 5-coefficient Brown–Conrady model (k1, k2, p1, p2, k3)."""

    name: ClassVar[str] = "opencv5"
    coefficient_names: ClassVar[tuple[str, ...]] = ("k1", "k2", "p1", "p2", "k3")

    def _radial(self, r2: Array) -> tuple[Array, Array, Array]:
        k1, k2, _, _, k3 = self.coefficients
        g, dg, powers = _even_cubic(k1, k2, k3, r2)
        dc = np.zeros((*r2.shape, 5))
        dc[..., 0], dc[..., 1], dc[..., 4] = powers
        return g, dg, dc


@dataclass(frozen=True)
class OpenCV8(LensModel):
    """OpenCV's 8-coefficient rational model (k1, k2, p1, p2, k3, k4, k5, k6)."""

    name: ClassVar[str] = "opencv8"
    coefficient_names: ClassVar[tuple[str, ...]] = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6")

    def _radial(self, r2: Array) -> tuple[Array, Array, Array]:
        k1, k2, _, _, k3, k4, k5, k6 = self.coefficients
        num, dnum, powers = _even_cubic(k1, k2, k3, r2)
        den, dden, _ = _even_cubic(k4, k5, k6, r2)
        with np.errstate(divide="ignore", invalid="ignore"):
            g = num / den
            dg = (dnum * den - num * dden) / (den * den)
            dc = np.zeros((*r2.shape, 8))
            dc[..., 0], dc[..., 1], dc[..., 4] = (p / den for p in powers)
            q = -num / (den * den)
            dc[..., 5], dc[..., 6], dc[..., 7] = (q * p for p in powers)
        return g, dg, dc


@dataclass(frozen=True)
class RadialOdd(LensModel):
    """Radial polynomial with every degree, odd ones included (thesis §3.2 fix 1).

    ``g = 1 + Σᵢ kᵢ rⁱ`` for i = 1..n, then the OpenCV tangential terms; coefficients
    ``(k1, …, kn, p1, p2)`` with 1 ≤ n ≤ 10.
    """

    name: ClassVar[str] = "radial-odd"
    after_radial: ClassVar[tuple[str, ...]] = ("p1", "p2")

    @property
    def n_radial(self) -> int:
        """Number of radial terms n."""
        return self.n_coefficients - 2

    def _radial(self, r2: Array) -> tuple[Array, Array, Array]:
        r = np.sqrt(r2)
        ks = self.coefficients[:-2]
        g = np.ones_like(r2)
        dg = np.zeros_like(r2)
        dc = np.zeros((*r2.shape, self.n_coefficients))
        with np.errstate(divide="ignore", invalid="ignore"):
            for i, k in enumerate(ks, start=1):
                ri = r**i
                g = g + k * ri
                dc[..., i - 1] = ri
                # dg/d(r²) = Σ i·k·r^(i−2) / 2; r = 0 is handled by callers via x²·g'.
                dg = dg + 0.5 * i * k * r ** (i - 2)
        return g, dg, dc


@dataclass(frozen=True)
class RadialOddCentred(LensModel):
    """``radial-odd`` about a distortion centre c of its own (``radial-odd-centred``).

    A real lens's distortion is radially symmetric about its optical axis, which a phone module's
    assembly places a few pixels to tens of pixels away from the principal point (Apple reports the
    two separately: ``lensDistortionCenter`` and ``intrinsicMatrix``). About the principal point,
    such a map is radial plus decentering terms of every order; OpenCV's tangential p1, p2 absorb
    only the lowest (the r² part), so a table about a centre 30 reference pixels off leaves 0.12 px
    that no ``radial-odd`` fit removes (measured on the virtual iPhone's wide camera). This model
    puts the centre into the model instead (normalised coordinates, unitless)::

        u = x − c,   x_d = c + RadialOdd(k1 … kn, p1, p2).distort(u)

    with coefficients ``(k1, …, kn, p1, p2, c_x, c_y)``. Everything is the inner ``radial-odd``
    map evaluated at ``u``; the Jacobians follow by the chain rule (∂x_d/∂x = J(u), ∂x_d/∂c =
    I − J(u)). Hand-written because no library lens model (OpenCV's included) has a distortion
    centre apart from the principal point. 1 ≤ n ≤ 10.

    Examples
    --------
    >>> lens = RadialOddCentred((0.1, 0.0, 0.0, 0.0, 0.01, 0.0))   # k1 r, centre (0.01, 0)
    >>> lens.distort([0.51, 0.0]).round(6).tolist()                  # 0.01 + 0.5·(1 + 0.1·0.5)
    [0.535, 0.0]
    >>> bool(np.allclose(lens.undistort(lens.distort([0.3, -0.2])), [0.3, -0.2], atol=1e-12))
    True
    """

    name: ClassVar[str] = "radial-odd-centred"
    after_radial: ClassVar[tuple[str, ...]] = ("p1", "p2", "c_x", "c_y")

    @cached_property
    def inner(self) -> RadialOdd:
        """The ``radial-odd`` map about the centre."""
        return RadialOdd(self.coefficients[:-2])

    @property
    def centre(self) -> Array:
        """The distortion centre c (2,), normalised units."""
        return np.array(self.coefficients[-2:], dtype=np.float64)

    @property
    def centre_columns(self) -> tuple[int, int]:
        """Indices of c_x, c_y in :attr:`coefficients`."""
        return self.n_coefficients - 2, self.n_coefficients - 1

    def _radial(self, r2: Array) -> tuple[Array, Array, Array]:
        """The inner model's radial factor of the radius about the centre (r² = |x − c|²)."""
        g, dg, dc = self.inner._radial(r2)
        pad = np.zeros((*r2.shape, 2))
        return g, dg, np.concatenate([dc, pad], axis=-1)

    @property
    def valid_radius(self) -> float:
        """Radius of a disc about the origin inside the valid field (inner radius − |c|)."""
        return max(self.inner.valid_radius - float(np.hypot(*self.centre)), 0.0)

    def distort(self, xy: Any) -> Array:
        """Distort ideal normalised coordinates (..., 2) → distorted (..., 2)."""
        c = self.centre
        return c + self.inner.distort(as_points(xy, 2, "xy") - c)

    def jacobian_point(self, xy: Any) -> Array:
        """∂x_d/∂x (..., 2, 2): the inner Jacobian at u = x − c."""
        return self.inner.jacobian_point(as_points(xy, 2, "xy") - self.centre)

    def jacobian_coefficients(self, xy: Any) -> Array:
        """∂x_d/∂coefficients (..., 2, n_coefficients); the centre's columns are I − J(u)."""
        u = as_points(xy, 2, "xy") - self.centre
        j_in = self.inner.jacobian_coefficients(u)
        j_c = np.eye(2) - self.inner.jacobian_point(u)
        return np.concatenate([j_in, j_c], axis=-1)

    def undistort(self, xy_d: Any, *, tol: float = UNDISTORT_TOL, max_iter: int = 50) -> Array:
        """Invert :meth:`distort` (the inner model's Newton solve about the centre)."""
        c = self.centre
        return c + self.inner.undistort(as_points(xy_d, 2, "xy_d") - c, tol=tol, max_iter=max_iter)


LENS_MODELS: dict[str, type[LensModel]] = {
    OpenCV5.name: OpenCV5,
    OpenCV8.name: OpenCV8,
    RadialOdd.name: RadialOdd,
    RadialOddCentred.name: RadialOddCentred,
}


def make_lens(name: str, coefficients: Any | None = None, *, n_radial: int = 6) -> LensModel:
    """Build a lens model by name; zero coefficients (a pinhole lens) when none are given.

    Parameters
    ----------
    name : {"opencv5", "opencv8", "radial-odd", "radial-odd-centred"}
    coefficients : array_like, optional
        Coefficients in the model's order.
    n_radial : int
        Number of radial terms for ``radial-odd`` when ``coefficients`` is omitted.

    Raises
    ------
    InputError
        Unknown model name or wrong coefficient count.
    """
    if name not in LENS_MODELS:
        raise InputError(f"unknown lens model '{name}'; choose one of {sorted(LENS_MODELS)}")
    cls = LENS_MODELS[name]
    if coefficients is None:
        n = len(cls.coefficient_names) or n_radial + len(cls.after_radial)
        coefficients = (0.0,) * n
    return cls(tuple(float(c) for c in np.ravel(np.asarray(coefficients, dtype=float))))


def lens_from_dict(data: dict[str, Any]) -> LensModel:
    """Inverse of :meth:`LensModel.to_dict`."""
    try:
        return make_lens(str(data["model"]), data["coefficients"])
    except KeyError as exc:
        raise InputError(f"lens entry needs 'model' and 'coefficients', missing {exc}") from exc
