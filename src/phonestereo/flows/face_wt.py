"""The W-T scale's measurement of a face capture (:func:`~phonestereo.flows.learning.
learn_face_capture`), started before its landmarks.

The learning flow fits the W-T scale (§3.5.1) with :func:`~phonestereo.flows.roi_disparity.
measure_roi` over everything the tele sees. That measurement reads the images, not the
landmarks, so :func:`start_wt` runs it on a thread of its own
(:func:`~phonestereo.features._threads.ahead`) while MediaPipe detects the faces on the calling
thread: MediaPipe's graph computes on its own threads with the GIL released (the calling
thread's CPU is ~25 of its ~95 ms at 2000 × 1500), and a 2 MP measurement is ~65 ms of a
~200 ms face capture. Its helper work (:func:`~phonestereo.features._threads.background`) still
goes to the helper thread, which the landmark disparity shares once the landmarks are found. The
results are those of measuring after the landmarks: ``measure_roi`` gives the same numbers on
any thread.
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import Future, wait
from dataclasses import replace
from functools import partial
from typing import Any

from phonestereo.features._threads import ahead, split_enabled
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.roi_disparity import RoiMeasurement, measure_roi
from phonestereo.flows.view_box import tele_view_box
from phonestereo.geometry import Rig
from phonestereo.rectification import Rectification

__all__ = ["measure_wt", "settle", "start_wt", "wt_box"]

Box = tuple[int, int, int, int]


def wt_box(ref: Rectification) -> Box | None:
    """The raw-wide box (x, y, w, h) of the face captures' W-T scale fit: everything the tele
    sees (:func:`~phonestereo.flows.view_box.tele_view_box`, inside the wide image);
    None when that is less than 32 px high or wide.

    The scale is read from e across the disparity axis, so its error is the matches' e error
    over their lever (the box's height in tele pixels). The faces' own box (a row of faces, a
    small lever) scattered the scale by 0.15 % on a ×3.5 periscope (random-1000), ±0.5 px in
    single face observations; the tele's whole view, 0.04 % (docs/module-random.md).
    """
    box = tele_view_box(ref)
    return box if min(box[2], box[3]) >= 32 else None


def measure_wt(
    config: FlowConfig, rig: Rig, images: tuple[Any, Any], box: Box, rect: Rectification
) -> RoiMeasurement:
    """:func:`measure_roi` of the raw ``images`` (wide, tele) over ``box`` (:func:`wt_box`)
    with the face captures' settings (``face_wt_keypoints``, no ROI expansion)."""
    match = replace(config.roi.match, max_keypoints=int(config.face_wt_keypoints))
    roi_cfg = replace(config.roi, expand=1.0, coarse_expand=1.0, match=match)
    return measure_roi(rig, images[0], images[1], box, roi_cfg, rect, mode=config.mode)


def start_wt(
    config: FlowConfig, rig: Rig, images: tuple[Any, Any], rect: Rectification
) -> tuple[Callable[[], RoiMeasurement] | None, Future[RoiMeasurement] | None]:
    """``(measure, pending)``: ``measure()`` gives the capture's :func:`measure_wt` (None: no
    W-T scale, or the tele's view is not inside the wide image); ``pending`` is that measurement
    already running on its own thread (None without a second core: ``measure()`` measures
    then). Hand ``pending`` to :func:`settle` once the capture is done."""
    box = wt_box(rect) if config.wt_scale else None
    if box is None:
        return None, None
    if not split_enabled():  # nothing to overlap with: measured only if the landmarks need it
        return partial(measure_wt, config, rig, images, box, rect), None
    pending = ahead(measure_wt, config, rig, images, box, rect)
    return pending.result, pending


def settle(pending: Future[Any] | None) -> None:
    """Cancel ``pending``, or wait for it when it is running (a capture without faces, or one
    that raised, does not read it): no measurement of one capture may still run on its
    thread when the next one starts."""
    if pending is not None and not pending.cancel():
        wait([pending])
