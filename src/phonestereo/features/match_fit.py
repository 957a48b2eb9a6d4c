"""The sub-pixel fit of a pair's matched windows and the pair's misfit floor (:mod:`.matching`).

:func:`fit_windows` runs :func:`~phonestereo.features.subpixel.refine_lk` on the NCC matches,
applies its convergence tests, caps the image-based noise estimate by the windows' typical
residual and measures the pair's misfit floor and normalised-residual bound
(:mod:`~phonestereo.features.misfit`). The matcher calls it once, and a second time with a wider
window when the floor says the pair is compression-limited (``MatchConfig.wide_floor``;
:func:`first_fit` lets a probe of the windows say so without fitting them all twice).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.features._threads import background
from phonestereo.features.blur import gaussian_blur, gaussian_kernel
from phonestereo.features.cfa import shift_noise_factor
from phonestereo.features.match_config import MatchConfig
from phonestereo.features.misfit import misfit_floor, misfit_tail
from phonestereo.features.refinement import Refinement
from phonestereo.features.subpixel import bspline_coefficients, refine_lk

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
Mask = NDArray[np.bool_]

__all__ = [
    "Fit", "NoiseModel", "Windows", "first_fit", "fit_windows", "scaled", "wide_prefilter",
]


@dataclass(frozen=True)
class NoiseModel:
    """Per-pixel σ (left, right) of the images fitted, of the input model, and for the shift."""

    pixel: tuple[float, float]
    input: tuple[float, float]
    shift: tuple[float, float]


@dataclass(frozen=True, eq=False)
class Windows:
    """The N matched windows to fit: the images, the integer matches and the window size."""

    #: The left image, shape (H, W), float32.
    left: F32
    #: B-spline coefficients of the right image, shape (H, W), float32.
    coef: F32
    #: Integer left-window centres, shape (N, 2).
    xy: Any
    #: Disparities the search found, shape (N,), px.
    d0: F64
    #: Row errors the search found, shape (N,), px.
    e0: F64
    #: Window half-size, px.
    radius: int
    #: σ of the window's Gaussian weight, px.
    sigma_w: float

    def take(self, idx: Any) -> Windows:
        """The windows ``idx`` of these (same images and window size)."""
        return replace(self, xy=np.asarray(self.xy)[idx], d0=self.d0[idx], e0=self.e0[idx])


@dataclass(frozen=True, eq=False)
class Fit:
    """The windows' fit, which passed the sub-pixel tests, the floor and the noise after the cap."""

    ref: Refinement
    ok: Mask
    floor: float
    nbound: float
    noise: tuple[float, float]
    shift_noise: tuple[float, float]
    noise_var: F64


def scaled(pair: tuple[float, float], k: float) -> tuple[float, float]:
    """Both σ of ``pair`` times ``k``."""
    return (pair[0] * k, pair[1] * k)


def fit_windows(
    win: Windows, nm: NoiseModel, cfg: MatchConfig, correlated: bool = False
) -> Fit:
    """The sub-pixel fit of the windows, the noise cap and the pair's misfit floor."""
    d0, e0 = win.d0, win.e0
    ref = refine_lk(
        win.left,
        None,  # the template gradients are filtered from the left windows directly
        win.coef,
        win.xy,
        d0,
        e0,
        radius=win.radius,
        sigma_w=win.sigma_w,
        slant=cfg.slant,
        max_slant=cfg.max_slant,
        max_iter=cfg.max_iter,
        tol=cfg.tol,
        influence=correlated,
    )
    ok = ref.converged & (np.abs(ref.d - d0) <= cfg.max_shift)
    ok &= np.abs(ref.e - e0) <= cfg.max_shift
    noise, noise_in, shift_noise = nm.pixel, nm.input, nm.shift
    if cfg.noise_sigma is None and ok.any():  # texture inflates the image-based estimate
        k = _noise_cap(noise, ref.residual_var[ok], ref.gain[ok])
        noise, shift_noise, noise_in = (
            scaled(noise, k),
            scaled(shift_noise, k),
            scaled(noise_in, k),
        )
    noise_var = noise[0] ** 2 + ref.gain**2 * noise[1] ** 2
    # the pair's own misfit, in units of its input noise model: blur equalisation lowers the
    # computed noise of the blurred image, not the misfit a clean pair shows (rectification,
    # surfaces, interpolation), so `typical_misfit` keeps its meaning with or without it; a
    # pair whose blur difference the equalisation explains reads ≤ 1 (no floor), an ISP's
    # misfit beyond it raises the floor either way (features/misfit.py)
    floor, nbound = 1.0, cfg.max_normalized_residual**2
    if cfg.misfit_floor:
        input_var = noise_in[0] ** 2 + ref.gain**2 * noise_in[1] ** 2
        floor = misfit_floor(ref.residual_var[ok], input_var[ok], typical=cfg.typical_misfit)
        # the normalised residual's bound: raised by the pair's typical value, and to the
        # upper tail of its own windows where their spread is wider (one-sided processing)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = ref.residual_var[ok] / ref.template_std[ok] ** 2
        nbound *= misfit_floor(ratio, np.ones(len(ratio)), typical=cfg.typical_normalized)
        tail = misfit_tail(ratio, k=cfg.normalized_tail)
        nbound = max(nbound, tail) if np.isfinite(tail) else nbound
    return Fit(ref, ok, floor, nbound, noise, shift_noise, noise_var)


#: Windows of the probe fit that can decide a pair is compression-limited (:func:`first_fit`).
PROBE_WINDOWS = 48
#: The probe decides only when its floor is at least this many times ``wide_floor``.
PROBE_MARGIN = 2.0


def first_fit(
    win: Windows, nm: NoiseModel, cfg: MatchConfig, correlated: bool = False
) -> tuple[Fit, bool]:
    """The first fit of the windows and whether the pair is compression-limited (refit wide).

    A compression-limited pair discards the first fit: only its misfit floor (a median over
    the windows) decides the wide refit (``MatchConfig.wide_floor``). Every ``k``-th of the
    windows (:data:`PROBE_WINDOWS`) is fitted first; a probe floor ≥ :data:`PROBE_MARGIN` ×
    ``wide_floor`` decides alone (rendered phone JPEGs read 12-145 against 5), anything else
    fits all windows as before. The returned fit is then the probe's (it is discarded).
    """
    can_widen = cfg.misfit_floor and cfg.wide_radius > win.radius
    n = len(win.xy)
    if can_widen and n >= 2 * PROBE_WINDOWS:
        sub = np.linspace(0, n - 1, PROBE_WINDOWS).round().astype(np.int64)
        probe = fit_windows(win.take(sub), nm, cfg, correlated)
        if probe.floor >= PROBE_MARGIN * cfg.wide_floor:
            return probe, True
    fit = fit_windows(win, nm, cfg, correlated)
    return fit, bool(can_widen and fit.floor >= cfg.wide_floor)


def _noise_cap(noise: tuple[float, float], residual_var: F64, gain: F64) -> float:
    """Factor ≤ 1 on the image-based noise σ (left, right): the typical window residual bounds it.

    Fine texture inflates :func:`~phonestereo.features.crlb.noise_sigma`; the median residual
    variance of the window fits, s² ≈ σ_L² + a²·σ_R² (per pixel), bounds it. One factor scales
    both, so their ratio is kept: after blur equalisation one image's noise is a computed
    fraction of the other's, and capping each at one common value would under-count the
    noisier one. For σ_L = σ_R this is the cap min(σ, √median(s² / (1 + a²))) / σ.
    """
    model = noise[0] ** 2 + gain**2 * noise[1] ** 2
    k = float(np.sqrt(np.median(residual_var / model)))
    return min(k, 1.0) if np.isfinite(k) else 1.0


def wide_prefilter(
    left: F32, right: F32, noise: tuple[float, float], sigma: float
) -> tuple[F32, float, F32, tuple[float, float]]:
    """The wide refit's inputs of a compression-limited pair (:func:`first_fit`): the left
    prefiltered by a Gaussian of ``sigma`` px and its noise factor, the B-spline coefficients of
    the prefiltered right, and the shift-noise factors ρ (left, right) of that prefilter
    (:func:`~phonestereo.features.cfa.shift_noise_factor`, for the noise σ ``noise``).

    The right's prefilter, spline and ρ run on the helper thread while this one does the
    left's (equal shares; the same numbers as one after the other: at 12 MP the sequence was
    ~6 % of the application phase).
    """
    taps = gaussian_kernel(sigma)

    def right_side() -> tuple[F32, float]:
        coef = bspline_coefficients(gaussian_blur(right, sigma)[0])
        return coef, shift_noise_factor(right, noise[1], kernel=taps)

    pending = background(right_side)
    l_wide, gain = gaussian_blur(left, sigma)
    rho_left = shift_noise_factor(left, noise[0], kernel=taps)
    coef, rho_right = pending.result()
    return l_wide, gain, coef, (rho_left, rho_right)
