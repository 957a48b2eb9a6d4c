"""The colour-filter-array phase of a demosaiced pair, and the filter that stops it locking d.

A phone's image comes from a Bayer mosaic: each pixel measured one colour and the demosaicer
interpolated the other two. The interpolation error depends on the pixel's place in the 2 × 2
CFA tile, so a demosaiced image carries a component fixed to the *sensor grid* (carriers at
the frequencies (½, 0), (0, ½), (½, ½) cycles/px, modulated by the image's own fine detail).
When both images of a rectified pair are on their sensors' grids (identical or near-identity
rectification), that component does not move with the scene: the window fit prefers the
disparities at which the two grids' carriers line up again, d ≡ 0 (mod 2). The estimate is
pulled toward the nearest even disparity by up to ~0.02 px (OpenCV's EA demosaic, noise-free)
and 0.03–0.04 px after a phone's sharpening, as −A·sin(π·d); it is the same for every window
of a fronto-parallel surface, so no per-window σ sees it.

This is physical, not an artefact of the simulator: Middlebury-Q Adirondack and Piano (colour
images with ground truth) re-mosaiced on RGGB and demosaiced by OpenCV show it as
−0.040 px and −0.085 px·sin(π·d) (EA), against +0.002 / −0.015 px on the original images
(``docs/module.md``, "The ISP and the matcher").

Two measurements and a filter:

* :func:`cfa_phase_contrast` — the high-pass energy of the image in each of the four 2 × 2 phase
  classes; demosaiced images differ by 50–100 % between classes (the interpolated sites are
  smoother), any image resampled off its sensor grid (rectification at a scale, Middlebury's
  quarter size) by 1–3 %;
* :func:`suppress_cfa` — the separable [1, 2, 1] / 4 filter on both images: zero response at
  the carriers, so the grid-locked part near them is gone (the estimate's pull drops from
  −0.022 to −0.001 px at d = 16.5 noise-free; on the re-mosaiced Middlebury pairs the sin(π·d)
  amplitude drops 2.4–3.2×). A symmetric filter on both images does not move d. It returns
  the filtered images' noise per pixel (σ·Σk² for the separable k) and as the window shift
  sees it (the noise is now correlated, :func:`shift_noise_factor`).
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]

__all__ = ["CFA_KERNEL", "cfa_phase_contrast", "shift_noise_factor", "suppress_cfa"]

#: the separable kernel of :func:`suppress_cfa` (zero at ½ cycle/px)
CFA_KERNEL = np.array([0.25, 0.5, 0.25])
_LAPLACE = np.array([[0.0, -0.25, 0.0], [-0.25, 1.0, -0.25], [0.0, -0.25, 0.0]], np.float32)
_DIFF = np.array([-0.5, 0.0, 0.5])  # central difference, the gradient the window fit uses


def cfa_phase_contrast(image: F32) -> float:
    """Max / min − 1 of the mean |Laplacian| over the four 2 × 2 phase classes of the image.

    Parameters
    ----------
    image : ndarray, shape (H, W), float32
        Grey image, DN; phase classes are taken from its own (0, 0) pixel.

    Returns
    -------
    float
        0 for an image with no grid-locked structure; measured 0.01–0.02 on Middlebury-Q (clean
        or JPEG), 0.54–1.03 on ISP renders (OpenCV EA demosaic), 0.63–0.67 on Middlebury-Q
        re-mosaiced and demosaiced; NaN for an image under 8 px a side, 0 for a flat one.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = rng.normal(128, 10, (64, 64)).astype(np.float32)
    >>> round(cfa_phase_contrast(img), 1)
    0.0
    >>> img[1::2, 1::2] = cv2.blur(img, (3, 3))[1::2, 1::2]         # a quarter interpolated
    >>> cfa_phase_contrast(img) > 0.5
    True
    """
    img = np.asarray(image, np.float32)
    if min(img.shape) < 8:
        return float("nan")
    r = np.abs(cv2.filter2D(img, -1, _LAPLACE, borderType=cv2.BORDER_REFLECT_101))
    e = np.array([r[i::2, j::2][1:-1, 1:-1].mean() for i in (0, 1) for j in (0, 1)])
    if not e.max() > 0:  # flat image
        return 0.0
    return float(e.max() / e.min() - 1.0) if e.min() > 0 else float("inf")


def _kernel_gain(taps: F64) -> float:
    """Σ k² of a 1-D kernel: the white-noise variance it passes."""
    return float(np.sum(np.asarray(taps) ** 2))


def shift_noise_factor(
    image: F32, noise: float, times: int = 1, kernel: F64 | None = None
) -> float:
    """Variance factor ρ of the filtered noise *as the window shift sees it*, ≤ 1.

    The filtered image's noise is correlated; the window fit's estimate weights it by the
    gradient of the filtered signal, so (as for the blur of :mod:`~.blur`) the white noise of
    equal effect has variance ρ·σ² with ρ = Σ|H|⁴|f|²S / Σ|H|²|f|²S, S the signal spectrum.
    Both sums are the gradient energies of the signal filtered twice and once, measured on the
    image (its noise subtracted). ``times`` = 0 gives 1.

    Parameters
    ----------
    image : ndarray, shape (H, W), float32
        The unfiltered image, DN.
    noise : float
        Its per-pixel white-noise σ, DN.
    times : int
        How many times the kernel was applied (0 or 1).
    kernel : ndarray, shape (K,), optional
        The separable 1-D kernel applied along x and y; default :data:`CFA_KERNEL` (the
        matcher also uses it for the Gaussian prefilter of a compression-limited pair).

    Examples
    --------
    A textured image whose noise is small: the shift sees most of the filtered noise
    (ρ near 1), far more than the per-pixel (Σk²)² = 0.14 of [1, 2, 1] / 4:

    >>> rng = np.random.default_rng(0)
    >>> tex = cv2.GaussianBlur(rng.normal(0, 50, (200, 200)).astype(np.float32), (0, 0), 2.0)
    >>> round(shift_noise_factor(tex, 0.5), 2)
    0.82
    """
    if times == 0:
        return 1.0
    k1 = CFA_KERNEL if kernel is None else np.asarray(kernel, np.float64)
    img = np.asarray(image, np.float32)
    once = _filter(img, k1)
    twice = _filter(once, k1)
    k2 = np.convolve(k1, k1)

    def grad_energy(x: F32, k: F64) -> float:
        # mean |∇(k ∗ x)|² minus the white noise it carries (∇ along one axis, k along both)
        gx = cv2.sepFilter2D(x, cv2.CV_32F, _DIFF.astype(np.float32), np.array([1], np.float32))
        gy = cv2.sepFilter2D(x, cv2.CV_32F, np.array([1], np.float32), _DIFF.astype(np.float32))
        e = float(np.mean(gx[4:-4, 4:-4] ** 2) + np.mean(gy[4:-4, 4:-4] ** 2))
        kd = np.convolve(k, _DIFF)
        return e - 2 * noise**2 * _kernel_gain(kd) * _kernel_gain(k)

    g1, g2 = grad_energy(once, k1), grad_energy(twice, k2)
    if not (g1 > 0 and g2 > 0):
        return _kernel_gain(k1) ** 2
    return float(np.clip(g2 / g1, _kernel_gain(k1) ** 2, 1.0))


def _filter(img: F32, taps: F64 = CFA_KERNEL) -> F32:
    k = np.asarray(taps, np.float32)
    out = cv2.sepFilter2D(img, cv2.CV_32F, k, k, borderType=cv2.BORDER_REFLECT_101)
    return np.asarray(out, np.float32)


def suppress_cfa(
    left: F32, right: F32, noise: tuple[float, float]
) -> tuple[F32, F32, float, tuple[float, float]]:
    """Both images filtered by [1, 2, 1] / 4 along x and y, and the factors on their noise σ.

    Parameters
    ----------
    left, right : ndarray, shape (H, W), float32
        The rectified pair, DN (same frame: their CFA phases line up).
    noise : (float, float)
        Per-pixel white-noise σ of left and right before filtering, DN.

    Returns
    -------
    left, right : ndarray, float32
        Filtered (mirror border).
    pixel_factor : float
        σ per pixel after / before (Σk² of the separable kernel, 0.375): for the residual test.
    shift_factors : (float, float)
        σ of the white noise that disturbs the window shift as much, after / before, left and
        right (√ρ, :func:`shift_noise_factor`): for the Cramér–Rao σ_d.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> img = rng.normal(128, 2, (100, 100)).astype(np.float32)
    >>> _, _, g, _ = suppress_cfa(img, img, (2.0, 2.0))
    >>> g
    0.375
    """
    g = _kernel_gain(CFA_KERNEL)
    shift = (
        float(np.sqrt(shift_noise_factor(left, noise[0]))),
        float(np.sqrt(shift_noise_factor(right, noise[1]))),
    )
    return _filter(left), _filter(right), g, shift
