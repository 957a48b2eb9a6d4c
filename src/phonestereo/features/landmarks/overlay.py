"""Draw a :class:`~phonestereo.features.landmarks.base.FaceResult` on its image."""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from phonestereo.features.landmarks.base import U8, FaceResult, as_rgb
from phonestereo.features.landmarks.eyes import IBUG_EYE_CONTOUR, MP_EYE_CONTOUR

_GREEN, _RED, _BLUE, _ORANGE, _GREY = (0, 200, 0), (0, 0, 255), (255, 120, 0), (0, 140, 255), (
    160, 160, 160,
)


def _pt(p: Any) -> tuple[int, int]:
    return round(float(p[0])), round(float(p[1]))


def draw_faces(image: object, result: FaceResult) -> U8:
    """A BGR copy of ``image`` with the faces drawn.

    Per face: its landmark box (green), every landmark (small grey dots), the eye-contour
    points (blue), the eye centres (blue crosses), the pupils (red crosses) joined by a line,
    and a label "#k ipd … px, yaw …°". Rejected candidates get an orange box and their
    reason; a banner gives the count or the reason none was found.

    Parameters
    ----------
    image : ndarray (H, W) gray / (H, W, 3) BGR uint8, or a path
    result : FaceResult

    Returns
    -------
    ndarray, shape (H, W, 3), uint8

    >>> from phonestereo.features.landmarks.base import make_result
    >>> draw_faces(np.zeros((60, 80), np.uint8), make_result((), (80, 60), "none")).shape
    (60, 80, 3)
    """
    out = cv2.cvtColor(as_rgb(image), cv2.COLOR_RGB2BGR)
    h, w = out.shape[:2]
    scale = max(h, w) / 1000.0
    thick = max(1, round(1.5 * scale))
    font = 0.45 * max(scale, 0.6)
    for k, f in enumerate(result.faces):
        x0, y0, x1, y1 = f.box_px
        cv2.rectangle(out, _pt((x0, y0)), _pt((x1, y1)), _GREEN, thick, cv2.LINE_AA)
        r_dot = max(1, round(scale))
        if f.ipd_px >= 40:  # every landmark, where they do not blot the face out
            for p in f.landmarks_px:
                cv2.circle(out, _pt(p), r_dot, _GREY, -1, cv2.LINE_AA)
        contour = MP_EYE_CONTOUR if len(f.landmarks_px) >= 478 else IBUG_EYE_CONTOUR
        for group in contour:
            for i in group:
                cv2.circle(out, _pt(f.landmarks_px[i]), r_dot + 1, _BLUE, -1, cv2.LINE_AA)
        size = max(6, round(0.12 * f.ipd_px))
        for c in f.eye_centres_px:
            cv2.drawMarker(out, _pt(c), _BLUE, cv2.MARKER_TILTED_CROSS, size, thick, cv2.LINE_AA)
        a, b = (_pt(p) for p in f.pupils_px)
        cv2.line(out, a, b, _RED, max(1, thick // 2), cv2.LINE_AA)
        for p in (a, b):
            cv2.drawMarker(out, p, _RED, cv2.MARKER_CROSS, size, thick, cv2.LINE_AA)
        yaw = "?" if not np.isfinite(f.yaw_rad) else f"{np.degrees(f.yaw_rad):+.1f}"
        label = f"#{k} ipd {f.ipd_px:.1f}px yaw {yaw}deg"
        fit = max(0.3, min(font, 1.5 * (x1 - x0) / (20.0 * len(label))))  # about the box width
        cv2.putText(out, label, _pt((x0, y0 - 6 * fit)), cv2.FONT_HERSHEY_SIMPLEX,
                    fit, _GREEN, max(1, round(2 * fit)), cv2.LINE_AA)
    for r in result.rejected:
        x0, y0, x1, y1 = r.box_px
        cv2.rectangle(out, _pt((x0, y0)), _pt((x1, y1)), _ORANGE, thick, cv2.LINE_AA)
        cv2.putText(out, r.reason[:60], _pt((x0, y1 + 16 * max(scale, 0.6))),
                    cv2.FONT_HERSHEY_SIMPLEX, font, _ORANGE, thick, cv2.LINE_AA)
    banner = f"{len(result)} face(s)" if result.found else f"no face: {result.reason}"
    cv2.putText(out, banner[:90], (10, round(28 * max(scale, 0.6))), cv2.FONT_HERSHEY_SIMPLEX,
                1.6 * font, _GREEN if result.found else _RED, thick, cv2.LINE_AA)
    return out
