"""Where a face the wide found is in the tele image (learning-phase speed-up, thesis §4.1.3).

The learning flow needs every face of the wide (a face chart's plane is fitted to all of
them, :func:`~phonestereo.learning.ipd.fit_face_plane`) and, in the tele, the same faces where
its narrower view sees them. Searching the tele again for faces costs as much as measuring
them; :class:`WideToTeleGuide` instead maps each wide face into the raw tele image through the
calibration — raw wide pixels → rectified wide → shifted by the disparity its IPD predicts
(eq. 11 with the nominal IPD, then eq. 4) → raw tele — so the tele is measured only there
(:meth:`~phonestereo.features.landmarks.base.LandmarkBackend.detect_pair`). The box only
places the landmark crop (2.2× the face): an error of tens of pixels from a wrong IPD or a
poor calibration is harmless.
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field

import numpy as np

from phonestereo.features.landmarks.base import BoxPx, Face
from phonestereo.rectification import Rectification


@dataclass(frozen=True)
class WideToTeleGuide:
    """A wide face → its raw-tele face box, through a rectification."""

    #: Of the calibration in use (any mode).
    rect: Rectification
    #: The IPD assumed for the depth of the face, metres.
    ipd_m: float = 0.063
    key: str = field(init=False, repr=False)

    def __post_init__(self) -> None:
        digest = hashlib.blake2b(
            json.dumps([self.rect.to_dict(), self.ipd_m], sort_keys=True, default=str).encode(),
            digest_size=12,
        ).hexdigest()
        object.__setattr__(self, "key", f"wide-to-tele:{digest}")

    def __call__(self, wide_face: Face) -> BoxPx | None:
        """The face's box in the raw tele image (x0, y0, x1, y1) px, or None when the face is
        not in the tele's view (or cannot be mapped).

        >>> from phonestereo.geometry import Camera, Rig, Transform
        >>> w = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
        >>> t = Camera((2000, 1500), 4500.0, 4500.0, 999.5, 749.5)
        >>> rig = Rig(w, t, Transform.from_rotvec([0, 0, 0], [-0.012, 0, 0]))
        >>> guide = WideToTeleGuide(Rectification.from_rig(rig, "canonical"))
        >>> # a frontal face at 1.5 m, 12 px of disparity right of the wide's centre: IPD 63 px
        >>> face = Face(np.array([[979.5, 749.5], [1042.5, 749.5]]), np.array([[979.5, 749.5],
        ...             [1042.5, 749.5]]), np.zeros((0, 2)), 0.0, 1.0,
        ...             np.array([945.0, 700.0, 1078.0, 833.0]))
        >>> [round(v) for v in guide(face)]     # three times larger, centred in the tele
        [800, 601, 1199, 1000]
        >>> face_far_left = Face(face.pupils_px - [900, 0], face.eye_centres_px - [900, 0],
        ...                      face.landmarks_px, 0.0, 1.0, face.box_px - [900, 0, 900, 0])
        >>> guide(face_far_left) is None        # outside the tele's view
        True
        """
        rect = self.rect
        p = rect.points_wide(wide_face.pupils_px)
        ipd_rect = float(np.linalg.norm(p[1] - p[0]))
        if not np.isfinite(ipd_rect) or ipd_rect < 1.0:
            return None
        # eq. 11 then eq. 4: Z = f·IPD / ipd_rect, d = f·B / Z = B·ipd_rect / IPD
        d = rect.baseline_m * ipd_rect / self.ipd_m
        x0, y0, x1, y1 = (float(v) for v in wide_face.box_px)
        q = rect.points_wide(np.array([[x0, y0], [x1, y0], [x0, y1], [x1, y1]]))
        q[:, 0] -= d  # x_tele = x_wide − d in the rectified frame
        raw = rect.unrectify_tele(q)
        if not np.isfinite(raw).all():
            return None
        lo, hi = raw.min(axis=0), raw.max(axis=0)
        w, h = rect.rig.tele.size
        if hi[0] < 0 or hi[1] < 0 or lo[0] > w - 1 or lo[1] > h - 1:
            return None
        return float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1])


__all__ = ["WideToTeleGuide"]
