"""Facial landmarks behind one small backend interface (thesis §1.2.3, docs/architecture.md).

- :mod:`~phonestereo.features.landmarks.base`: :class:`Face`, :class:`FaceResult`, the
  :class:`LandmarkBackend` interface;
- :mod:`~phonestereo.features.landmarks.mediapipe_backend`: MediaPipe Face Mesh with iris
  landmarks, tiled so small faces in large images are found (the default);
- :mod:`~phonestereo.features.landmarks.openface`: OpenFace 2.0 CSV import (the thesis's tool);
- :mod:`~phonestereo.features.landmarks.eyes`: pupils and the thesis's eye centres;
- :mod:`~phonestereo.features.landmarks.pose`: head yaw, to undo the foreshortened IPD (eq. 11);
- :mod:`~phonestereo.features.landmarks.overlay`: drawing faces on an image.

Typical use::

    from phonestereo.features.landmarks import MediaPipeBackend

    result = MediaPipeBackend().detect("portrait.jpg")
    for face in result:
        print(face.pupils_px, face.ipd_px, face.yaw_rad)
"""

from __future__ import annotations

from phonestereo.features.landmarks.base import (
    Face,
    FaceResult,
    LandmarkBackend,
    Rejected,
    as_rgb,
    read_color,
)
from phonestereo.features.landmarks.mediapipe_backend import MediaPipeBackend
from phonestereo.features.landmarks.openface import OpenFaceCsvBackend, read_openface_csv

__all__ = [
    "Face",
    "FaceResult",
    "LandmarkBackend",
    "MediaPipeBackend",
    "OpenFaceCsvBackend",
    "Rejected",
    "as_rgb",
    "read_color",
    "read_openface_csv",
]
