"""Head yaw from facial landmarks, to undo the foreshortening of the pixel IPD (eq. 11).

The eye-to-eye direction of a face is its x axis. With 3-D landmarks (MediaPipe gives x, y
in pixels and a depth z on the same scale) the x axis is the mean direction of the vectors
joining left/right-symmetric landmarks (eye corners, cheeks, jaw, mouth corners, brows). If
that unit axis is ``a`` in the camera frame (x right, y down, z forward),

    yaw = atan2(a_z, hypot(a_x, a_y)),

with ``a`` oriented from the image-left eye (eye 0) to the image-right eye (eye 1), so the yaw
is positive when eye 1 is farther from the camera — for any roll of the head, even upside
down. A head rolled in the image plane keeps its yaw. A segment along the face's x axis of
length L projects (weak perspective) to L·cos(yaw), hence ``ipd_px_frontal = ipd_px /
cos(yaw)`` (thesis §1.2.3: "fix the face orientation so that all landmarks will be parallel to
the camera").

OpenFace reports the head rotation as Euler angles with R = Rx · Ry · Rz (its ``pose_Rx``,
``pose_Ry``, ``pose_Rz``); the face's x axis is then R's first column and the same formula
applies (:func:`yaw_from_euler`).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from phonestereo.errors import ShapeError
from phonestereo.features.landmarks.base import F64

#: Left/right-symmetric MediaPipe landmarks (subject's right member first): outer and inner
#: eye corners, cheeks, temples, jaw, mouth corners, brows.
MP_SYMMETRIC_PAIRS = (
    (33, 263),
    (133, 362),
    (234, 454),
    (127, 356),
    (93, 323),
    (132, 361),
    (58, 288),
    (172, 397),
    (61, 291),
    (70, 300),
    (105, 334),
)
#: Yaw beyond which a face is a profile: the hidden eye is guessed, and 1/cos(yaw) amplifies
#: yaw errors (at 40°, a 3° yaw error is 2.6 % of IPD).
MAX_YAW_RAD = float(np.deg2rad(40.0))


def face_axis(points: Any, pairs: Any = MP_SYMMETRIC_PAIRS) -> F64:
    """Unit x axis (3,) of a face from 3-D landmarks: mean of the symmetric-pair directions.

    Parameters
    ----------
    points : array_like, shape (K, 3)
        Landmarks (x, y, z) on one scale (pixels), z away from the camera.
    pairs : sequence of (int, int)
        Indices (subject's right, subject's left) of symmetric landmarks.

    Returns
    -------
    ndarray, shape (3,)
        Unit vector pointing from the subject's right side to its left (image right when
        frontal).
    """
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ShapeError(f"3-D landmarks must have shape (K, 3), got {p.shape}")
    idx = np.asarray(pairs, dtype=np.intp).reshape(-1, 2)
    if idx.size == 0 or idx.max() >= len(p) or idx.min() < 0:
        raise ShapeError(f"symmetric pairs index {len(p)} landmarks out of range")
    d = p[idx[:, 1]] - p[idx[:, 0]]
    n = np.linalg.norm(d, axis=1, keepdims=True)
    ok = n[:, 0] > 0
    if not ok.any():
        raise ShapeError("all symmetric landmark pairs coincide; the landmarks are degenerate")
    a = (d[ok] / n[ok]).mean(axis=0)
    return np.asarray(a / np.linalg.norm(a))


def yaw_from_axis(axis: Any, toward: Any = None) -> float:
    """Yaw (rad) of a face whose x axis is ``axis`` (3,) in the camera frame.

    Parameters
    ----------
    axis : array_like, shape (3,)
    toward : array_like, shape (2,), optional
        Image direction from eye 0 to eye 1 (pupil 1 − pupil 0); the axis is first turned to
        point that way, so the sign refers to the image order of the eyes.

    >>> round(np.degrees(yaw_from_axis([np.cos(0.3), 0.0, np.sin(0.3)])), 3)   # 0.3 rad
    17.189
    >>> round(np.degrees(yaw_from_axis([np.cos(0.3), 0.0, np.sin(0.3)], [-1, 0])), 3)
    -17.189
    >>> yaw_from_axis([0.0, 1.0, 0.0])                                         # rolled 90°
    0.0
    """
    a = np.asarray(axis, dtype=np.float64)
    if a.shape != (3,):
        raise ShapeError(f"axis must have shape (3,), got {a.shape}")
    if toward is not None and float(np.dot(a[:2], np.asarray(toward, dtype=np.float64))) < 0:
        a = -a
    return float(np.arctan2(a[2], np.hypot(a[0], a[1])))


def yaw_from_landmarks(points: Any, pairs: Any = MP_SYMMETRIC_PAIRS, toward: Any = None) -> float:
    """Yaw (rad) from 3-D landmarks (K, 3): :func:`face_axis` then :func:`yaw_from_axis`.

    A synthetic face turned by 20° about the vertical axis:

    >>> rng = np.random.default_rng(0)
    >>> half = rng.uniform(10, 60, (6, 3)) * [1, 1, 0.3]                 # subject's left half
    >>> face = np.vstack([half * [-1, 1, 1], half])                       # mirrored right half
    >>> R = Rotation.from_euler("y", -20, degrees=True).as_matrix()       # far side: image right
    >>> pairs = [(i, i + 6) for i in range(6)]
    >>> round(np.degrees(yaw_from_landmarks(face @ R.T, pairs)), 6)
    20.0
    """
    return yaw_from_axis(face_axis(points, pairs), toward)


def yaw_from_euler(rx: float, ry: float, rz: float, toward: Any = None) -> float:
    """Yaw (rad) from OpenFace's head rotation (radians, R = Rx · Ry · Rz).

    The face's x axis is R's first column; for a pure ``ry`` the yaw is ``-ry``. ``toward``
    as in :func:`yaw_from_axis`.

    >>> round(yaw_from_euler(0.0, 0.25, 0.0), 6), round(yaw_from_euler(0.0, 0.0, 0.5), 6)
    (-0.25, 0.0)
    """
    R = Rotation.from_euler("XYZ", [rx, ry, rz]).as_matrix()
    return yaw_from_axis(R[:, 0], toward)
