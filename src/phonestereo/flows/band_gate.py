"""The one-surface check after the disparity plane (ROI disparity, issue #18).

The majority keeps the matches within a tolerance of the most populated disparity and the
plane is fitted to them; its σ then says nothing about matches just outside that band. One
surface gives one band (the folded-x3 and periscope-x5 demos: no match beside it); random-1001's
×3.9 periscope gave two bands of equal size 1.4 px apart on the verification chart (edges of
one polarity against the other's?), the majority picked either from capture to capture, and
the flow read −13 % and +28 % at 4 m with σ of 2-4 %: a confident wrong number.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from phonestereo.fixes.wt_scale import WTScale
from phonestereo.flows.roi_config import RoiConfig

#: A match whose rows still disagree after the W-T scale by more than this many of the fit's
#: inlier spread of e (and by at least :data:`ROW_FLOOR_PX`) is not a correspondence: on a
#: repetitive chart it is a row alias, a square above or below. random-3037 (a held-out module,
#: session 20): at 4 m, 25 of 110 matches sat 15 px off their row at 2 px less disparity, and
#: the plane through both read the chart 12 % far at 9.6σ.
ROW_SIGMAS = 6.0
#: See :data:`ROW_SIGMAS` (px): the spread of e after the W-T scale is 0.05–0.3 px.
ROW_FLOOR_PX = 1.0


def on_row(e: Any, rms_e_px: float) -> np.ndarray:
    """Which matches (N,) of non-disparity errors ``e`` (px, after the W-T scale whose inlier
    spread is ``rms_e_px``) lie on their row (:data:`ROW_SIGMAS`).

    >>> on_row([0.1, -0.05, 0.02, 15.1, 0.0], 0.11).tolist()
    [True, True, True, False, True]
    """
    ev = np.asarray(e, dtype=np.float64)
    return np.asarray(np.abs(ev - np.median(ev)) <= max(ROW_SIGMAS * rms_e_px, ROW_FLOOR_PX))


def band_split(
    xy: Any, d: Any, e: Any, majority_px: float, wt: WTScale | None, predict: Any,
    cfg: RoiConfig,
) -> dict[str, int]:
    """The surface window's matches (within 3 majority tolerances of ``majority_px``) about
    the plane: how many lie in the band (± one tolerance), how many on its fuller side beyond
    it, and that side's median offset (×10, px).

    Parameters
    ----------
    xy : (N, 2)
        All fine matches, reference rectified wide pixels.
    d, e : (N,)
        Their disparity and non-disparity error, px (before the W-T scale).
    majority_px : float
        The final majority disparity.
    wt : WTScale or None
        The W-T scale applied to the kept matches (None or not ok: none).
    predict : callable
        The plane's ``predict`` ((M, 2) → (d, σ)).
    cfg : RoiConfig

    Examples
    --------
    >>> xy = np.column_stack([np.arange(40.0), np.zeros(40)])
    >>> d = np.r_[np.full(20, 10.0), np.full(20, 11.5)]  # two bands 1.5 px apart
    >>> flat = lambda p: (np.full(len(p), 10.0), np.zeros(len(p)))
    >>> band_split(xy, d, np.zeros(40), 10.0, None, flat, RoiConfig())
    {'band_in': 20, 'band_side': 20, 'band_gap_x10': 15}
    """
    xy, d, e = (np.asarray(v, dtype=np.float64) for v in (xy, d, e))
    tol = max(cfg.majority_tol_px, cfg.majority_tol_rel * abs(majority_px))
    w = np.abs(d - majority_px) <= 3 * tol
    xw, dw, ew = xy[w], d[w], e[w]
    if wt is not None and wt.ok:  # on their rows only (on_row: a row alias is no match)
        dw, ew = wt.disparity(xw, xw - np.column_stack([dw, ew]))
        row = on_row(ew, wt.rms_e_px) if len(ew) else np.zeros(0, bool)
        xw, dw = xw[row], dw[row]
    r = dw - predict(xw)[0]
    above, below = r[r > tol], r[r < -tol]
    side = above if len(above) >= len(below) else below
    gap = round(10 * float(np.median(np.abs(side)))) if len(side) else 0
    return {"band_in": int((np.abs(r) <= tol).sum()), "band_side": len(side),
            "band_gap_x10": gap}


def band_reason(split: dict[str, int], cfg: RoiConfig) -> str:
    """Why the plane is not the surface's disparity ("" when it is)."""
    if split["band_side"] < cfg.max_band_split * max(split["band_in"], 1):
        return ""
    return (
        f"the surface's matches split into two disparities about "
        f"{split['band_gap_x10'] / 10:.1f} px apart ({split['band_in']} and "
        f"{split['band_side']} matches): no single disparity (the tele's blur or processing "
        "shifts the texture's edges by their polarity?) — focus the tele on the object or aim "
        "at other texture"
    )


__all__ = ["ROW_FLOOR_PX", "ROW_SIGMAS", "band_reason", "band_split", "on_row"]
