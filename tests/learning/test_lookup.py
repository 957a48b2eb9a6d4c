"""Dictionary lookups (thesis Figure 3-31) and the smooth field: values, σ, buckets, errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import least_squares

from phonestereo.errors import InputError, ShapeError
from phonestereo.learning.field import FieldConfig, FieldLookup, _irls, fit_field
from phonestereo.learning.lookup import DictionaryLookup, LookupConfig
from phonestereo.learning.observation import Observation, observations_to_array


def ob(x: float, y: float, d: float, c: float, o: str = "landscape", sigma: float = math.nan):
    """An observation at (x, y) with measured disparity d and correction c (px)."""
    return Observation(x, y, d, d + c, 18.0 / (d + c), o, "", 0.0, None, f"c{x:.0f}", "t", sigma)


SMALL = [
    ob(100, 100, 9.0, 0.10, sigma=0.02),
    ob(1900, 100, 9.0, 0.50),
    ob(1000, 750, 9.0, 0.30),
    ob(1010, 760, 18.0, 0.70),  # same place as the previous one, other disparity
    ob(100, 1400, 9.0, -0.20),
]


def test_nearest_uses_normalised_xyd() -> None:
    lut = DictionaryLookup(SMALL, (1000.0, 750.0), LookupConfig(k_nearest=1))
    c = lut.correct([[110, 90, 9.1], [1005, 755, 17.5], [1005, 755, 9.2]], "landscape")
    # the disparity axis separates the two observations at the centre
    assert c.value_px.tolist() == pytest.approx([0.10, 0.70, 0.30])
    assert c.sigma_px[0] == pytest.approx(0.02)  # k = 1: the point's own σ
    assert c.n_used.tolist() == [1, 1, 1] and c.ok and c.strategy == "nearest"
    assert not c.value_px.flags.writeable


def test_nearest_k_weighted_mean_and_spread() -> None:
    lut = DictionaryLookup(SMALL, (1000.0, 750.0), LookupConfig(k_nearest=3))
    c = lut.correct([[1000, 750, 9.0]], "landscape")
    # the exact hit dominates the inverse-distance weights; σ is the weighted spread (> 0)
    assert abs(c.value_px[0] - 0.30) < 0.01 and 0 < c.sigma_px[0] < 0.5
    assert c.n_used[0] == 3


def test_global_strategies_and_their_sigma() -> None:
    lut = DictionaryLookup(SMALL, (1000.0, 750.0), LookupConfig(k_centre=1))
    corr = np.array([0.10, 0.50, 0.30, 0.70, -0.20])
    q = np.array([[0.0, 0.0, 9.0], [1999.0, 1499.0, 5.0]])
    mean = lut.correct(q, "landscape", "mean")
    s = corr.std(ddof=1)
    assert mean.value_px.tolist() == pytest.approx([corr.mean()] * 2)
    assert mean.sigma_px[0] == pytest.approx(math.hypot(s / math.sqrt(5), s))
    mx, mn = lut.correct(q, "landscape", "max"), lut.correct(q, "landscape", "min")
    assert mx.value_px[0] == pytest.approx(0.70) and mn.value_px[0] == pytest.approx(-0.20)
    assert mx.sigma_px[0] == pytest.approx(np.sqrt(np.mean((corr - 0.7) ** 2)))
    centre = lut.correct(q, "landscape", "centre")
    assert centre.value_px[0] == pytest.approx(0.30)  # the observation at the principal point


def test_lookups_are_keyed_by_orientation_bucket() -> None:
    obs = [*SMALL, ob(1000, 750, 9.0, 5.0, o="landscape-flipped")]
    lut = DictionaryLookup(obs, (1000.0, 750.0), LookupConfig(k_nearest=1))
    assert lut.orientations == ("landscape", "landscape-flipped")
    q = [[1000, 750, 9.0]]
    assert lut.correct(q, "landscape").value_px[0] == pytest.approx(0.30)
    assert lut.correct(q, "landscape-flipped", "mean").value_px[0] == pytest.approx(5.0)
    none = lut.correct(q, "portrait", "nearest")
    assert not none.ok and np.isnan(none.value_px).all() and none.n_used[0] == 0
    assert "portrait" in none.reason and "learn in this orientation" in none.reason
    assert not FieldLookup(obs).correct(q, "portrait").ok


def test_bad_arguments_raise_typed_errors() -> None:
    lut = DictionaryLookup(SMALL)
    with pytest.raises(InputError, match="unknown lookup strategy"):
        lut.correct([[0, 0, 9]], "landscape", "closest")
    with pytest.raises(ShapeError, match=r"\(N, 3\)"):
        lut.correct([[0, 0]], "landscape")
    with pytest.raises(InputError):
        LookupConfig(k_nearest=0)
    with pytest.raises(InputError):
        FieldConfig(max_degree=4)


def _field_obs(n: int, seed: int, noise: float, outliers: float = 0.0) -> np.ndarray:
    """Faces at 1–3 m whose correction follows :func:`truth` of the measured disparity."""
    rng = np.random.default_rng(seed)
    x, y = rng.uniform([0, 0], [2000, 1500], (n, 2)).T
    d_meas = 18.0 / rng.uniform(1.0, 3.0, n)
    c = truth(x, y, d_meas) + rng.normal(0, noise, n)
    bad = rng.random(n) < outliers
    c[bad] += rng.choice([-1, 1], bad.sum()) * rng.uniform(1.0, 2.0, bad.sum())
    d_exp = d_meas + c
    return observations_to_array(
        Observation(
            x[i],
            y[i],
            d_meas[i],
            d_exp[i],
            18.0 / d_exp[i],
            "landscape",
            "",
            0.0,
            None,
            f"c{i // 8}",
        )
        for i in range(n)
    )


def truth(x: np.ndarray, y: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Offset of degree 2 and gain of degree 1 over the sensor (units: px, px per px)."""
    u, v = (x - 1000) / 1000, (y - 750) / 1000
    return 0.3 + 0.2 * u - 0.1 * v + 0.15 * u * u + (0.02 + 0.01 * u) * d


def test_field_recovers_a_known_field_and_its_gain() -> None:
    fit = fit_field(_field_obs(300, 0, noise=0.002), (1000.0, 750.0))
    f = fit.field
    assert f is not None and (f.degree_offset, f.degree_gain) == (2, 1)
    xy = np.array([[200.0, 300.0], [1700.0, 1200.0]])
    offset, gain = f.offset_gain(xy)
    u = (xy[:, 0] - 1000) / 1000
    v = (xy[:, 1] - 750) / 1000
    # 2 mpx noise on 300 points: the coefficients are good to ~1 mpx; extreme sensor corners
    # and a disparity range of 6–18 px allow a few mpx in offset and 0.1 mpx/px in gain
    assert offset == pytest.approx(0.3 + 0.2 * u - 0.1 * v + 0.15 * u * u, abs=5e-3)
    assert gain == pytest.approx(0.02 + 0.01 * u, abs=5e-4)


def test_field_is_robust_and_reports_sigma() -> None:
    obs = _field_obs(400, 1, noise=0.03, outliers=0.08)
    rng = np.random.default_rng(5)
    qx, qy = rng.uniform([100, 100], [1900, 1400], (200, 2)).T
    qd = rng.uniform(6, 18, 200)
    q = np.c_[qx, qy, qd]
    err = {}
    for loss in ("soft_l1", "linear"):
        fit = fit_field(obs, (1000.0, 750.0), FieldConfig(loss=loss))
        assert fit.field is not None
        corr = fit.field.predict(q)
        err[loss] = float(np.sqrt(np.mean((corr.value_px - truth(qx, qy, qd)) ** 2)))
    # 8 % gross outliers of 1–2 px: the robust fit stays near the noise/√n level (measured
    # 0.009 px), plain least squares is pulled ~5× further (measured 0.049 px)
    assert err["soft_l1"] < 0.02 and err["linear"] > 2 * err["soft_l1"]
    fit = fit_field(obs, (1000.0, 750.0))
    assert fit.field is not None and fit.field.n_outliers >= 20  # 29 flagged, ~32 planted
    # robust scatter ≈ the 0.03 px noise (measured 0.036: 8 % outliers still widen the MAD)
    assert fit.field.scatter_px == pytest.approx(0.03, rel=0.25)
    inside = fit.field.predict([[1000.0, 750.0, 9.0]]).sigma_px[0]
    outside = fit.field.predict([[6000.0, 5000.0, 9.0]]).sigma_px[0]
    assert outside > 5 * inside  # extrapolation is visible in σ


def test_irls_reaches_the_least_squares_optimum() -> None:
    obs = _field_obs(300, 2, noise=0.03, outliers=0.1)
    q = np.c_[obs["x_px"], obs["y_px"], obs["d_measured_px"]]
    c = obs["d_expected_px"] - obs["d_measured_px"]
    f = fit_field(obs, (1000.0, 750.0)).field
    assert f is not None
    A = f.frame.design(q, 2, 1)
    for loss in ("soft_l1", "huber", "cauchy"):
        x0 = np.linalg.lstsq(A, c, rcond=None)[0]  # least_squares from the plain LSQ start
        ref = least_squares(lambda t: A @ t - c, x0, loss=loss, f_scale=0.05, xtol=1e-14).x
        # the cross-validation's IRLS solves the same M-estimation problem; agreement to a
        # micro-pixel (measured ≤ 6e-7, least_squares' own ftol/gtol = 1e-8 sets the floor)
        assert np.max(np.abs(_irls(A, c, loss, 0.05) - ref)) < 1e-6


def test_field_small_and_empty_sets() -> None:
    assert fit_field(observations_to_array([])).reason == "no observations to fit"
    fit = fit_field(SMALL[:3])  # too few to cross-validate: a constant
    assert fit.field is not None and (fit.field.degree_offset, fit.field.degree_gain) == (0, -1)
    assert fit.field.cv == ()
    assert fit.field.predict([[0, 0, 9.0]]).value_px[0] == pytest.approx(0.30, abs=0.1)
