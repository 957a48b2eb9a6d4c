"""The pair's own misfit model: its typical window residual and the residual's autocorrelation.

Sensor noise is white, and the Cramér–Rao σ_d of :mod:`~phonestereo.features.crlb` assumes it.
Images out of a phone's ISP are not: demosaicing, denoising, sharpening and JPEG leave a misfit
between corresponding windows that is larger than the sensor noise the image shows (compression
and denoising even *lower* the Immerkær estimate) and spatially correlated (blocks, halos,
smoothed noise). Two things are therefore measured on the pair's own converged windows:

* **the misfit floor** — a robust typical value of the window residual variance in units of the
  noise model, max(1, median s²_k / (σ_L² + a_k²σ_R²) / typical): the residual test then
  rejects a window that fits much worse than the pair's typical window, not one that fits worse
  than the sensor noise alone would allow (:func:`misfit_floor`). ``typical`` is what clean real
  pairs already show (2–6 noise variances), so on them nothing changes; JPEG q85 reads 52. The
  same is done for the normalised residual s² / window variance (≈ 1 − ZNCC²), whose typical
  value rises from 0.014 (clean) to 0.07 (q85) because compression removes low-contrast detail;
  its bound is also raised to the upper tail of the pair's own windows, median + 2·σ_MAD
  (:func:`misfit_tail`), where a one-sided denoiser widens the spread (0.005–0.19 between the
  10th and 90th percentiles on Adirondack) without the high-ratio windows' disparities being
  worse.
* **the residual autocorrelation** ρ(δ) at lags |δx|, |δy| ≤ 3 px, pooled over the windows
  (:func:`residual_correlation`). For a window of influence image G (d̂ − d = Σ_p G(p) n(p),
  from :func:`~phonestereo.features.subpixel.refine_lk`) the variance of d̂ under a residual of
  variance s² and correlation ρ is the sandwich with the correlated meat::

      Var d̂ = s² Σ_pq G(p) ρ(p − q) G(q) = s² Σ_δ ρ(δ) A_G(δ),

  A_G the autocorrelation of G. :func:`correlation_factor` returns Σ_δ ρ(δ) A_G(δ) / A_G(0),
  the factor on the white-noise variance s²·Σ G² (1 for white residuals; > 1 when the misfit
  is smooth at the scale of the gradients, < 1 when it oscillates, as after sharpening).

Both are computed with FFTs of the small window images (NumPy), a few ms for 2000 windows.

Measured (benchmarks/bench_match_isp.py): the floor and the tail keep 82 / 81 % of
Adirondack's matches at JPEG q85 / q70 (14 / 0 before; 82 / 76 % before the compression-limited
wide fit) and the sharpened pair's 96 % (0 before). The floor also decides that a pair is
compression-limited (``MatchConfig.wide_floor``). The correlation factor is 0.9–1.4 on JPEG
and ISP renders and changed no figure with the 15 × 15 window; on a relative blur it reads the
deterministic even misfit (which does not move d) as correlated noise and over-states σ_d
(within σ 0.83–0.87), so the matcher leaves it off by default (``MatchConfig.correlated_misfit``)
except in the compression-limited 23 × 23 fit of a pair without blur equalisation, where the
white σ under-states it (Adirondack JPEG q85 / q70 within σ 0.44 / 0.40 → 0.52 / 0.50).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

MAX_LAG = 3  # px: lags of the residual autocorrelation used (the ISP's kernels are ≤ 7 px)
MIN_WINDOWS = 20  # fewer converged windows: white residual assumed
_FFT = 32  # ≥ M + MAX_LAG for windows up to M = 29 (radius 14); larger windows: next power of 2


def misfit_floor(residual_var: F64, model_var: F64, *, typical: float = 1.0) -> float:
    """max(1, median(s² / σ_r²) / typical): the pair's excess misfit in units of its noise model.

    ``typical`` is the median ratio a pair without ISP processing already shows (the misfit of
    rectification, surfaces and interpolation the fit does not model; Middlebury-Q Adirondack
    measures 2.0, the motorcycle's GT-consistent pair 5.7): only the misfit beyond it raises
    the floor.

    Parameters
    ----------
    residual_var : ndarray, shape (N,)
        A-posteriori residual variance of each converged window, DN².
    model_var : ndarray, shape (N,)
        The noise model of each window σ_L² + a²σ_R², DN².

    Returns
    -------
    float
        ≥ 1; 1 when there are no finite ratios.

    >>> misfit_floor(np.array([4.0, 5.0, 6.0, 90.0]), np.ones(4))      # JPEG-like misfit
    5.5
    >>> misfit_floor(np.array([0.5, 0.8, 1.2]), np.ones(3))            # a clean pair
    1.0
    """
    ratio = np.asarray(residual_var, np.float64) / np.asarray(model_var, np.float64)
    ratio = ratio[np.isfinite(ratio)]
    if not len(ratio):
        return 1.0
    return max(1.0, float(np.median(ratio)) / float(typical))


def misfit_tail(ratio: F64, *, k: float = 2.0) -> float:
    """median + k·σ_MAD of the finite ``ratio`` values (σ_MAD = 1.4826 · MAD); NaN if none.

    The upper tail of the pair's own distribution of a window statistic: a window beyond it
    fits much worse than the pair's windows do, whatever the pair's processing. Used for the
    normalised residual s² / window variance, whose spread a one-sided denoiser or JPEG widens
    (the low-contrast windows lose their texture on one side only) without the windows'
    disparity getting worse.

    >>> round(misfit_tail(np.array([0.01, 0.02, 0.02, 0.03, 0.5])), 4)   # 0.02 + 2·1.4826·0.01
    0.0497
    """
    r = np.asarray(ratio, np.float64)
    r = r[np.isfinite(r)]
    if not len(r):
        return float("nan")
    med = float(np.median(r))
    return med + float(k) * 1.4826 * float(np.median(np.abs(r - med)))


def _size(m: int) -> int:
    return _FFT if m + MAX_LAG <= _FFT else int(2 ** np.ceil(np.log2(m + MAX_LAG)))


def _autocorrelation_sums(images: F64, m: int) -> F64:
    """Σ over images of Σ_p x(p)·x(p + δ) for |δ| ≤ MAX_LAG, shape (2L + 1, 2L + 1)."""
    n = _size(m)
    spec = np.fft.rfft2(images.reshape(-1, m, m), s=(n, n))
    acf = np.fft.irfft2((spec * spec.conj()).real.sum(axis=0), s=(n, n))
    lags = np.arange(-MAX_LAG, MAX_LAG + 1) % n
    return np.asarray(acf[np.ix_(lags, lags)], np.float64)


def residual_correlation(residual: F32, m: int) -> F64:
    """Pooled autocorrelation ρ(δy, δx) of the window residuals, ρ(0) = 1, shape (7, 7).

    Each lag's sum is divided by the pixel pairs it has inside an M × M window, so ρ is an
    unbiased ratio of the lag's mean product to the mean square. Windows are mean-removed
    (the fit has an offset). Fewer than :data:`MIN_WINDOWS` finite windows: white (a delta).

    Parameters
    ----------
    residual : ndarray, shape (N, M²)
        Residual images L − a·R − b of the converged windows (row-major), DN.
    m : int
        Window side M, px.

    Examples
    --------
    White noise smoothed by [1, 2, 1]/4 along x: ρ(0, ±1) = 4/6, ρ(0, ±2) = 1/6.

    >>> rng = np.random.default_rng(0)
    >>> noise = rng.standard_normal((400, 17 * 17))
    >>> k = np.array([0.25, 0.5, 0.25])
    >>> img = np.apply_along_axis(lambda r: np.convolve(r, k, "same"), 2,
    ...                           noise.reshape(400, 17, 17)).reshape(400, -1)
    >>> rho = residual_correlation(img, 17)
    >>> bool(abs(rho[3, 4] - 4 / 6) < 0.03), bool(abs(rho[3, 5] - 1 / 6) < 0.03)
    (True, True)
    >>> bool(abs(rho[4, 3]) < 0.03)                        # no correlation across rows
    True
    """
    r = np.asarray(residual, np.float64)
    r = r[np.isfinite(r).all(axis=1)]
    white = np.zeros((2 * MAX_LAG + 1,) * 2)
    white[MAX_LAG, MAX_LAG] = 1.0
    if len(r) < MIN_WINDOWS:
        return white
    r = r - r.mean(axis=1, keepdims=True)
    sums = _autocorrelation_sums(r, m)
    overlap = m - np.abs(np.arange(-MAX_LAG, MAX_LAG + 1))
    mean = sums / np.outer(overlap, overlap)
    if not mean[MAX_LAG, MAX_LAG] > 0:
        return white
    return np.asarray(mean / mean[MAX_LAG, MAX_LAG], np.float64)


def correlation_factor(influence: F32, rho: F64, *, floor: float = 0.25) -> F64:
    """Σ_δ ρ(δ)·A_G(δ) / A_G(0) per window: Var d̂ for correlated residuals / white, shape (N,).

    Parameters
    ----------
    influence : ndarray, shape (N, M²)
        Influence images of the estimate (``Refinement.influence[:, 0]`` for d).
    rho : ndarray, shape (2L + 1, 2L + 1)
        Residual autocorrelation from :func:`residual_correlation`.
    floor : float
        Lower bound of the factor: a residual that oscillates (sharpening) can cancel much of
        the white variance in theory; the estimate of ρ is not trusted to more than 4×.

    Returns
    -------
    ndarray, shape (N,)
        1 for a white ρ; NaN where the influence image is not finite.

    >>> g = np.zeros((1, 15 * 15)); g[0, 7 * 15 + 7] = 1.0          # one pixel: no lags
    >>> rho = np.full((7, 7), 0.5); rho[3, 3] = 1.0
    >>> correlation_factor(g, rho).round(3).tolist()
    [1.0]
    >>> g = np.ones((1, 15 * 15))                                   # a flat influence image
    >>> round(float(correlation_factor(g, rho)[0]), 1)     # 1 + 0.5·Σ_δ≠0 (15−|δx|)(15−|δy|)/225
    19.7
    """
    g = np.asarray(influence, np.float64)
    out = np.full(len(g), np.nan)
    fin = np.isfinite(g).all(axis=1)
    if not fin.any():
        return out
    m = round(float(np.sqrt(g.shape[1])))
    n = _size(m)
    spec = np.fft.rfft2(g[fin].reshape(-1, m, m), s=(n, n))
    acf = np.fft.irfft2((spec * spec.conj()).real, s=(n, n))
    lags = np.arange(-MAX_LAG, MAX_LAG + 1) % n
    a = acf[:, lags][:, :, lags]  # (k, 2L + 1, 2L + 1)
    zero = a[:, MAX_LAG, MAX_LAG]
    factor = np.einsum("kij,ij->k", a, rho) / np.maximum(zero, 1e-300)
    out[fin] = np.maximum(factor, floor)
    return out
