"""Which wide face is which tele face, and how far each is: steps 2–3 of landmark disparity.

- :func:`ipd_depths`: the depth of each wide face from its IPD (eq. 11:
  :func:`~phonestereo.learning.ipd.fit_face_plane` for a printed chart,
  :func:`~phonestereo.learning.ipd.face_depth` for real heads) and the disparity it predicts,
  ``d_expected = f·B/Z`` (eq. 4, Z along the rectified axis);
- :func:`match_faces`: the one-to-one wide ↔ tele assignment by landmark disparity, gated on
  the non-disparity error and on ``d_expected``.

Used by :func:`phonestereo.learning.landmark_disparity.landmark_disparity` (which re-exports
both).
"""

from __future__ import annotations

from typing import Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import linear_sum_assignment

from phonestereo.errors import InputError
from phonestereo.features.landmarks.base import FaceResult
from phonestereo.learning.chart_pitch import grid_scale
from phonestereo.learning.ipd import IPD_M, face_depth, fit_face_plane
from phonestereo.rectification import Rectification

F64 = NDArray[np.float64]
DepthMode = Literal["chart", "face"]


def pupils_px(res: FaceResult) -> F64:
    """Raw-image pupils of every face, shape (N, 2, 2): face, (left, right), (x, y) pixels."""
    return np.array([f.pupils_px for f in res.faces], dtype=np.float64).reshape(-1, 2, 2)


def ipd_depths(
    faces: FaceResult,
    rect: Rectification,
    ipd_m: float = IPD_M,
    mode: DepthMode = "chart",
    pitch_m: float | None = None,
) -> tuple[F64, F64]:
    """IPD depth of each wide face along the rectified axis and its expected disparity.

    Parameters
    ----------
    faces : FaceResult
        Faces of the raw wide image.
    rect : Rectification
        The rectification (``canonical`` makes f·B/Z exact).
    ipd_m : float
        The IPD, metres.
    mode : {"chart", "face"}
        ``"chart"``: all faces on one printed plane (:func:`fit_face_plane`, the chart's tilt
        instead of the portraits' head yaw); ``"face"``: real heads, each with its own yaw
        (:func:`face_depth`).
    pitch_m : float, optional
        ``"chart"`` only: the chart's grid pitch; the plane's scale is then taken from the eye
        midpoints' grid (:func:`~phonestereo.learning.chart_pitch.grid_scale`), the IPDs give
        its tilt. None: the IPDs alone.

    Returns
    -------
    depth_m, d_expected_px : ndarray, shape (N,)
        Metres and pixels; NaN where the pupils leave the camera's valid field.
    """
    pupils = pupils_px(faces)
    if len(pupils) == 0:
        return np.zeros(0), np.zeros(0)
    cam = rect.rig.wide
    z = np.full(len(pupils), np.nan)
    if mode == "chart":
        try:
            fit = fit_face_plane(pupils, cam, ipd_m)
        except InputError:  # no pupil in the valid field: the per-face fallback says so (NaN)
            fit = None
        if fit is not None and not fit.reason:
            z = np.asarray(fit.depth_m, dtype=np.float64)
            if pitch_m is not None:
                z = z * grid_scale(z, pupils, cam, pitch_m)[0]
    elif mode != "face":
        raise InputError(f"depth mode must be 'chart' or 'face', got {mode!r}")
    bad = ~np.isfinite(z)
    if bad.any():  # real heads (or a failed plane fit): each face on its own
        yaw = np.array([f.yaw_rad if np.isfinite(f.yaw_rad) else 0.0 for f in faces.faces])
        refs = np.array([f.yaw_reference for f in faces.faces])
        for ref in ("sight", "image"):
            sel = bad & (refs == ref)
            if sel.any():
                z[sel] = face_depth(pupils[sel], cam, ipd_m, yaw[sel], relative_to=ref)
    mid = cam.unproject(pupils).mean(axis=1)  # (N, 3), z = 1: the pupil midpoint's ray
    p_rect = (mid * z[:, None]) @ np.asarray(rect.R_rect_wide).T
    z_rect = p_rect[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        d_exp = rect.f_px * rect.baseline_m / z_rect
    return z_rect, np.where(z_rect > 0, d_exp, np.nan)


def match_faces(
    d: F64,
    e: F64,
    d_expected: F64,
    *,
    max_e_px: float = 10.0,
    d_tol_px: float = 4.0,
    d_tol_rel: float = 0.35,
) -> list[tuple[int, int]]:
    """Assign wide faces to tele faces by landmark (d, e) (one-to-one, gated).

    Parameters
    ----------
    d, e : ndarray, shape (Nw, Nt)
        Landmark disparity and non-disparity error of every wide/tele pair, pixels.
    d_expected : ndarray, shape (Nw,)
        f·B/Z_IPD of each wide face, pixels.
    max_e_px, d_tol_px, d_tol_rel : float
        Gates: |e| ≤ max_e_px and |d − d_expected| ≤ d_tol_px + d_tol_rel · d_expected.

    Returns
    -------
    list of (wide_index, tele_index)

    Examples
    --------
    Two faces 300 px apart, both at 12 px of disparity; the tele faces listed in reverse:

    >>> d = np.array([[-288.0, 12.2], [11.8, 312.0]])
    >>> match_faces(d, np.zeros((2, 2)), np.array([12.0, 12.0]))
    [(0, 1), (1, 0)]
    """
    if d.size == 0:
        return []
    tol = d_tol_px + d_tol_rel * np.abs(d_expected)[:, None]
    cost = (e / max_e_px) ** 2 + ((d - d_expected[:, None]) / tol) ** 2
    ok = np.isfinite(cost) & (np.abs(e) <= max_e_px) & (np.abs(d - d_expected[:, None]) <= tol)
    big = 1e6
    rows, cols = linear_sum_assignment(np.where(ok, cost, big))
    return [(int(i), int(j)) for i, j in zip(rows, cols, strict=True) if ok[i, j]]
