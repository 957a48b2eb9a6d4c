"""Relative blur of a matched pair and its equalisation (thesis §1.2.1, sparse matching).

The wide and the tele camera have different apertures and focus, so a rectified pair rarely
has the same sharpness. A window fitted across a blur difference misfits by the difference of
the two blurs (a Laplacian-like, even term): the disparity is not biased, but the residual is
far above the noise, so the residual test of the matcher drops the window and σ_d (raised to
the residual) widens. Blurring the sharper image by the difference makes the windows fit again;
a symmetric Gaussian does not move the correlation peak, so d stays unbiased.

The difference is measured on the windows the NCC search matched, in the Fourier domain: with
point-spread functions H_L, H_R, the power spectra of corresponding windows obey
P_L(f) / P_R(f) = a² · |H_L(f) / H_R(f)|² whatever the texture (a the photometric gain). The
power spectrum does not depend on the window's sub-pixel position, so the integer NCC match is
enough, and the sensor MTF, the pixel aperture and the texture spectrum cancel in the ratio.
The spectra of many windows are summed, the white-noise floor subtracted, and the sampled
Gaussian that, applied to one side, leaves the least residual power is chosen: one batched DFT
of small windows (~0.2 ms). It is applied only when it removes at least a noise variance of
misfit per window (:attr:`BlurEstimate.misfit_ratio`); the noise of the blurred image is then
computed from the kernel (per pixel for the residual test, and as seen by the window shift for
the Cramér–Rao σ_d), not re-estimated.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

__all__ = ["BlurEstimate", "EqualisedPair", "equalise_pair", "gaussian_blur", "relative_blur"]


def gaussian_kernel(sigma: float) -> F64:
    """Sampled 1-D Gaussian of standard deviation ``sigma`` px, ±⌈4σ⌉ taps, sum 1, shape (K,).

    >>> k = gaussian_kernel(0.7)
    >>> len(k), round(float(k.sum()), 6)
    (7, 1.0)
    """
    half = max(1, int(np.ceil(4.0 * float(sigma))))
    return np.asarray(cv2.getGaussianKernel(2 * half + 1, float(sigma), cv2.CV_64F)).ravel()


def gaussian_blur(image: F32, sigma: float) -> tuple[F32, float]:
    """``image`` blurred by a separable Gaussian of σ px, and the factor on its noise σ.

    White noise of σ_n per pixel has σ_n · Σ k² per pixel after the separable kernel k (its
    variance is multiplied by Σ_2D k² = (Σ k²)²): the noise of the blurred image is computed
    from the image's own, not re-estimated (an estimate from the blurred image would see
    correlated noise and read it low).

    Parameters
    ----------
    image : ndarray, shape (H, W), float32
    sigma : float
        Gaussian σ, px; ≤ 0 returns the image unchanged with factor 1.

    Returns
    -------
    blurred : ndarray, shape (H, W), float32
        Mirror border (``BORDER_REFLECT_101``).
    noise_factor : float
        σ of the noise after / before, Σ k² ≤ 1.

    >>> img = np.random.default_rng(0).normal(0, 2.0, (400, 400)).astype(np.float32)
    >>> out, g = gaussian_blur(img, 1.0)
    >>> round(g, 3), round(float(out[20:-20, 20:-20].std()) / 2.0, 3)
    (0.282, 0.282)
    """
    if not sigma > 0:
        return image, 1.0
    k = gaussian_kernel(sigma)
    out = cv2.sepFilter2D(
        np.asarray(image, np.float32),
        cv2.CV_32F,
        k.astype(np.float32),
        k.astype(np.float32),
        borderType=cv2.BORDER_REFLECT_101,
    )
    return np.asarray(out, np.float32), float(np.sum(k * k))


def _patches(image: F32, x: I64, y: I64, size: int) -> F32:
    """(n, size, size) float32 patches with top-left (x − size/2, y − size/2), clipped inside."""
    h, w = image.shape
    half = size // 2
    x0 = np.clip(x - half, 0, w - size)
    y0 = np.clip(y - half, 0, h - size)
    view = np.lib.stride_tricks.sliding_window_view(image, (size, size))
    return np.asarray(view[y0, x0], dtype=np.float32)


@lru_cache(maxsize=8)
def _dft(size: int) -> tuple[F32, F32, F32]:
    """Tapered real-input DFT matrices for :func:`_power_spectra`: (Hann taper as a column
    vector (size, 1)) and the real/imaginary DFT (size, size) along y and half-spectrum
    (size, size//2 + 1) along x, stacked as (2, size, ·) float32."""
    taper = np.hanning(size + 2)[1:-1]
    u = np.arange(size)
    ky, kx = np.fft.fftfreq(size) * size, np.fft.rfftfreq(size) * size
    ay = -2 * np.pi * np.outer(ky, u) / size  # (size freq, size px)
    ax = -2 * np.pi * np.outer(u, kx) / size  # (size px, half freq)
    fy = np.stack([np.cos(ay), np.sin(ay)]) * taper[None, None, :]
    fx = np.stack([np.cos(ax), np.sin(ax)]) * taper[None, :, None]
    return taper.astype(np.float32), fy.astype(np.float32), fx.astype(np.float32)


def _power_spectra(patches: F32) -> F64:
    """Σ over windows of |DFT(taper · (patch − tapered mean))|², shape (size, size//2 + 1).

    Two small real matrix products instead of a batched FFT: ~10× faster for 16² windows.
    """
    taper, fy, fx = _dft(patches.shape[1])
    t2 = np.outer(taper, taper)
    p = patches - ((patches * t2).sum(axis=(1, 2)) / t2.sum())[:, None, None]
    re_x, im_x = p @ fx[0], p @ fx[1]  # (n, size, half)
    re = fy[0] @ re_x - fy[1] @ im_x
    im = fy[0] @ im_x + fy[1] @ re_x
    return np.asarray((re * re + im * im).sum(axis=0), dtype=np.float64)


# σ (px) of the sampled Gaussians tried as the equalising blur; 0.05 px steps, refined by a
# parabola through the best three (the fit's SSE is smooth in σ)
_CANDIDATES = np.round(np.arange(0.0, 2.55, 0.05), 2)


def kernel_power(sigma: float, fx: F64, fy: F64) -> F64:
    """|H(f)|² of the separable :func:`gaussian_kernel` at frequencies (fx, fy), cycles/px.

    The sampled kernel, not the continuous Gaussian: for σ ≲ 1 px they differ at high
    frequency (σ = 0.5: |H(½, 0)| = 0.57 sampled, 0.29 continuous), and the sampled one is what
    :func:`gaussian_blur` applies. Shapes broadcast (fx, fy of any broadcastable shapes).
    """
    if not sigma > 0:
        return np.ones(np.broadcast_shapes(np.shape(fx), np.shape(fy)))
    k = gaussian_kernel(sigma)
    j = np.arange(len(k)) - len(k) // 2

    def h1(f: F64) -> F64:
        f = np.asarray(f, dtype=np.float64)
        return np.asarray(np.cos(2 * np.pi * f[..., None] * j) @ k, dtype=np.float64)

    return np.asarray((h1(fx) * h1(fy)) ** 2, dtype=np.float64)


@lru_cache(maxsize=8)
def _log_power_table(size: int) -> F64:
    """log |H_σ(f)|² of every candidate σ on a size² window's rfft2 grid, (C, size, size//2 + 1)."""
    fy, fx = np.fft.fftfreq(size)[:, None], np.fft.rfftfreq(size)[None, :]
    return np.stack([np.log(np.maximum(kernel_power(s, fx, fy), 1e-12)) for s in _CANDIDATES])


@dataclass(frozen=True)
class BlurEstimate:
    """Relative blur of a matched pair (:func:`relative_blur`)."""

    #: Signed σ of the sampled Gaussian (:func:`gaussian_blur`) that equalises the pair, px: > 0
    #: blur the right image (the left is blurrier), < 0 blur the left; 0 when no blur reduces the
    #: misfit.
    sigma: float
    #: The window misfit that this blur removes, in units of the pair's noise variance
    #: (σ_L² + a²σ_R² per pixel): what the blur difference adds to a fitted window's residual
    #: variance. The matcher's residual test keeps windows up to 16 noise variances.
    misfit_ratio: float
    #: ρ = Σ |H|²·|f|²·S / Σ |f|²·S over the equalised windows' signal spectrum S: the variance
    #: factor of the blurred image's noise *as seen by the window shift* (the Jacobian is a
    #: gradient, so its spectrum weights |f|²·S). The per-pixel factor Σ k² = mean |H|² is far
    #: smaller: blurred noise is correlated, and most of what is left of it sits at the low
    #: frequencies where the gradient is, so a white-noise Cramér–Rao bound with the per-pixel σ
    #: would be too small.
    shift_noise_factor: float
    #: ``windows``, ``bins``: Windows and frequency bins used.
    windows: int
    #: See ``windows`` above.
    bins: int


def _misfit(target: F64, model: F64) -> F64:
    """min over the gain g of Σ (target − g·model)² per candidate, (C, bins) each → (C,).

    Amplitude spectra (n-window sums) of the left windows (the template, blurred or not) and
    the right ones (blurred or not): the residual power that no gain can remove, in left
    units, as the sub-pixel fit left ≈ a·right + b sees it.
    """
    num = (target * model).sum(axis=1)
    den = np.maximum((model * model).sum(axis=1), 1e-300)
    return np.asarray((target * target).sum(axis=1) - num * num / den)


def relative_blur(
    left: F32,
    right: F32,
    xy: I64,
    d0: F64,
    e0: F64,
    noise: tuple[float, float],
    *,
    size: int = 16,
    max_windows: int = 128,
) -> BlurEstimate:
    """The Gaussian blur that equalises a matched pair, from the power spectra of its windows.

    Amplitude spectra A_L, A_R (summed over windows, noise floor subtracted) are compared as
    the sub-pixel fit will compare the windows: the sampled Gaussian H_σ (the one
    :func:`gaussian_blur` applies, σ on a 0.05 px grid refined by a parabola) applied to either
    side that leaves the least residual power min_a Σ (A_L′ − a·A_R′)² (A′ the blurred or
    unblurred side) wins. The
    fit weights each frequency by its signal, as the window residual does (a fit of the log
    ratio would weight the faint high frequencies as much as the strong ones).

    Parameters
    ----------
    left, right : ndarray, shape (H, W), float32
        Rectified pair (same frame), DN.
    xy : ndarray of int, shape (N, 2)
        Left window centres (x, y), px.
    d0, e0 : ndarray, shape (N,)
        Their matches (the NCC search's), px: the right window is at (x − d0, y − e0),
        rounded (the power spectrum ignores the sub-pixel rest).
    noise : (float, float)
        Per-pixel white-noise σ of left and right, DN: its flat power is subtracted, and it is
        the unit of :attr:`BlurEstimate.misfit_ratio`.
    size : int
        Window side, px (a Hann taper keeps the window edges out of the spectrum).
    max_windows : int
        At most this many windows, evenly spread over ``xy``, are used (the time is fixed:
        ~0.2 ms for 128).

    Returns
    -------
    BlurEstimate

    Examples
    --------
    A random texture blurred by σ = 1.0 px on the left only, the right shifted by 9 px:

    >>> rng = np.random.default_rng(0)
    >>> tex = rng.uniform(0, 255, (200, 260)).astype(np.float32)
    >>> left, _ = gaussian_blur(tex, 1.0)
    >>> right = np.roll(tex, -9, axis=1)
    >>> xy = np.stack(np.meshgrid(np.arange(40, 180, 10), np.arange(30, 170, 10)), -1)
    >>> xy = xy.reshape(-1, 2)
    >>> est = relative_blur(left, right, xy, np.full(len(xy), 9.0), np.zeros(len(xy)),
    ...                     (0.3, 0.3))
    >>> round(est.sigma, 1), est.misfit_ratio > 100        # blur the right by 1 px
    (1.0, True)
    """
    n = len(xy)
    if n == 0:
        return BlurEstimate(0.0, 0.0, 1.0, 0, 0)
    pick = np.unique(np.linspace(0, n - 1, min(n, max_windows)).round().astype(np.int64))
    x, y = xy[pick, 0].astype(np.int64), xy[pick, 1].astype(np.int64)
    xr = x - np.rint(d0[pick]).astype(np.int64)
    yr = y - np.rint(e0[pick]).astype(np.int64)
    pl = _power_spectra(_patches(left, x, y, size))
    pr = _power_spectra(_patches(right, xr, yr, size))
    # white noise of σ has E|DFT|² = σ² Σ taper² in every bin, per window
    taper = _dft(size)[0].astype(np.float64)
    unit = len(pick) * float((taper**2).sum()) ** 2
    fl, fr = unit * noise[0] ** 2, unit * noise[1] ** 2
    fy, fx = np.fft.fftfreq(size)[:, None], np.fft.rfftfreq(size)[None, :]
    f2 = np.broadcast_to(fx**2 + fy**2, pl.shape)
    # below ~1.5 cycles per window the taper's own spectrum (and the mean) dominate
    use = f2 >= (1.5 / size) ** 2
    al, ar = np.sqrt(np.maximum(pl - fl, 0.0))[use], np.sqrt(np.maximum(pr - fr, 0.0))[use]
    h = np.sqrt(np.exp(_log_power_table(size)[:, use]))  # (C, bins), C[0] = identity
    # blurring the right: the fit sees left vs right·H; blurring the left: left·H vs right
    cost_r = _misfit(np.broadcast_to(al, h.shape), ar * h)
    # blurring the left shrinks the target (and the misfit with it): compare relative misfits,
    # expressed in the unblurred left's power (else the strongest blur would always win)
    lh = al * h
    cost_l = _misfit(lh, np.broadcast_to(ar, h.shape))
    cost_l = cost_l * float((al * al).sum()) / np.maximum((lh * lh).sum(axis=1), 1e-300)
    gain2 = float((al * ar).sum() / max(float((ar * ar).sum()), 1e-300)) ** 2
    costs = np.concatenate([cost_l[:0:-1], cost_r])  # σ = −2.5 … 0 … 2.5
    sig = np.concatenate([-_CANDIDATES[:0:-1], _CANDIDATES])
    i = int(np.argmin(costs))
    best = float(sig[i])
    if 0 < i < len(costs) - 1:
        den = costs[i - 1] - 2 * costs[i] + costs[i + 1]
        if den > 0:
            best += 0.5 * float(costs[i - 1] - costs[i + 1]) / float(den) * float(_CANDIDATES[1])
    # the residual power of a window is (Σ over the full spectrum) / M²; noise: σ_L² + a²σ_R²
    noise_power = (fl + gain2 * fr) * f2.size
    removed = float(costs[len(_CANDIDATES) - 1] - costs[i]) / noise_power
    # the equalised windows' gradient spectrum: the blurrier side's signal times |f|²
    grad = (ar**2 if best < 0 else al**2) * f2[use]
    h2 = kernel_power(abs(best), fx, fy)[use]
    rho = float((h2 * grad).sum() / max(float(grad.sum()), 1e-300))
    return BlurEstimate(best, removed, rho, len(pick), int(use.sum()))


@dataclass(frozen=True, eq=False)
class EqualisedPair:
    """A pair after :func:`equalise_pair`."""

    #: ``left``, ``right``: ndarray, shape (H, W), float32. The pair, the sharper one blurred (or
    #: both unchanged).
    left: F32
    #: See ``left`` above.
    right: F32
    #: Gaussian σ added to left and right, px (one of them 0).
    added: tuple[float, float]
    #: Per-pixel noise σ of the returned images, DN (the input σ times Σ k² on the blurred side):
    #: what the residual of a fitted window is compared with.
    noise: tuple[float, float]
    #: The σ of white noise that would disturb a window's shift as much as the returned images'
    #: noise does, DN (the input σ times √ρ on the blurred side,
    #: :attr:`BlurEstimate.shift_noise_factor`): what the Cramér–Rao σ_d uses.
    shift_noise: tuple[float, float]
    estimate: BlurEstimate


def equalise_pair(
    left: F32,
    right: F32,
    est: BlurEstimate,
    noise: tuple[float, float],
    *,
    min_misfit: float = 1.0,
) -> EqualisedPair:
    """Blur the sharper image of a matched pair by its relative blur.

    Parameters
    ----------
    left, right : ndarray, shape (H, W), float32
        Rectified pair, DN.
    est : BlurEstimate
        The pair's relative blur, :func:`relative_blur` of the matched windows of the NCC
        search.
    noise : (float, float)
        Per-pixel white-noise σ of left and right, DN.
    min_misfit : float
        Equalise only when the blur difference adds at least this many noise variances to a
        window's residual (:attr:`BlurEstimate.misfit_ratio`); below it the misfit is within
        the noise and blurring would only lose signal (and ~1 ms on a 600 × 700 crop).
    Returns
    -------
    EqualisedPair
    """
    s = abs(est.sigma)
    if not (est.misfit_ratio >= min_misfit and s > 0):
        return EqualisedPair(left, right, (0.0, 0.0), noise, noise, est)
    side = 0 if est.sigma < 0 else 1  # the sharper image: 0 left, 1 right
    images, added = [left, right], [0.0, 0.0]
    pixel, shift = list(noise), list(noise)
    images[side], g = gaussian_blur(images[side], s)
    added[side] = s
    pixel[side] *= g
    shift[side] *= float(np.sqrt(est.shift_noise_factor))
    return EqualisedPair(
        images[0], images[1], (added[0], added[1]), (pixel[0], pixel[1]), (shift[0], shift[1]), est
    )
