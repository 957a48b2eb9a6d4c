"""The learning phase: face captures → disparity observations in the fix store (thesis §4.1.3).

Per face capture (Fig. 4-3, 4-4): landmarks in the wide and the tele → IPD depth → landmark
disparity (:func:`~phonestereo.learning.landmark_disparity.landmark_disparity`) → one
:class:`~phonestereo.learning.observation.Observation` per measured face (sensor position = the
face's rectified wide pupil midpoint, measured and expected disparity, depth, orientation
bucket, focus group, time, temperature).

This module is the per-capture landmark block only. The learning of a capture set — gates,
focus calibration, W-T scale, the store and its context — is
:func:`phonestereo.flows.learning.run`, the one path every command takes (an earlier
``learn_capture_set`` here had none of those: it corrected focus breathing twice and learned
cold captures).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from phonestereo.features.landmarks import LandmarkBackend, MediaPipeBackend
from phonestereo.fixes.orientation import orientation_bucket
from phonestereo.io import (
    CaptureEntry,
    CaptureSet,
    read_gray,
)
from phonestereo.learning.ipd import IPD_M
from phonestereo.learning.landmark_disparity import (
    DepthMode,
    LandmarkDisparityResult,
    landmark_disparity,
)
from phonestereo.learning.observation import Observation
from phonestereo.learning.pair_guide import WideToTeleGuide
from phonestereo.rectification import Rectification

#: Progress callback: ``progress(done, total, capture_id)``.
Progress = Callable[[int, int, str], None]


def capture_orientation(entry: CaptureEntry) -> str:
    """The capture's orientation label, else its gravity bucket
    (:func:`~phonestereo.fixes.orientation.orientation_bucket`, §3.4), else ``"unknown"``."""
    if entry.orientation:
        return str(entry.orientation)
    if entry.gravity is not None:
        return orientation_bucket(entry.gravity)
    return "unknown"


@dataclass(frozen=True)
class LearnResult:
    """What one capture gave: observations, the face measurement, or why it was skipped.

    ``timing_s`` holds ``detect`` (landmarks, both images), ``disparity`` and ``total``.
    """

    capture_id: str
    observations: tuple[Observation, ...]
    disparity: LandmarkDisparityResult | None
    reason: str = ""
    timing_s: dict[str, float] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when at least one observation was learned."""
        return len(self.observations) > 0

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly record."""
        return {
            "capture_id": self.capture_id,
            "n_observations": len(self.observations),
            "reason": self.reason,
            "timing_s": {k: round(v, 4) for k, v in self.timing_s.items()},
            "faces": [] if self.disparity is None else [f.to_dict() for f in self.disparity.faces],
        }


def learn_capture(
    capture_set: CaptureSet,
    capture_id: str,
    rect: Rectification,
    *,
    ipd_m: float = IPD_M,
    source: str = "face-chart",
    depth_mode: DepthMode = "chart",
    chart_pitch_m: float | None = None,
    backend: LandmarkBackend | None = None,
    guided: bool = True,
    images: tuple[Any, Any] | None = None,
    d_offset_px: float = 0.0,
) -> LearnResult:
    """Learn the disparity observations of one face capture.

    Parameters
    ----------
    capture_set : CaptureSet
        The loaded capture set.
    capture_id : str
        Which capture.
    rect : Rectification
        Of the calibration (``canonical``).
    ipd_m : float
        IPD, metres (the chart's 63 mm, or a population mean).
    source : str
        Recorded as the observations' ``source`` (``"face-chart"`` / ``"population"``).
    depth_mode : {"chart", "face"}
        One printed plane of faces, or real heads (see
        :func:`~phonestereo.learning.landmark_disparity.ipd_depths`).
    chart_pitch_m : float, optional
        The face chart's grid pitch: its eye midpoints, not the IPDs, scale the chart's plane
        (:mod:`~phonestereo.learning.chart_pitch`).
    backend : LandmarkBackend, optional
        Default: :class:`MediaPipeBackend`.
    guided : bool
        Find the faces in the wide and measure the tele only where they map to
        (:class:`~phonestereo.learning.pair_guide.WideToTeleGuide`). False: search the whole
        tele image too.
    images : (wide, tele) arrays, optional
        The capture's decoded images, when the caller has them (else read from the set).
    d_offset_px : float
        The calibration's known disparity offset, px (see
        :func:`~phonestereo.learning.landmark_disparity.landmark_disparity`).

    Returns
    -------
    LearnResult
        Observations (one per face measured in both cameras) or the reason there are none.
    """
    t0 = time.perf_counter()
    entry = capture_set.get(capture_id)
    if entry.time_s is None:  # an observation records the heating state it was learned in
        why = (
            "no time_s (seconds since the camera app started) in the manifest: an observation "
            "records the heating state it was learned in; add time_s to learn from this capture"
        )
        return LearnResult(entry.id, (), None, why, {"total": time.perf_counter() - t0})
    if images is None:
        path_w, path_t = capture_set.image_paths(capture_id)
        img_w, img_t = read_gray(path_w), read_gray(path_t)
    else:
        img_w, img_t = images
    det = backend if backend is not None else MediaPipeBackend()
    guide = WideToTeleGuide(rect, ipd_m) if guided else None
    faces_w, faces_t = det.detect_pair(img_w, img_t, guide)
    t1 = time.perf_counter()
    res = landmark_disparity(
        rect, img_w, img_t, faces_w, faces_t, ipd_m=ipd_m, depth_mode=depth_mode,
        chart_pitch_m=chart_pitch_m, d_offset_px=d_offset_px,
    )
    t2 = time.perf_counter()
    timing = {"detect": t1 - t0, "disparity": t2 - t1, "total": t2 - t0}
    orientation = capture_orientation(entry)
    obs = []
    for f in res.faces:
        if not (np.isfinite(f.d_px) and np.isfinite(f.d_expected_px) and f.depth_ipd_m > 0):
            continue
        obs.append(
            Observation(
                x_px=f.x_px,
                y_px=f.y_px,
                d_measured_px=f.d_px,
                d_expected_px=f.d_expected_px,
                depth_m=f.depth_ipd_m,
                orientation=orientation,
                focus_group=entry.focus_group,
                time_s=entry.time_s,
                temperature_c=entry.temperature_c,
                capture_id=entry.id,
                source=source,
                sigma_px=f.sigma_d_px,
                # in the calibration's rectification (rect's tele rows may have been moved)
                e_measured_px=f.e_px + rect.options.tele_row_shift_px,
            )
        )
    reason = "" if obs else (res.reason or "no face measured")
    return LearnResult(entry.id, tuple(obs), res, reason, timing)
