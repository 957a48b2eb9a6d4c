"""The learned residual radial distortion of the flows (thesis §3.2, fixes/radial_residual.py)."""

from __future__ import annotations

import numpy as np

from phonestereo.fixes.distortion import radial_geometry
from phonestereo.fixes.radial_residual import (
    correct_matches,
    fit_capture_radial,
    pool_radial,
    radial_from_dict,
    radial_shift,
)

CENTER = (520.0, 380.0)


def _capture(rng: np.random.Generator, amp: float, n: int = 600) -> tuple[np.ndarray, np.ndarray]:
    """Matches over a 1000 × 760 view whose e carries P(r) = amp·(r/500)³ − 0.1·(r/500) px and
    0.1 px of noise (a capture's whole-view W-T matches)."""
    q = rng.uniform([20, 20], [1020, 740], (n, 2))
    r, u = radial_geometry(q, CENTER)
    p = amp * (r / 500) ** 3 - 0.1 * (r / 500)
    return q, u[:, 1] * p + 0.05 + rng.normal(0, 0.1, n)


def test_pooled_fit_is_the_median_capture_curve() -> None:
    # 15 captures (the learning's face captures) with amplitudes 0.3 ± 0.05 px and one wild one:
    # the pooled P follows the median capture, 0.3·(r/500)³ − 0.1·(r/500), within 0.02 px over
    # the fitted radii (the per-capture fit's noise at 600 matches is ~0.02 px there).
    rng = np.random.default_rng(4)
    amps = [*rng.normal(0.3, 0.05, 14), 3.0]
    fits = [fit_capture_radial(*_capture(rng, a), CENTER) for a in amps]
    pooled = pool_radial(fits)
    assert pooled is not None and pooled.n_used == 15 and pooled.offset_px == 0.0
    r = np.linspace(50, 0.95 * pooled.radius_scale_px, 20)
    truth = 0.3 * (r / 500) ** 3 - 0.1 * (r / 500)
    assert np.max(np.abs(pooled.radial(r) - truth)) < 0.03


def test_correction_holds_beyond_the_fitted_radius() -> None:
    # A polynomial is not extrapolated: past ρ the displacement stays P(ρ)·û.
    rng = np.random.default_rng(5)
    fit = fit_capture_radial(*_capture(rng, 0.3), CENTER)
    assert fit is not None
    rho = fit.radius_scale_px
    far = [[CENTER[0] + 2 * rho, CENTER[1]]]
    d, e = correct_matches(fit, far, [10.0], [0.0])
    assert np.isclose(d[0], 10.0 - float(fit.radial(rho))) and np.isclose(e[0], 0.0)


def test_too_few_matches_or_no_gain_give_no_fit_and_the_dict_round_trips() -> None:
    rng = np.random.default_rng(6)
    q, e = _capture(rng, 0.3, n=40)
    assert fit_capture_radial(q, e, CENTER) is None  # < 50 matches
    assert pool_radial([None, None]) is None
    fit = fit_capture_radial(*_capture(rng, 0.3), CENTER)
    assert fit is not None and radial_from_dict(fit.to_dict()) == fit


def test_p_centred_where_the_residual_is_centred_carries_its_x_part_to_the_centre() -> None:
    """The residual is the wide's factory misfit, radial about the wide's principal point; it
    rises steeply near it (~0.3 % of r, as on the random modules: +0.27 px at r ≈ 175 px, zero
    at ≈ 425 px). P fitted from e alone about that centre gives the x part (what a disparity
    carries) within 0.015 px over the central ±150 px where charts are measured; about a centre
    22 px away (the tele's principal point on random-3030) it is off by ~0.04 px there, 0.3 %
    of a 2 m chart's disparity (docs/module-random.md, session 19)."""
    wide_c = np.array([540.0, 390.0])

    def p_true(r: np.ndarray) -> np.ndarray:
        return 0.0031 * r - 0.0000073 * r**2

    for seed in range(3):
        rng = np.random.default_rng(seed)
        q = rng.uniform([20, 20], [1060, 760], (600, 2))
        r, u = radial_geometry(q, wide_c)
        e = u[:, 1] * p_true(r) + rng.normal(0, 0.05, 600)
        central = wide_c + rng.uniform(-150, 150, (300, 2))
        rc, uc = radial_geometry(central, wide_c)
        errs = []
        for c in (wide_c, wide_c + np.array([22.0, 3.0])):
            fit = fit_capture_radial(q, e, (float(c[0]), float(c[1])))
            assert fit is not None
            miss = radial_shift(fit, central)[:, 0] - uc[:, 0] * p_true(rc)
            errs.append(float(np.sqrt(np.mean(miss**2))))
        assert errs[0] < 0.015 and errs[1] > 0.03, errs
