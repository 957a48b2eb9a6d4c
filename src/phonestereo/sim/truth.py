"""True image positions and depths of scene keypoints and ROIs (computing the ground truth).

For every keypoint of every object (chessboard corners, circle centres, pupils) the true pixel
in each camera is the true camera's projection of the keypoint's world position, and it is
NaN where the point is not visible: behind the camera, outside the image, seen from behind
the chart, beyond the lens's one-to-one field, or hidden by a nearer object. Depth is the Z of
the point in the true wide frame at that capture (metres).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.geometry import Camera, Transform
from phonestereo.geometry.checks import Array
from phonestereo.sim.capture import ROLES, CaptureState, Role

#: Two pixels whose round trip through the lens differs by more than this are folded-over.
FOLD_TOL_NORMALISED = 1e-7


@dataclass(frozen=True, eq=False)
class KeypointTruth:
    """One keypoint set of one object at one capture."""

    #: ndarray (N, k) int.
    ids: NDArray[np.int64]
    #: ``wide_px``, ``tele_px``: ndarray (N, 2). True pixels, NaN where not visible.
    wide_px: Array
    #: See ``wide_px`` above.
    tele_px: Array
    #: ndarray (N,). True depth Z in the wide frame, metres.
    depth_m: Array


def _object_points_world(obj: Any, uv: Array) -> Array:
    pts = np.column_stack([uv, np.zeros(len(uv))])
    return np.asarray(obj.T_world_chart.apply(pts), dtype=np.float64)


def _blocked_by(obj: Any, origin_w: Array, points_w: Array) -> NDArray[np.bool_]:
    """True where the segment origin → point crosses ``obj`` (strictly before the point)."""
    T_chart_world = obj.T_world_chart.inverse()
    o = T_chart_world.apply(origin_w)
    p = T_chart_world.apply(points_w)
    dz = p[:, 2] - o[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = -o[2] / dz
    hit = o + lam[:, None] * (p - o)
    w, h = obj.chart.size_m
    inside = (hit[:, 0] >= 0) & (hit[:, 0] <= w) & (hit[:, 1] >= 0) & (hit[:, 1] <= h)
    return np.asarray(np.isfinite(lam) & (lam > 0) & (lam < 1 - 1e-9) & inside)


def visible_pixels(
    camera: Camera, T_cam_world: Transform, objects: tuple[Any, ...], index: int, uv: Array
) -> Array:
    """True pixels (N, 2) of chart points ``uv`` of ``objects[index]``; NaN where hidden."""
    obj = objects[index]
    pw = _object_points_world(obj, uv)
    pc = T_cam_world.apply(pw)
    q = camera.project(pc)
    ok = (pc[:, 2] > 0) & camera.contains(q)
    # Facing: the camera must be on the chart's −z side (charts print on their front only).
    cam_in_chart = (obj.T_world_chart.inverse() @ T_cam_world.inverse()).t
    ok &= bool(cam_in_chart[2] < 0)
    # Folded lens field: the pixel must undistort back to the same ray.
    with np.errstate(invalid="ignore", divide="ignore"):
        xy = pc[:, :2] / pc[:, 2:3]
        back = camera.pixel_to_normalized(np.where(ok[:, None], q, 0.0))
    ok &= np.all(np.abs(back - xy) < FOLD_TOL_NORMALISED * (1 + np.abs(xy)), axis=1)
    origin = T_cam_world.inverse().t
    for j, other in enumerate(objects):
        if j != index:
            ok &= ~_blocked_by(other, origin, pw)
    q = np.where(ok[:, None], q, np.nan)
    return np.asarray(q, dtype=np.float64)


def keypoint_truth(state: CaptureState, objects: tuple[Any, ...]) -> list[dict[str, Any]]:
    """Per object: name, chart name and its keypoint sets with true pixels and depths."""
    out = []
    T_wide_world = state.T_cam_world("wide")
    for i, obj in enumerate(objects):
        sets: dict[str, KeypointTruth] = {}
        keypoints = obj.chart.keypoints() if hasattr(obj.chart, "keypoints") else {}
        for key, kp in sorted(keypoints.items()):
            uv = np.asarray(kp.uv, dtype=np.float64)
            px = {
                role: visible_pixels(
                    state.camera(role).camera, state.T_cam_world(role), objects, i, uv
                )
                for role in ROLES
            }
            depth = T_wide_world.apply(_object_points_world(obj, uv))[:, 2]
            sets[key] = KeypointTruth(np.asarray(kp.ids), px["wide"], px["tele"], depth)
        out.append({"name": obj.name, "chart": getattr(obj.chart, "name", ""), "keypoints": sets})
    return out


def ray_depths(state: CaptureState, objects: tuple[Any, ...], pixels: Array, role: Role) -> Array:
    """Depth (camera Z, metres) of the nearest object along each pixel's ray; NaN if none."""
    camera = state.camera(role).camera
    rays = camera.unproject(pixels)
    T_world_cam = state.T_cam_world(role).inverse()
    best = np.full(len(rays), np.inf)
    for obj in objects:
        T_chart_cam = obj.T_world_chart.inverse() @ T_world_cam
        o = T_chart_cam.t
        d = rays @ T_chart_cam.R.T
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = -o[2] / d[:, 2]
        hit = o + lam[:, None] * d
        w, h = obj.chart.size_m
        ok = (lam > 0) & (hit[:, 0] >= 0) & (hit[:, 0] <= w) & (hit[:, 1] >= 0) & (hit[:, 1] <= h)
        best = np.where(ok & (lam < best), lam, best)
    return np.where(np.isfinite(best), best, np.nan)  # rays have Z = 1: λ is the depth


def roi_depth_m(
    state: CaptureState, objects: tuple[Any, ...], roi: tuple[int, int, int, int], n: int = 9
) -> float:
    """Median true depth (wide Z, metres) over an n × n grid of pixels in the ROI [x, y, w, h]."""
    x, y, w, h = roi
    gx, gy = np.meshgrid(np.linspace(x, x + w - 1, n), np.linspace(y, y + h - 1, n))
    z = ray_depths(state, objects, np.column_stack([gx.ravel(), gy.ravel()]), "wide")
    return float(np.nanmedian(z)) if np.any(np.isfinite(z)) else float("nan")
