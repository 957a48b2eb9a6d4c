"""Focus calibration (thesis Fig. 4-1, §3.5.3): a refocus stack → a correction per attempt.

N refocus attempts at the same manual focus position never land on the same lens position.
Per camera, features of the first attempt are tracked into every other attempt (same camera:
pyramidal Lucas–Kanade, ``cv2.calcOpticalFlowPyrLK``), each attempt's scale and offset about
the principal point is fitted (:func:`~phonestereo.fixes.focus.fit_scale_offset`) and
normalised to the stack's median (:func:`~phonestereo.fixes.focus.normalise_to_median`): the
correction of an attempt maps its pixels into the median geometry, i.e. a calibration whose
camera is scaled and shifted accordingly (:meth:`FocusCorrection.apply`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from phonestereo.fixes.focus import ScaleOffset, fit_scale_offset, normalise_to_median
from phonestereo.geometry import Camera, Rig

#: Features tracked per camera.
MAX_FEATURES = 400


@dataclass(frozen=True)
class FocusCorrection:
    """The corrections of one attempt: wide and tele pixels → the stack's median geometry."""

    wide: ScaleOffset
    tele: ScaleOffset
    offsets: bool = False

    def _camera(self, cam: Camera, t: ScaleOffset) -> Camera:
        # q_i = (q_med − c − o)/s + c  ⇒  f_i = f/s, c_i = c − o/s (c = the principal point).
        if not t.ok:
            return cam
        s = float(t.scale)
        out = cam.scaled(1.0 / s)
        if self.offsets:
            out = out.shifted(-float(t.offset_px[0]) / s, -float(t.offset_px[1]) / s)
        return out

    def apply(self, rig: Rig) -> Rig:
        """The calibration of this attempt (cameras scaled by the inverse correction).

        Offsets are applied only when ``offsets`` is set (a tripod stack): handheld, the
        offset between attempts is mostly the hand's rotation — three times larger in the tele
        than in the wide — and "correcting" it would rotate the rig (a 10 px tele shift is a
        ~3 px disparity error). The scale is the focus effect.
        """
        return Rig(self._camera(rig.wide, self.wide), self._camera(rig.tele, self.tele),
                   rig.T_tele_wide)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"wide": self.wide.to_dict(), "tele": self.tele.to_dict()}


def _gray8(img: Any) -> Any:
    a = np.asarray(img)
    if a.ndim == 3:
        a = cv2.cvtColor(a[..., :3].astype(np.uint8), cv2.COLOR_BGR2GRAY)
    return np.ascontiguousarray(a, dtype=np.uint8)


def track_scale_offsets(
    images: Sequence[Any], center_px: Any, *, mask_box: tuple[int, int, int, int] | None = None
) -> list[ScaleOffset]:
    """Scale/offset of every attempt against the first, same camera (§3.5.3).

    Parameters
    ----------
    images : sequence of ndarray
        The attempts' images of one camera, first = reference.
    center_px : (2,)
        The camera's principal point.
    mask_box : (x, y, w, h), optional
        Where to pick features (default the whole image).
    """
    ref = _gray8(images[0])
    mask = None
    if mask_box is not None:
        x, y, w, h = mask_box
        mask = np.zeros_like(ref)
        mask[max(y, 0) : y + h, max(x, 0) : x + w] = 255
    p0 = cv2.goodFeaturesToTrack(ref, MAX_FEATURES, 0.01, 8, mask=mask, blockSize=7)
    c = np.asarray(center_px, dtype=np.float64)
    fits = [ScaleOffset.identity(c)]
    for img in images[1:]:
        if p0 is None or len(p0) < 6:
            fits.append(fit_scale_offset(np.zeros((0, 2)), np.zeros((0, 2)), c))
            continue
        cur = _gray8(img)
        lk = {
            "winSize": (21, 21),
            "maxLevel": 3,
            "criteria": (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.003),
        }
        p1, st, _ = cv2.calcOpticalFlowPyrLK(ref, cur, p0, None, **lk)  # type: ignore[call-overload]
        back, st2, _ = cv2.calcOpticalFlowPyrLK(cur, ref, p1, None, **lk)  # type: ignore[call-overload]
        ok = (st.ravel() == 1) & (st2.ravel() == 1)
        ok &= np.linalg.norm((back - p0).reshape(-1, 2), axis=1) < 0.1  # forward-backward check
        a, b = p0.reshape(-1, 2)[ok].astype(np.float64), p1.reshape(-1, 2)[ok].astype(np.float64)
        fits.append(fit_scale_offset(a, b, c))
    return fits


def focus_calibration(
    rig: Rig,
    wide_images: Sequence[Any],
    tele_images: Sequence[Any],
    *,
    wide_box: tuple[int, int, int, int] | None = None,
) -> list[FocusCorrection]:
    """Fig. 4-1: the per-attempt corrections of a refocus stack (both cameras).

    Parameters
    ----------
    rig : Rig
        The calibration (its principal points are the scale centres).
    wide_images, tele_images : sequence of ndarray
        The stack's images, attempt order.
    wide_box : (x, y, w, h), optional
        Where to track in the wide (e.g. around the ROI; the tele tracks its whole view).
    """
    fw = track_scale_offsets(wide_images, (rig.wide.cx, rig.wide.cy), mask_box=wide_box)
    ft = track_scale_offsets(tele_images, (rig.tele.cx, rig.tele.cy))
    cw, ct = normalise_to_median(fw), normalise_to_median(ft)
    return [FocusCorrection(w, t) for w, t in zip(cw, ct, strict=True)]


__all__ = ["FocusCorrection", "focus_calibration", "track_scale_offsets"]
