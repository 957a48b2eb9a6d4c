"""Sub-pixel refinement (features/subpixel.py) and its Cramér–Rao σ (features/crlb.py).

Truth comes from exact Fourier shifts of a band-limited random texture (no renderer needed):
R(x, y) = L(x + d, y + e) holds to float precision, so any bias is the estimator's.
"""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.errors import InputError
from phonestereo.features.crlb import noise_sigma, solve_spd, weighted_ls_covariance
from phonestereo.features.subpixel import bspline_coefficients, refine_lk

H, W = 160, 200


def _texture(seed: int, blur_px: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    spec = np.fft.fft2(rng.standard_normal((H, W)))
    fy, fx = np.fft.fftfreq(H)[:, None], np.fft.fftfreq(W)[None, :]
    spec *= np.exp(-2 * np.pi**2 * blur_px**2 * (fx**2 + fy**2))
    return spec * 40 / np.real(np.fft.ifft2(spec)).std(), fx, fy


def shifted_pair(d: float, e: float, *, seed: int = 0, blur_px: float = 1.2) -> tuple:
    """Left and right (x_right = x_left − d, y_right = y_left − e), 128 ± 40 DN, noise-free."""
    spec, fx, fy = _texture(seed, blur_px)
    left = 128 + np.real(np.fft.ifft2(spec))
    right = 128 + np.real(np.fft.ifft2(spec * np.exp(2j * np.pi * (fx * d + fy * e))))
    return left.astype(np.float32), right.astype(np.float32)


def _grid(step: int = 9, margin: int = 30) -> np.ndarray:
    ys, xs = np.mgrid[margin : H - margin : step, margin : W - margin : step]
    return np.stack([xs.ravel(), ys.ravel()], axis=1)


def _refine(left, right, xy, d0, e0, **kw):
    return refine_lk(
        left, bspline_coefficients(left), bspline_coefficients(right), xy, d0, e0, **kw
    )


@pytest.mark.parametrize("slant", [False, True])
def test_no_pixel_locking_across_fractional_disparities(slant: bool) -> None:
    xy = _grid()
    for frac in np.arange(0.0, 1.0, 0.125):
        d = 9.0 + frac
        left, right = shifted_pair(d, 0.3)
        start = np.full(len(xy), np.round(d)), np.zeros(len(xy))
        ref = _refine(left, right, xy, *start, slant=slant)
        assert ref.converged.mean() > 0.95
        err = ref.d[ref.converged] - d
        # Cubic B-spline interpolation of a σ = 1.2 px texture: bias < 0.005 px at every
        # fraction (the acceptance allows 0.02); NCC + parabola on the same data is ~0.05.
        assert abs(err.mean()) < 0.005, (frac, err.mean())
        assert np.abs(ref.e[ref.converged] - 0.3).max() < 0.02


def test_parabola_start_locks_but_refinement_does_not() -> None:
    from phonestereo.features.search import ncc_search

    xy = _grid()
    left, right = shifted_pair(9.25, 0.0)
    s = ncc_search(left, right, xy, radius=7, min_d=0, max_d=20, row_tolerance=0)
    ref = _refine(left, right, xy, s.d0, s.e0 * 0)
    parabola_bias = float(np.mean(s.d0 - 9.25))
    lk_bias = float(np.mean(ref.d[ref.converged] - 9.25))
    # the parabola is pulled toward the integer (−0.014 px here), the refinement is not
    assert parabola_bias < -0.01
    assert abs(lk_bias) < 0.2 * abs(parabola_bias), (lk_bias, parabola_bias)


def test_slanted_surface_disparity_at_the_window_centre() -> None:
    """d(x) = 10 + 0.2·(x − 100): with slant the centre value is recovered, without it the
    gradient-weighted window mean is."""
    rng = np.random.default_rng(3)
    k = rng.uniform(0.05, 0.35, (40, 2)) * rng.choice([-1, 1], (40, 2))
    phase = rng.uniform(0, 2 * np.pi, 40)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)

    def tex(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return 128 + 6 * np.cos(x[..., None] * k[:, 0] + y[..., None] * k[:, 1] + phase).sum(-1)

    s, c = 0.2, 10.0
    left = tex(xx, yy).astype(np.float32)
    # right pixel x_r sees the left point x with x − (c + s·(x − 100)) = x_r
    right = tex((xx + c - 100 * s) / (1 - s), yy).astype(np.float32)
    xy = _grid(step=11)
    truth = c + s * (xy[:, 0] - 100)
    ref = _refine(left, right, xy, np.round(truth), np.zeros(len(xy)), slant=True)
    ok = ref.converged
    assert ok.mean() > 0.9
    assert np.abs(ref.d[ok] - truth[ok]).max() < 0.01  # px
    assert np.abs(ref.slant[ok, 0] - s).max() < 0.01


def test_sigma_d_matches_the_scatter_over_noise() -> None:
    """Empirical std of d over noise draws ≈ predicted σ_d (the bound is attained)."""
    left0, right0 = shifted_pair(7.4, -0.2, seed=5)
    xy = _grid(step=15)
    rng = np.random.default_rng(0)
    sigma_n = 3.0
    ds, sds = [], []
    for _ in range(40):
        left = left0 + sigma_n * rng.standard_normal(left0.shape).astype(np.float32)
        right = right0 + sigma_n * rng.standard_normal(left0.shape).astype(np.float32)
        ref = _refine(left, right, xy, np.full(len(xy), 7.0), np.zeros(len(xy)), slant=False)
        assert ref.converged.all()
        ds.append(ref.d)
        sds.append(np.sqrt(2 * sigma_n**2 * ref.cov_unit[:, 0, 0]))
    ratio = np.std(ds, axis=0) / np.mean(sds, axis=0)
    # 40 draws: the std of a std estimate is ~11 %; the median over windows is much tighter.
    assert 0.9 < float(np.median(ratio)) < 1.1, np.median(ratio)


def test_windows_outside_the_image_are_an_input_error() -> None:
    left, right = shifted_pair(5.0, 0.0)
    with pytest.raises(InputError, match="inside the left image"):
        _refine(left, right, np.array([[3, 50]]), np.array([5.0]), np.array([0.0]))


def test_flat_window_is_not_converged() -> None:
    flat = np.full((60, 60), 100.0, np.float32)
    ref = _refine(flat, flat, np.array([[30, 30]]), np.array([2.0]), np.array([0.0]))
    assert not ref.converged[0] and np.isnan(ref.cov_unit[0]).all()


def test_noise_sigma_ignores_texture_and_handles_integers() -> None:
    left, _ = shifted_pair(0.0, 0.0, blur_px=2.0)
    rng = np.random.default_rng(1)
    noisy = np.rint(left + 2.0 * rng.standard_normal(left.shape))
    # rounding adds 1/12 DN²: √(4 + 1/12) = 2.02; the texture adds a few per cent.
    assert abs(noise_sigma(noisy) - 2.02) < 0.12


def test_solve_spd_matches_numpy_and_flags_singular() -> None:
    rng = np.random.default_rng(2)
    m = rng.standard_normal((50, 6, 9))
    a = m @ m.transpose(0, 2, 1)
    b = rng.standard_normal((50, 6))
    x, ok = solve_spd(a, b)
    assert ok.all() and np.allclose(x, np.linalg.solve(a, b[..., None])[..., 0])
    a[0] = 0.0
    assert not solve_spd(a, b)[1][0]


def test_sandwich_equals_crlb_for_uniform_weights() -> None:
    rng = np.random.default_rng(4)
    jac = rng.standard_normal((3, 4, 100))
    cov, dof = weighted_ls_covariance(jac, np.ones(100))
    assert np.allclose(cov, np.linalg.inv(jac @ jac.transpose(0, 2, 1)))
    assert np.allclose(dof, 96.0)  # n − p


def test_template_gradients_equal_the_spline_derivative() -> None:
    """The fast FIR gradients equal the derivative of the interpolating spline (slow reference:
    prefilter the whole image, then differentiate the cubic B-spline at the integers)."""
    from phonestereo.features.spline_gradients import image_gradients, window_gradients

    left, _ = shifted_pair(0.0, 0.0)
    xy = _grid(step=13)
    x0, y0 = xy[:, 0], xy[:, 1]
    tmpl, gx, gy = image_gradients(left, x0, y0, 7)  # dense windows: one filter of their box
    # window by window (sparse windows' path): the same to float32 rounding (~1e-6 relative)
    for a, b in zip(window_gradients(left, x0, y0, 7), (tmpl, gx, gy), strict=True):
        assert np.abs(a - b).max() <= 1e-5 * np.abs(b).max()
    c = bspline_coefficients(left)
    k = np.arange(-8, 9)
    blk = c[(y0[:, None] + k)[:, :, None], (x0[:, None] + k)[:, None, :]]  # (n, 17, 17)
    dx = 0.5 * (blk[:, :, 2:] - blk[:, :, :-2])
    sm = (blk[:, :, :-2] + 4 * blk[:, :, 1:-1] + blk[:, :, 2:]) / 6
    ref_gx = ((dx[:, :-2] + 4 * dx[:, 1:-1] + dx[:, 2:]) / 6).reshape(len(xy), -1)
    ref_gy = (0.5 * (sm[:, 2:] - sm[:, :-2])).reshape(len(xy), -1)
    scale = np.abs(ref_gx).max()  # ~30 DN/px; float32 sums of 23 taps agree to ~1e-5 of it
    assert np.abs(gx - ref_gx).max() < 1e-4 * scale
    assert np.abs(gy - ref_gy).max() < 1e-4 * scale
    u = np.arange(-7, 8)
    ref_t = left[(y0[:, None] + u)[:, :, None], (x0[:, None] + u)[:, None, :]]
    assert np.array_equal(tmpl, ref_t.reshape(len(xy), -1))
