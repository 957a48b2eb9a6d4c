"""Cramér–Rao uncertainty of a window match (docs/architecture.md): σ_d per match from the images.

Model: left window T(u) = a·R(warp(u; θ)) + b + n(u), n white with variance σ_r² per pixel. For
two images that both carry sensor noise σ_n, σ_r² = σ_n,L² + a²·σ_n,R² (≈ 2 σ_n²). The
Gaussian-weighted least-squares estimate (weights w, Jacobian J = ∂(aR + b)/∂θ, shape
(P, M²)) has the sandwich covariance::

    Cov θ̂ = σ_r² · H⁻¹ (Jᵀ W² J) H⁻¹,   H = Jᵀ W J,

which for uniform weights is the Cramér–Rao bound σ_r² (JᵀJ)⁻¹; for a pure 1-D shift it reduces
to the textbook σ_d² = σ_r² Σ w² g_x² / (Σ w g_x²)² (≥ σ_r² / Σ g_x²). Honest σ also needs what
the model leaves out (interpolation, perspective inside the window, occlusion, non-Lambertian
surfaces): the a-posteriori residual variance s² = Σ w r² / (Σ w − tr(H⁻¹JᵀW²J)) estimates σ_r²
including that misfit, and :func:`match_sigma` uses max(s², σ_r² from the noise) — never below
the noise bound, larger where the window does not fit.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray


def _c_einsum() -> Callable[..., Any]:
    """NumPy's C einsum, which ``np.einsum`` (``optimize=False``) calls as is: the same values
    without its Python wrapper and ``__array_function__`` dispatch (~2 µs a call, more than the
    K × P contractions in :func:`solve_spd`'s loops; ~1 900 calls per learning capture)."""
    for name in ("numpy.core._multiarray_umath", "numpy._core._multiarray_umath"):
        try:
            fn = getattr(importlib.import_module(name), "c_einsum", None)
        except ImportError:  # pragma: no cover - another NumPy layout
            continue
        if callable(fn):
            return fn  # type: ignore[no-any-return]
    return np.einsum  # pragma: no cover


#: :func:`numpy.einsum` without its dispatch overhead (:func:`_c_einsum`); plain operands only.
einsum = _c_einsum()

F64 = NDArray[np.float64]

_MAD = 1.4826  # σ / MAD of a Gaussian
_SAMPLES = 40_000  # pixels behind the noise median


def noise_rows(height: int, width: int) -> NDArray[np.int64]:
    """The rows r whose mask responses :func:`noise_sigma` takes (it reads rows r − 1, r, r + 1
    of an image of that size; an image known only there has the same σ).

    >>> noise_rows(1500, 2000)[:3].tolist()
    [1, 75, 149]
    """
    step = max(1, int((height - 2) * (width - 2) / _SAMPLES))
    return np.arange(1, height - 1, step)


def noise_sigma(image: Any) -> float:
    """Robust per-pixel noise σ of an image, DN: median |k ∗ I| / 6 · 1.4826 (Immerkær mask k).

    The mask annihilates constant and linear intensity (and most of a smooth texture), so the
    median of its response is the noise; flat and textured regions both count, edges are few.
    For integer images (8-bit) the median is interpolated within its integer group, so that σ is
    not quantised to steps of 0.25 DN.

    >>> rng = np.random.default_rng(0)
    >>> yy, xx = np.mgrid[0:300, 0:300]
    >>> img = 100 + 0.3 * xx + 20 * np.sin(xx / 9.0) + 2.0 * rng.standard_normal((300, 300))
    >>> round(noise_sigma(img), 1)                         # σ = 2 DN under a smooth texture
    2.0
    """
    img = np.asarray(image, dtype=np.float32)
    h, w = img.shape
    if h < 3 or w < 3:
        return float("nan")
    # the mask is the outer product [1, −2, 1]ᵀ[1, −2, 1]: evaluate it on a subset of rows
    rows = noise_rows(h, w)
    v = img[rows - 1] - 2 * img[rows] + img[rows + 1]
    resp = np.abs(v[:, :-2] - 2 * v[:, 1:-1] + v[:, 2:]).ravel()
    if not len(resp):
        return float("nan")
    med = float(np.median(resp))
    if np.array_equal(resp, np.rint(resp)):  # integer data: median of grouped data
        below = np.count_nonzero(resp < med)
        at = np.count_nonzero(resp == med)
        med = med - 0.5 + (0.5 * len(resp) - below) / max(at, 1)
        med = max(med, 0.0)
    return float(_MAD * med / 6.0)


def weighted_ls_covariance(jac: F64, weights: F64) -> tuple[F64, F64]:
    """Sandwich covariance per unit residual variance and the residual degrees of freedom.

    Parameters
    ----------
    jac : ndarray, shape (K, P, M)
        Jacobian of the model w.r.t. P parameters at M samples, for K windows.
    weights : ndarray, shape (M,)
        Least-squares weights w.

    Returns
    -------
    cov : ndarray, shape (K, P, P)
        H⁻¹ (JᵀW²J) H⁻¹ with H = JᵀWJ (multiply by σ_r² for the covariance).
    dof : ndarray, shape (K,)
        Σ w − tr(H⁻¹ JᵀW²J): E[Σ w r²] = σ_r² · dof for white residuals.

    Examples
    --------
    A 1-D shift on a sinusoid of amplitude 50 DN and period 16 px over 15 × 15 uniform weights:
    σ_d = σ_r / √(Σ g_x²), g_x the intensity slope.

    >>> u = np.tile(np.arange(-7, 8), 15).astype(float)
    >>> gx = 50 * 2 * np.pi / 16 * np.cos(2 * np.pi * u / 16)
    >>> cov, dof = weighted_ls_covariance(gx[None, None, :], np.ones(225))
    >>> round(float(np.sqrt(cov[0, 0, 0])) * 2.0, 4)   # px for σ_r = 2 DN (Σ g_x² ≈ 41 000)
    0.0099
    """
    j = np.asarray(jac, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)
    jw = j * w
    hess = jw @ j.transpose(0, 2, 1)
    meat = (jw * w) @ j.transpose(0, 2, 1)
    return sandwich(hess, meat, float(w.sum()))


def sandwich(hess: F64, meat: F64, weight_sum: float) -> tuple[F64, F64]:
    """H⁻¹ M H⁻¹ and Σw − tr(H⁻¹ M) from H = JᵀWJ (K, P, P) and M = JᵀW²J (K, P, P).

    See :func:`weighted_ls_covariance`; this is its second half, for callers that assembled
    H and M themselves.
    """
    hinv, _ = solve_spd(hess, np.broadcast_to(np.eye(hess.shape[1]), hess.shape))
    hm = hinv @ meat  # H⁻¹ JᵀW²J
    return hm @ hinv, weight_sum - einsum("kii->k", hm)


def solve_spd(a: F64, b: F64) -> tuple[F64, NDArray[np.bool_]]:
    """Solve K small symmetric positive-definite systems a x = b by a vectorised Cholesky.

    Parameters
    ----------
    a : ndarray, shape (K, P, P)
    b : ndarray, shape (K, P) or (K, P, Q)

    Returns
    -------
    x : ndarray, shape of ``b``
        The solutions (garbage where not ``ok``).
    ok : ndarray of bool, shape (K,)
        The matrix was numerically positive definite (pivot > 1e-12 of its diagonal).

    Batched LAPACK pays a per-matrix overhead; for P ≤ 8 a loop over P with NumPy vector
    operations across K is an order of magnitude faster.

    >>> a = np.array([[[4.0, 2.0], [2.0, 3.0]]])
    >>> x, ok = solve_spd(a, np.array([[2.0, 1.0]]))
    >>> x.round(6).tolist(), ok.tolist()
    ([[0.5, 0.0]], [True])
    """
    a = np.asarray(a, dtype=np.float64)
    vec = np.ndim(b) == 2
    y = np.array(b, dtype=np.float64)[..., None] if vec else np.array(b, dtype=np.float64)
    k, p, _ = a.shape
    low = np.zeros_like(a)
    ok = np.ones(k, bool)
    for j in range(p):
        piv = a[:, j, j] - einsum("ki,ki->k", low[:, j, :j], low[:, j, :j])
        ok &= piv > 1e-12 * np.abs(a[:, j, j]) + 1e-300
        low[:, j, j] = np.sqrt(np.where(ok, piv, 1.0))
        if j + 1 < p:
            dots = einsum("kri,ki->kr", low[:, j + 1 :, :j], low[:, j, :j])
            low[:, j + 1 :, j] = (a[:, j + 1 :, j] - dots) / low[:, j, j, None]
    for j in range(p):  # forward: L z = b
        y[:, j] -= einsum("ki,kiq->kq", low[:, j, :j], y[:, :j])
        y[:, j] /= low[:, j, j, None]
    for j in range(p - 1, -1, -1):  # back: Lᵀ x = z
        y[:, j] -= einsum("ki,kiq->kq", low[:, j + 1 :, j], y[:, j + 1 :])
        y[:, j] /= low[:, j, j, None]
    return (y[..., 0] if vec else y), ok


def match_sigma(
    cov_unit: F64,
    residual_var: F64,
    gain: F64,
    sigma_left: float,
    sigma_right: float,
    *,
    use_residual: bool = True,
    factor_d: F64 | None = None,
    factor_e: F64 | None = None,
) -> tuple[F64, F64, F64]:
    """σ_d, σ_e (px) and the σ_r² used (DN²) for each match.

    σ_r² = σ_L² + a²·σ_R² from the image noise (the Cramér–Rao floor), raised to the
    a-posteriori residual variance where the window fits worse than noise (``use_residual``).
    ``factor_d``, ``factor_e`` (shape (N,), default 1) multiply the residual term: the variance
    of d̂ (e) under the residual's measured autocorrelation over that under a white residual
    (:func:`~phonestereo.features.misfit.correlation_factor`); the noise floor stays white
    (its correlation after blur equalisation is already in σ_L, σ_R).

    >>> cov = np.array([[[1e-4, 0.0], [0.0, 2e-4]]])          # px²/DN²
    >>> sd, se, var = match_sigma(cov, np.array([1.0]), np.array([1.0]), 1.0, 1.0)
    >>> round(float(sd[0]), 4), round(float(se[0]), 4)        # σ_r² = 2 DN²
    (0.0141, 0.02)
    >>> sd, _, _ = match_sigma(cov, np.array([8.0]), np.array([1.0]), 1.0, 1.0,
    ...                        factor_d=np.array([2.0]))
    >>> round(float(sd[0]), 4)                                # 8 DN² residual, twice as smooth
    0.04
    """
    noise = (
        float(sigma_left) ** 2 + np.asarray(gain, dtype=np.float64) ** 2 * float(sigma_right) ** 2
    )
    res = np.asarray(residual_var, dtype=np.float64)
    if not use_residual:
        var = noise * np.ones_like(res)
        return np.sqrt(var * cov_unit[:, 0, 0]), np.sqrt(var * cov_unit[:, 1, 1]), var
    fd = np.ones_like(res) if factor_d is None else np.asarray(factor_d, np.float64)
    fe = np.ones_like(res) if factor_e is None else np.asarray(factor_e, np.float64)
    sd = np.sqrt(np.maximum(noise, res * fd) * cov_unit[:, 0, 0])
    se = np.sqrt(np.maximum(noise, res * fe) * cov_unit[:, 1, 1])
    return sd, se, np.maximum(noise, res)
