"""A face's disparity without tele landmarks (learning for any focal ratio, issue 18).

Face Mesh fails on a face that fills a ×5 tele or is cut by its border, and the wide-to-tele
guide can miss a face; the wide's pupils and the disparity their IPD predicts still say where
to look. :func:`search_start` gives the landmark disparity that
:func:`~phonestereo.learning.landmark_disparity.landmark_disparity` would have taken from the
tele's landmarks, by NCC at the two eyes.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from phonestereo.features.search import ncc_search
from phonestereo.learning.eye_images import MAX_RADIUS
from phonestereo.rectification import Rectification

F64 = NDArray[np.float64]
F32 = NDArray[np.float32]


def search_start(
    rect: Rectification,
    left: F32,
    right: F32,
    pupils: F64,
    gate: tuple[float, float],
    max_e_px: float,
    min_score: float = 0.6,
) -> tuple[tuple[float, float] | None, str]:
    """The landmark (d, e) of a wide face without a tele partner, searched from its rectified
    pupils (2, 2) in the rectified pair ``left`` (wide), ``right`` (tele) (float32): one window
    per eye, NCC over the disparities ``gate`` (lo, hi) px — the expected-disparity gate of
    :func:`~phonestereo.learning.landmark_disparity.match_faces` — and rows within
    ``max_e_px``; both eyes must be in the tele's image and agree within 2 px.

    Returns ((d, e), "") or (None, the reason).
    """
    lo, hi = gate
    guess = pupils - [0.5 * (lo + hi), 0.0]
    raw = rect.unrectify_tele(guess)
    w, h = rect.rig.tele.size
    if not (np.isfinite(raw).all() and ((raw >= 0) & (raw <= [w - 1, h - 1])).all()):
        return None, "an eye is outside the tele's view"
    ipd = float(np.linalg.norm(pupils[1] - pupils[0]))
    r = int(np.clip(round(0.3 * ipd), 6, MAX_RADIUS))
    xy = np.rint(pupils).astype(np.int64)
    hh, ww = left.shape
    if not ((xy >= r + 2) & (xy < [ww - r - 2, hh - r - 2])).all():
        return None, "an eye is at the rectified image's edge"
    s = ncc_search(
        left, right, xy, radius=r, min_d=int(np.floor(lo)), max_d=int(np.ceil(hi)),
        row_tolerance=int(np.ceil(max_e_px)),
        lr_min_score=np.inf,
    )
    ok = s.searched & ~s.at_edge & np.isfinite(s.d0) & (s.score >= min_score)
    if not ok.all() and (s.at_edge & (s.score >= min_score)).any():
        return None, (
            "no tele face landmarks and the eyes correlate best at the end of the disparities "
            f"the IPD allows ({lo:.0f} to {hi:.0f} px): the "
            "calibration's disparity is off by more than that, or the IPD is far from assumed"
        )
    if not ok.all():
        return None, (
            "no tele face landmarks and the eyes do not correlate with the tele "
            f"(NCC {np.nan_to_num(s.score).round(2).tolist()} < {min_score})"
        )
    if abs(float(s.d0[1] - s.d0[0])) > 2.0 or abs(float(s.e0[1] - s.e0[0])) > 2.0:
        return None, "no tele face landmarks and the two eyes' searches disagree"
    return (float(np.mean(s.d0)), float(np.mean(s.e0))), ""


__all__ = ["search_start"]
