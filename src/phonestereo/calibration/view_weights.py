"""Per-view weights of the calibration solve (variance components; :mod:`.solve`).

A phone's board views are not alike. On the presets' ISP renders the wide's views of far boards
(45 px squares) err 0.041–0.055 px per coordinate, against 0.012–0.017 px for near ones (61–90 px).
One pooled σ took their corners for outliers (28–73 a seed) and read d²/P 1.31 over six seeds.
A view keeps the pooled σ unless its own residual σ differs from it beyond chance (a χ² test at
the 99.7 % the outlier test uses); then it gets its own. Measured (session 29): the six ISP
seeds read d²/P 1.00 and RMS z 1.07 (pooled 1.31 / 1.20), the six linear seeds 1.05 / 1.04
(pooled 1.04 / 1.04), the 20-seed covariance test on linear renders 1.086 / 1.063 (pooled
1.091 / 1.040). Every view by its own σ, untested, read 1.079 / 1.103 there: the views' own σ
estimates carry ~7 % chance error at 54 corners, which weights of their own pass to the
covariance. The detector's corner σ as the weight read 1.00 on the ISP but 1.20 on linear
renders, where its misfit term errs on the side of caution; the residuals are the data's own
word on each view. On the OpenCV sample's real JPEGs one view (left08.jpg, a steeply tilted
board, 2.3× the pooled σ) gets its own σ, and 9 of 1402 corners are rejected instead of 18.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy import sparse, stats

from phonestereo.calibration.bundle import Observations

#: Two-sided significance of the test "this view's residual σ is the pooled one": the 99.7 %
#: of the solve's outlier test. Over 0.0003–0.03 the 20-seed covariance test reads RMS z
#: 1.052–1.063 and d²/P 1.075–1.086 (session 29), so the choice is not critical.
EQUAL_SIGMA_SIGNIFICANCE = 0.003


def view_weights(
    residuals: np.ndarray,
    inliers: np.ndarray,
    obs: Observations,
    *,
    significance: float = EQUAL_SIGMA_SIGNIFICANCE,
) -> np.ndarray:
    """Each corner's weight σ_ref / σ_view from its view's own residuals (variance components).

    σ_view² = Σ r² / (2n − 6) over the view's n kept corners (its pose takes 6 degrees of
    freedom), σ_ref the pooled σ of the views alike (starting from their median). A view keeps
    σ_ref unless σ_view² / σ_ref² lies outside the two-sided ``significance`` interval of
    χ²_ν / ν (ν = 2n − 6): a σ that differs only by chance would pass its own estimation error
    to the covariance. A view of fewer than 8 kept corners gets σ_ref, and σ_view is floored at
    σ_ref / 4 (one view must not decide the cameras).

    Parameters
    ----------
    residuals : ndarray, shape (M, 2)
        Residuals of every corner, px.
    inliers : ndarray of bool, shape (M,)
        The corners kept.
    obs : Observations
        Their cameras and views.
    significance : float, optional
        Two-sided probability, under equal σ, of a view being given its own.

    Returns
    -------
    ndarray, shape (M,)
    """
    key = obs.camera.astype(np.int64) * (int(obs.view.max(initial=0)) + 1) + obs.view
    _, group = np.unique(key, return_inverse=True)
    kept = np.asarray(inliers, dtype=np.float64)
    n = np.bincount(group, weights=kept)
    ss = np.bincount(group, weights=kept * np.sum(np.asarray(residuals) ** 2, axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        sig = np.where(n >= 8, np.sqrt(ss / (2 * n - 6)), np.nan)
    ok = np.isfinite(sig) & (sig > 0)
    if not ok.any():
        return np.ones(key.size)
    nu = np.maximum(2 * n - 6, 1.0)
    lo = stats.chi2.ppf(significance / 2, nu) / nu
    hi = stats.chi2.isf(significance / 2, nu) / nu

    def alike_to(ref: float) -> np.ndarray:
        ratio = (sig / ref) ** 2
        return np.asarray(ok & (ratio >= lo) & (ratio <= hi))

    # σ_ref: the median, then the pooled σ of the views alike to it (the median alone sits
    # high when a third of the views are noisy, and flags quiet views by their chance lows)
    ref = float(np.median(sig[ok]))
    for _ in range(3):
        alike = alike_to(ref)
        if not alike.any():
            break
        pooled = float(np.sqrt(np.sum(ss[alike]) / np.sum(nu[alike])))
        if abs(pooled - ref) <= 1e-6 * ref:
            break
        ref = pooled
    alike = alike_to(ref)
    sig = np.where(ok & ~alike, np.maximum(sig, ref / 4), ref)
    return np.asarray(ref / sig[group])


def weighted_rows(jac: Any, wr: np.ndarray) -> Any:
    """The Jacobian's rows scaled by the residuals' weights (sparse stays sparse)."""
    if jac is None or np.all(wr == 1.0):
        return jac
    return sparse.diags(wr) @ jac


__all__ = ["view_weights", "weighted_rows"]
