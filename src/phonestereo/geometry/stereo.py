"""Disparity ↔ depth for a rectified pair (thesis §1.1.2, eq. 4).

After rectification the disparity axis is x and d = x_wide − x_tele (positive in front).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from phonestereo.geometry.checks import Array, require_positive


def depth_from_disparity(d: Any, f_px: float, baseline_m: float) -> Array:
    """Z = f·B / d (eq. 4).

    Parameters
    ----------
    d : array_like, shape (...)
        Disparity in pixels; d ≤ 0 gives NaN (no point in front).
    f_px : float
        Focal length of the rectified pair in pixels.
    baseline_m : float
        Baseline in metres.

    Returns
    -------
    ndarray, shape (...)
        Depth in metres.

    Examples
    --------
    >>> float(depth_from_disparity(9.0, 1500.0, 0.012))
    2.0
    """
    return _fb_over(d, f_px, baseline_m)


def disparity_from_depth(z: Any, f_px: float, baseline_m: float) -> Array:
    """d = f·B / Z (eq. 4), pixels; Z ≤ 0 gives NaN.

    Examples
    --------
    >>> float(disparity_from_depth(2.0, 1500.0, 0.012))
    9.0
    """
    return _fb_over(z, f_px, baseline_m)


def relative_depth_error(z: Any, f_px: float, baseline_m: float, sigma_d_px: Any) -> Array:
    """δZ / Z = Z·δd / (f·B), the sensitivity of eq. (4), first order.

    Examples
    --------
    >>> round(float(relative_depth_error(2.0, 1500.0, 0.012, 0.1)), 4)   # docs/equations.md: 1.1 %
    0.0111
    """
    f = require_positive(f_px, "focal length f_px", "pixels")
    b = require_positive(baseline_m, "baseline_m", "metres")
    return np.asarray(z, dtype=np.float64) * np.asarray(sigma_d_px, dtype=np.float64) / (f * b)


def _fb_over(x: Any, f_px: float, baseline_m: float) -> Array:
    """f·B / x where x > 0, NaN elsewhere (eq. 4 both ways: x is a disparity or a depth)."""
    f = require_positive(f_px, "focal length f_px", "pixels")
    b = require_positive(baseline_m, "baseline_m", "metres")
    xx = np.asarray(x, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(xx > 0, f * b / xx, np.nan)
