"""Pupils and eye centres from facial landmarks (thesis §1.2.3, §3.6).

Two definitions of "where an eye is":

- the **pupil**: the iris centre (MediaPipe Face Mesh with ``refine_landmarks=True`` gives it
  as landmarks 468 and 473; OpenFace 2.0 as the mean of its 8 iris landmarks per eye);
- the thesis's **eye centre**: the centre of mass of the eye's contour landmarks. The thesis
  used OpenFace's 68-point model, whose eye contours have 6 points (iBUG 36–41 and 42–47);
  for MediaPipe the same six points are used (outer corner, two upper lid, inner corner, two
  lower lid), so both backends measure the same thing.

Eye 0 is always the one on the image left (the subject's right eye on a frontal face).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from phonestereo.errors import ShapeError
from phonestereo.features.landmarks.base import F64

#: MediaPipe iris-centre landmarks (subject's right eye, left eye); needs refine_landmarks.
MP_IRIS_CENTRE = (468, 473)
#: MediaPipe points equivalent to the 68-point model's eye contours (iBUG 36–41, 42–47).
MP_EYE_CONTOUR = ((33, 160, 158, 133, 153, 144), (362, 385, 387, 263, 373, 380))
#: The 68-point (iBUG / OpenFace) eye contours.
IBUG_EYE_CONTOUR = (tuple(range(36, 42)), tuple(range(42, 48)))
#: OpenFace 2.0 eye-region landmarks (28 per eye): the 8 iris points of each eye.
OPENFACE_IRIS = (tuple(range(0, 8)), tuple(range(28, 36)))


def _points(landmarks: Any) -> F64:
    pts = np.asarray(landmarks, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] not in (2, 3):
        raise ShapeError(f"landmarks must have shape (K, 2) or (K, 3), got {pts.shape}")
    return pts[:, :2]


def group_centres(landmarks: Any, groups: Any) -> F64:
    """Mean of each index group of ``landmarks`` (K, 2|3) → (len(groups), 2), pixels.

    >>> lm = [[0, 0], [2, 0], [10, 0], [12, 2]]
    >>> group_centres(lm, ((0, 1), (2, 3))).tolist()
    [[1.0, 0.0], [11.0, 1.0]]
    """
    pts = _points(landmarks)
    k = len(pts)
    out = []
    for g in groups:
        idx = np.asarray(g, dtype=np.intp)
        if idx.size == 0 or idx.min() < 0 or idx.max() >= k:
            raise ShapeError(f"landmark group {tuple(g)} is out of range for {k} landmarks")
        out.append(pts[idx].mean(axis=0))
    return np.array(out, dtype=np.float64)


def image_left_first(pupils_px: Any, *others: Any) -> tuple[F64, ...]:
    """Reorder eye pairs so that row 0 is the pupil with the smaller x.

    Parameters
    ----------
    pupils_px : array_like, shape (2, 2)
    *others : array_like, shape (2, ...)
        Per-eye arrays in the same eye order as ``pupils_px``; reordered alike.

    >>> p, c = image_left_first([[50.0, 10.0], [20.0, 11.0]], [[49.0, 10.0], [21.0, 11.0]])
    >>> p[0].tolist(), c[0].tolist()
    ([20.0, 11.0], [21.0, 11.0])
    """
    p = np.asarray(pupils_px, dtype=np.float64)
    if p.shape != (2, 2):
        raise ShapeError(f"pupils_px must have shape (2, 2), got {p.shape}")
    order = [0, 1] if p[0, 0] <= p[1, 0] else [1, 0]
    return (p[order], *(np.asarray(o, dtype=np.float64)[order] for o in others))


def mediapipe_eyes(landmarks: Any) -> tuple[F64, F64]:
    """Pupils (iris centres) and eye-contour centres of a 478-point MediaPipe mesh.

    Parameters
    ----------
    landmarks : array_like, shape (478, 2) or (478, 3)
        Face Mesh landmarks with the 10 iris points (``refine_landmarks=True``), pixels.

    Returns
    -------
    pupils_px, eye_centres_px : ndarray, shape (2, 2)
        Image-left eye first.
    """
    pts = _points(landmarks)
    if len(pts) < 478:
        raise ShapeError(
            f"MediaPipe landmarks need the iris points (478), got {len(pts)}; "
            "run Face Mesh with refine_landmarks=True"
        )
    pupils = pts[list(MP_IRIS_CENTRE)]
    centres = group_centres(pts, MP_EYE_CONTOUR)
    p, c = image_left_first(pupils, centres)
    return p, c


def ibug68_eyes(landmarks: Any, eye_landmarks: Any = None) -> tuple[F64, F64, str]:
    """Pupils and eye centres from the 68-point model (OpenFace), image-left eye first.

    Parameters
    ----------
    landmarks : array_like, shape (68, 2)
        The 68 face landmarks, pixels.
    eye_landmarks : array_like, shape (56, 2), optional
        OpenFace 2.0's eye-region landmarks; their iris points give the pupils. Without them
        the pupils are the eye-contour centres.

    Returns
    -------
    pupils_px, eye_centres_px : ndarray, shape (2, 2)
    pupil_source : str
        ``"iris"`` or ``"eye-contour"``.

    >>> lm = np.zeros((68, 2)); lm[36:42] = [100.0, 50.0]; lm[42:48] = [40.0, 50.0]
    >>> p, c, src = ibug68_eyes(lm)
    >>> p.tolist(), src
    ([[40.0, 50.0], [100.0, 50.0]], 'eye-contour')
    """
    pts = _points(landmarks)
    if len(pts) != 68:
        raise ShapeError(f"the 68-point model needs 68 landmarks, got {len(pts)}")
    centres = group_centres(pts, IBUG_EYE_CONTOUR)
    if eye_landmarks is None:
        p, c = image_left_first(centres, centres)
        return p, c, "eye-contour"
    eye = _points(eye_landmarks)
    if len(eye) != 56:
        raise ShapeError(f"OpenFace eye landmarks must be 56 points, got {len(eye)}")
    pupils = group_centres(eye, OPENFACE_IRIS)
    # OpenFace's eye order need not match the 68-point order: pair each pupil to its contour.
    if np.linalg.norm(pupils[0] - centres[0]) > np.linalg.norm(pupils[0] - centres[1]):
        pupils = pupils[::-1]
    p, c = image_left_first(pupils, centres)
    return p, c, "iris"
