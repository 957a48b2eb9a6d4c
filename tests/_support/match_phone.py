"""The sparse matcher on real phone pairs: ../shared/data/phone_wide_ultra (issue #16 item 4).

Real ultra-wide (our ``wide``) + wide (our ``tele``) 480 × 424 JPEGs out of a phone's ISP, with a
third party's OpenCV calibration (camera 1 = the phone's wide = our tele). Per pair, through the
product: the calibration converted by :func:`phonestereo.io.opencv_yaml.import_opencv_yaml`
(``convert-calibration … --first-camera tele``), the pair rectified in canonical mode
(:class:`phonestereo.rectification.rectify.Rectification`, the tele's field of view), matched
with :func:`phonestereo.features.matching.match_rectified` both ways. Reported: the matches,
the median |e| (row error after rectification, px) and the left→right vs right→left
consistency: the pair is matched again with the images swapped and mirrored (x → W − 1 − x keeps
d > 0), matches are paired by position (same left pixel within 1 px: the mirrored right point
x − d, row y − e), and RMS of (d_LR − d_RL) / √(σ_LR² + σ_RL²) is reported. It is ≈ 1 for
honest σ only when the two directions' errors are independent: both fit the same pixels, so a
misfit common to both (compression, denoising, the ISP's) cancels and the figure reads low
(Middlebury JPEG q85: 0.58–0.83 while σ_d is too small against the ground truth), and so does
the sensor noise: on the ISP renders of ``match_isp.isp_honesty``, where σ_d is honest against
the truth, the two directions' errors correlate 0.97–0.99 and the figure reads 0.08–0.17. It
measures the direction-dependent part of the error only: a figure above 1 shows σ_d too small,
one below 1 does not show it too large.

``benchmarks/bench_match_phone.py`` prints the per-pair table.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from _support import SHARED_DATA
from phonestereo.features.matching import MatchConfig, match_rectified
from phonestereo.io.images import read_gray
from phonestereo.io.opencv_yaml import import_opencv_yaml
from phonestereo.rectification.options import RectifyOptions
from phonestereo.rectification.rectify import Rectification

DATA = SHARED_DATA / "phone_wide_ultra"
SIZE = (480, 424)
#: the product's default matcher (the misfit floor, measured in units of the pair's input noise,
#: holds after the blur equalisation that the phone's sharper tele triggers)
CONFIG = MatchConfig()
MAX_DISPARITY = 64  # px at the wide's rectified scale: 1 m at f ≈ 390 px, B ≈ 1.9 cm gives 7.5


def pairs() -> list[tuple[str, Path, Path]]:
    """(name, wide = phone's ultra-wide, tele = phone's wide) of every frame pair, sorted."""
    out = []
    for folder in sorted(p for p in DATA.iterdir() if p.is_dir()):
        for ultra in sorted(folder.glob("*ultra*.jpg")):
            wide_phone = ultra.with_name(ultra.name.replace("ultra", "wide"))
            if wide_phone.exists():
                out.append((f"{folder.name.split('_')[0]}/{ultra.stem}", ultra, wide_phone))
    return out


@lru_cache(maxsize=1)
def rectification() -> Rectification:
    """The canonical rectification from the third party's calibration, through the product."""
    cal = import_opencv_yaml(
        DATA / "intrinsics.yml",
        DATA / "extrinsics.yml",
        wide_size=SIZE,
        tele_size=SIZE,
        first_camera="tele",
    )
    return Rectification.from_rig(cal.rig, "canonical", RectifyOptions())


def both_directions(
    left: np.ndarray, right: np.ndarray, max_disparity: int = MAX_DISPARITY
) -> tuple[Any, Any, np.ndarray, np.ndarray]:
    """The pair matched left→right and right→left, and which matches pair up.

    Returns (lr, rl, i, j): the two :class:`MatchResult` s and the indices of the paired
    matches (``lr`` match i is ``rl`` match j; ``rl.d[j]`` is a disparity of the same sign).
    """
    lr = match_rectified(left, right, max_disparity=max_disparity, config=CONFIG)
    w = left.shape[1]
    # right→left: the right image is the new left; mirrored, so that d stays positive
    rl = match_rectified(
        right[:, ::-1], left[:, ::-1], max_disparity=max_disparity, config=CONFIG
    )
    # a right→left match at mirrored (x', y') of the right image is the left point
    # (W − 1 − x' + d, y' − e): its e = y_right − y_left (the images swapped)
    back = np.column_stack([w - 1 - rl.xy[:, 0] + rl.d, rl.xy[:, 1] - rl.e])
    i = j = np.zeros(0, np.int64)
    if len(lr) and len(rl):
        dist, jj = cKDTree(back).query(lr.xy, distance_upper_bound=1.0)
        hit = np.isfinite(dist)
        i, j = np.flatnonzero(hit), jj[hit]
    return lr, rl, i, j


def consistency(left: np.ndarray, right: np.ndarray) -> dict[str, Any]:
    """Matches both ways on a rectified pair and their left→right / right→left agreement."""
    lr, rl, i, j = both_directions(left, right)
    z = (lr.d[i] - rl.d[j]) / np.hypot(lr.sigma_d[i], rl.sigma_d[j])
    return {
        "matches": len(lr),
        "matches_rl": len(rl),
        "median_abs_e_px": float(np.median(np.abs(lr.e))) if len(lr) else float("nan"),
        "median_sigma_d_px": float(np.median(lr.sigma_d)) if len(lr) else float("nan"),
        "paired": len(z),
        "rms_z": float(np.sqrt(np.mean(z**2))) if len(z) else float("nan"),
        "reason": lr.reason,
    }


def pooled_rms_z(rows: list[dict[str, Any]]) -> float:
    """RMS z over every paired match of the pairs' :func:`consistency` rows (each pair's RMS
    weighted by its pairs; pairs without a finite RMS are left out)."""
    ok = [r for r in rows if np.isfinite(r["rms_z"])]
    w = np.array([r["paired"] for r in ok], dtype=np.float64)
    z = np.array([r["rms_z"] for r in ok])
    return float(np.sqrt(np.sum(w * z**2) / np.sum(w)))


def evaluate(wide: Path, tele: Path) -> dict[str, Any]:
    """Rectify one real pair and match it both ways (see :func:`consistency`)."""
    left, right = rectification().remap(read_gray(wide), read_gray(tele))
    return consistency(np.asarray(left), np.asarray(right))
