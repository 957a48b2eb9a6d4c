"""The chart ruler (thesis §1.2.2): matched verification-chart corners of a capture, rectified.

Every chapter-3 analysis measures through the same ruler: the verification chart is detected in
the wide and the tele image, corners are matched by their chart (row, col) id, and the pairs are
rectified (points, exact: no image resampling) into disparity ``d`` and non-disparity error
``e``. Helpers here also take the corners seen in *every* capture of a series (so a corner
dropped in one capture cannot move a mean) and, for simulated sets, the same quantities from the
true corner pixels (scoring only; the sim import is deferred and never used to fix anything).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from phonestereo.features.verification import ChartDetection, detect_verification_chart
from phonestereo.io import CaptureEntry, CaptureSet, read_gray
from phonestereo.rectification import Rectification

F64 = np.ndarray
MIN_CORNERS = 4  # fewest corners seen in both images for a capture to count as measured


@dataclass(frozen=True)
class CaptureMeasurement:
    """Matched chart corners of one capture, rectified."""

    #: Capture id.
    id: str
    #: ``time_s``, ``temperature_c``: float, float or None. From the manifest.
    time_s: float
    #: See ``time_s`` above.
    temperature_c: float | None
    #: False when the chart was not measured (``reason`` says why).
    found: bool
    reason: str
    #: (N, 2) int64. Chart (row, col) of each matched corner.
    ids: np.ndarray
    #: ``q_wide``, ``q_tele``: (N, 2) float64. Detected corner pixels in the wide and the tele
    #: image.
    q_wide: F64
    #: See ``q_wide`` above.
    q_tele: F64
    #: ``d_px``, ``e_px``: (N,) float64. Rectified disparity and non-disparity error, pixels.
    d_px: F64
    #: See ``d_px`` above.
    e_px: F64


def corner_keys(ids: np.ndarray) -> np.ndarray:
    """One int64 key per chart (row, col) id, for set operations; ids (N, 2) -> (N,)."""
    ids = np.asarray(ids, dtype=np.int64).reshape(-1, 2)
    return np.asarray(ids[:, 0] * 100_000 + ids[:, 1], dtype=np.int64)


def match_detections(dw: ChartDetection, dt: ChartDetection) -> tuple[np.ndarray, F64, F64]:
    """Corners found in both detections, matched by id: (ids (N, 2), q_wide, q_tele (N, 2))."""
    _, iw, it = np.intersect1d(corner_keys(dw.ids), corner_keys(dt.ids), return_indices=True)
    return dw.ids[iw], dw.points[iw], dt.points[it]


def measure_capture(
    cs: CaptureSet, entry: CaptureEntry, rect: Rectification, *, min_corners: int = MIN_CORNERS
) -> CaptureMeasurement:
    """Detect the chart in both images of a capture, match corners by id, rectify (px)."""
    t_s = float("nan") if entry.time_s is None else entry.time_s  # NaN: time not recorded
    dets = [detect_verification_chart(read_gray(p)) for p in cs.image_paths(entry.id)]
    dw, dt = dets
    ids, qw, qt = match_detections(dw, dt)
    bad = [f"{r}: {x.reason}" for r, x in zip(("wide", "tele"), dets, strict=True) if not x.found]
    if not bad and len(ids) < min_corners:
        bad = [f"only {len(ids)} corners seen in both images"]
    if bad:
        z, e2, empty = np.zeros(0), np.zeros((0, 2)), np.zeros((0, 2), np.int64)
        return CaptureMeasurement(
            entry.id, t_s, entry.temperature_c, False, bad[0], empty, e2, e2, z, z
        )
    d, e = rect.disparity(qw, qt)
    return CaptureMeasurement(entry.id, t_s, entry.temperature_c, True, "", ids, qw, qt, d, e)


def shared_keys(ms: list[CaptureMeasurement]) -> np.ndarray:
    """Keys of the corners found in every measured capture (sorted int64)."""
    good = [m for m in ms if m.found]
    if not good:
        return np.zeros(0, np.int64)
    shared = corner_keys(good[0].ids)
    for m in good[1:]:
        shared = np.intersect1d(shared, corner_keys(m.ids))
    return shared


def per_corner(ms: list[CaptureMeasurement], keys: np.ndarray, attr: str = "d_px") -> F64:
    """A (M captures, K corners) table of ``attr`` at the given corner keys (NaN when missing)."""
    out = np.full((len(ms), len(keys)), np.nan)
    for i, m in enumerate(ms):
        if not m.found:
            continue
        col = {int(k): j for j, k in enumerate(corner_keys(m.ids))}
        vals = np.asarray(getattr(m, attr))
        for j, k in enumerate(keys):  # K corners per capture (tens), not pixels
            if int(k) in col:
                out[i, j] = vals[col[int(k)]]
    return out


def true_corners(root: Path, capture_id: str, object_index: int = 0) -> Any:
    """True corner pixels of a simulated capture (scoring only), or None for a real set.

    Returns the ground-truth keypoint arrays (``ids``, ``wide_px``, ``tele_px``) of the
    object's ``corners``.
    """
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    path = root / GROUND_TRUTH_NAME
    if not path.is_file():
        return None
    gt = load_ground_truth(path)
    return gt.capture(capture_id).objects[object_index].keypoints["corners"].arrays()


__all__ = [
    "CaptureMeasurement",
    "corner_keys",
    "match_detections",
    "measure_capture",
    "per_corner",
    "shared_keys",
    "true_corners",
]
