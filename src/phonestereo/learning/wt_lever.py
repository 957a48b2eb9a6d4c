"""The W-T scale's lever arm: why a face far from the tele's centre teaches less (thesis §3.5.1,
§3.6; issue #18).

Every face observation's disparity is corrected by its own capture's W-T scale s
(:class:`~phonestereo.fixes.wt_scale.WTScale`): d' = x_w − c_x − s·(x_t − c_x). An error δs of
that capture's s moves the observation by δs·(x_t − c_x): nothing at the tele's centre c_x, a
lot at the edge of its view. The scale's own statistical σ (≲ 10⁻⁴ from hundreds of matches)
is not that error: where the capture's matches lie decides what the linear fit of e takes from
the lens's residual field, so s differs from capture to capture by ~10⁻³ at one distance
(random-3095: 1.008–1.013 at 1 m, 1.016–1.019 at 3 m), and a face 300 px from c_x carries
~0.4 px of it against ~0.05 px of its own. The chart a user measures is usually near the
centre, where that lever is 0, so the correction there must come from the faces nearest it.

This module estimates the two noise parts from the observations themselves:

- τ, the capture-to-capture spread of the scale error: each capture with two or more faces
  spread along x gives the slope of its corrections over the lever arm; the slopes' robust
  spread about their median (the field's own x-gradient is common to all captures), less
  what each slope's noise explains, is τ;
- σ₀, one face's own noise: the residuals about each capture's line (captures of three or
  more faces), pooled; or the observations' own ``sigma_px`` when too few.

:func:`lever_weights` turns them into relative weights 1/σ_i with σ_i² = σ₀² + τ²·lever_i²
(median 1), which the smooth field's fit uses (:func:`~phonestereo.learning.field.fit_field`).
Where τ cannot be told (fewer than :data:`MIN_CAPTURES` usable captures) the weights are all 1,
and the fit is the unweighted one.

Examples
--------
Ten captures of four faces; each capture's scale error tilts its faces by δs·lever:

>>> rng = np.random.default_rng(0)
>>> lever = np.tile([-300.0, -100.0, 100.0, 300.0], 10)
>>> groups = np.repeat(np.arange(10), 4)
>>> c = 2.0 + rng.normal(0, 1e-3, 10)[groups] * lever + rng.normal(0, 0.05, 40)
>>> tau, s0 = lever_noise(c, lever, groups)
>>> bool(5e-4 < tau < 2e-3), bool(0.02 < s0 < 0.1)
(True, True)
>>> w = lever_weights(c, lever, groups)
>>> bool(w[1] > 2 * w[0])                          # the face 100 px from c_x counts more
True
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Fewest captures with faces spread along x (≥ :data:`MIN_SPREAD_PX`) to estimate τ from.
MIN_CAPTURES = 4
#: Least spread of one capture's lever arms (max − min) for its slope to count, px: two faces
#: of one capture closer than this tell the slope only to σ₀ / 35 px, ~10⁻³ for σ₀ = 0.05 px.
MIN_SPREAD_PX = 50.0
#: Fewest residual degrees of freedom about the captures' lines to estimate σ₀ from them.
MIN_DOF = 3

_MAD = 1.4826


def lever_noise(
    c: Any, lever_px: Any, groups: Any, sigma_px: Any = None
) -> tuple[float, float]:
    """(τ, σ₀): the spread of the captures' W-T scale errors (dimensionless) and one
    observation's own noise (px), from corrections ``c`` (N,) px, their lever arms
    ``lever_px`` (N,) = x_t − c_x px, their capture ``groups`` (N,) and optionally their own
    ``sigma_px`` (N,) (module docstring). τ is 0 when it cannot be told."""
    c = np.asarray(c, dtype=np.float64).reshape(-1)
    lev = np.asarray(lever_px, dtype=np.float64).reshape(-1)
    g = np.asarray(groups).reshape(-1)
    slopes, inv_sxx = [], []
    rss, dof = 0.0, 0
    for k in np.unique(g):
        m = (g == k) & np.isfinite(c) & np.isfinite(lev)
        n = int(m.sum())
        if n < 2 or np.ptp(lev[m]) < MIN_SPREAD_PX:
            continue
        lc = lev[m] - lev[m].mean()
        sxx = float(lc @ lc)
        b = float(lc @ (c[m] - c[m].mean())) / sxx
        slopes.append(b)
        inv_sxx.append(1.0 / sxx)
        if n >= 3:
            res = c[m] - c[m].mean() - b * lc
            rss, dof = rss + float(res @ res), dof + n - 2
    s0 = float(np.sqrt(rss / dof)) if dof >= MIN_DOF else float("nan")
    if not np.isfinite(s0) and sigma_px is not None:
        own = np.asarray(sigma_px, dtype=np.float64).reshape(-1)
        own = own[np.isfinite(own) & (own > 0)]
        s0 = float(np.median(own)) if own.size else float("nan")
    if len(slopes) < MIN_CAPTURES or not np.isfinite(s0):
        return 0.0, s0
    sl = np.asarray(slopes)
    spread = _MAD * float(np.median(np.abs(sl - np.median(sl))))
    tau2 = spread**2 - s0**2 * float(np.median(inv_sxx))
    return float(np.sqrt(max(tau2, 0.0))), s0


def lever_weights(c: Any, lever_px: Any, groups: Any, sigma_px: Any = None) -> np.ndarray:
    """Relative weights 1/σ_i (median 1), σ_i² = σ₀² + τ²·lever_i² (:func:`lever_noise`); all 1
    when τ is 0 or cannot be told. Shape (N,)."""
    lev = np.asarray(lever_px, dtype=np.float64).reshape(-1)
    tau, s0 = lever_noise(c, lev, groups, sigma_px)
    if not (tau > 0 and s0 > 0):
        return np.ones(lev.shape)
    sig = np.sqrt(s0**2 + (tau * np.nan_to_num(lev)) ** 2)
    return np.asarray(np.median(sig) / sig)


def capture_lever_variance(lever_px: Any, groups: Any, tau: float) -> np.ndarray:
    """The variance each capture's mean correction owes its W-T scale error, px², shape (G,)
    for the G captures of ``groups`` (N,) in ``np.unique`` order: τ²·l̄², l̄ the mean lever arm
    of the capture's faces (``lever_px`` (N,), px). Its faces share that error, so no number of
    them averages it out; a chart at the tele's centre (lever 0) does not carry it.

    >>> capture_lever_variance([300.0, 400.0, -50.0, 50.0], [0, 0, 1, 1], 1e-3)
    array([0.1225, 0.    ])
    """
    lev = np.nan_to_num(np.asarray(lever_px, dtype=np.float64).reshape(-1))
    g = np.unique(np.asarray(groups).reshape(-1), return_inverse=True)[1].ravel()
    n_g = int(g.max()) + 1 if g.size else 0
    mean_lever = np.bincount(g, lev, n_g) / np.maximum(np.bincount(g, minlength=n_g), 1)
    return np.asarray(float(tau) ** 2 * mean_lever**2)


__all__ = ["MIN_CAPTURES", "MIN_DOF", "MIN_SPREAD_PX", "capture_lever_variance", "lever_noise",
           "lever_weights"]
