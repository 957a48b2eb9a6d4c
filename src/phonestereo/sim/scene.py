"""Scenes of the virtual module: posed planar objects, a background and optional lighting.

A :class:`PlanarObject` is a chart (anything with ``size_m`` and ``intensity(uv)``, the
renderer's part of the ``charts.base.Chart`` protocol) placed in an arbitrary world frame by
``T_world_chart``. The chart frame has its origin at the chart's top-left corner, u to the
right, v down, the chart in the plane z = 0 and +z pointing away from the viewer (into the
chart), so a chart that faces a camera has its normal along the camera's +z. Charts are
one-sided: seen from behind they are not rendered (their back is not printed).

The world frame is the caller's choice; each camera is placed by the ``T_cam_world`` passed to
:func:`phonestereo.sim.render.render_view`.

Ray casting: :func:`view_planes` poses the scene in one camera (per visible object the
homography from a normalised ray to chart uv, and a pixel box that bounds it), and
:func:`cast_rays` gives the radiance, object and depth that a batch of rays sees — the nearest
object with a finite chart intensity wins (occlusion); :func:`cast_grid` does it for a whole ray
field, each object only inside its pixel box.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np
from numpy.typing import NDArray
from scipy.spatial.transform import Rotation

from phonestereo.errors import InputError, PhysicsError
from phonestereo.geometry import Camera, Transform

__all__ = [
    "Lighting",
    "PlanarObject",
    "Scene",
    "SceneChart",
    "ViewPlane",
    "cast_grid",
    "cast_rays",
    "facing_pose",
    "view_planes",
]

F64 = NDArray[np.float64]


@runtime_checkable
class SceneChart(Protocol):
    """What the renderer needs of a chart (a subset of ``charts.base.Chart``)."""

    @property
    def size_m(self) -> tuple[float, float]:
        """(width, height) of the chart, metres."""
        ...

    def intensity(self, uv: NDArray[np.float64]) -> NDArray[np.float64]:
        """Reflectance (N,) in [0, 1] at chart points uv (N, 2) metres; NaN outside the chart."""
        ...


@dataclass(frozen=True)
class PlanarObject:
    """A chart posed in the world."""

    #: The chart (verification chart, face chart, textured plane, ...).
    chart: SceneChart
    #: Pose of the chart frame in the world frame (maps chart points into the world).
    T_world_chart: Transform
    #: Label of the object (used in ground truth and ``object_index`` bookkeeping).
    name: str = "object"

    def __post_init__(self) -> None:
        if not isinstance(self.chart, SceneChart):
            raise InputError(
                f"PlanarObject '{self.name}': chart must have size_m and intensity(uv), got "
                f"{type(self.chart).__name__}"
            )
        if not isinstance(self.T_world_chart, Transform):
            raise InputError(
                f"PlanarObject '{self.name}': T_world_chart must be a geometry.Transform, got "
                f"{type(self.T_world_chart).__name__}"
            )
        w, h = (float(v) for v in self.chart.size_m)
        if not (np.isfinite(w) and np.isfinite(h) and w > 0 and h > 0):
            raise PhysicsError(f"PlanarObject '{self.name}': chart size_m must be > 0, got {w, h}")

    def corners_world(self) -> NDArray[np.float64]:
        """The chart's four corners (TL, TR, BR, BL) in the world frame, shape (4, 3), metres."""
        w, h = (float(v) for v in self.chart.size_m)
        uv = np.array([[0, 0, 0], [w, 0, 0], [w, h, 0], [0, h, 0]], dtype=np.float64)
        return self.T_world_chart.apply(uv)


@dataclass(frozen=True)
class Lighting:
    """Smooth multiplicative illumination over the image (uneven-lighting robustness tests).

    With image coordinates normalised to x̂, ŷ ∈ [−1, 1] (centre 0, edges ±1) and
    r² = (x̂² + ŷ²) / 2 (1 at the corners), the radiance is multiplied by::

        gain · (1 + gradient_x·x̂ + gradient_y·ŷ) · (1 − vignetting·r²)

    Examples
    --------
    >>> Lighting(vignetting=0.3).field((3, 3)).astype(float).round(3).tolist()[0]   # top row
    [0.7, 0.85, 0.7]
    """

    #: Overall illumination factor (> 0; values above 1 can saturate the sensor).
    gain: float = 1.0
    #: Relative illumination change from the centre to the right and bottom edges; ``|gx| + |gy| <
    #: 1`` keeps the light positive.
    gradient: tuple[float, float] = (0.0, 0.0)
    #: Relative fall-off at the image corners, 0 ≤ v < 1.
    vignetting: float = 0.0

    def __post_init__(self) -> None:
        gx, gy = (float(v) for v in self.gradient)
        g, v = float(self.gain), float(self.vignetting)
        if not np.isfinite(g) or g <= 0:
            raise PhysicsError(f"lighting gain must be > 0, got {g}")
        if not (np.isfinite(gx) and np.isfinite(gy)) or abs(gx) + abs(gy) >= 1:
            raise PhysicsError(
                f"lighting gradient {gx, gy} would make the light negative: keep |gx| + |gy| < 1"
            )
        if not np.isfinite(v) or not 0 <= v < 1:
            raise PhysicsError(f"lighting vignetting must be in [0, 1), got {v}")
        object.__setattr__(self, "gain", g)
        object.__setattr__(self, "gradient", (gx, gy))
        object.__setattr__(self, "vignetting", v)

    def field(self, size: tuple[int, int]) -> NDArray[np.float32]:
        """Illumination factor per pixel of a ``size = (width, height)`` image, (H, W) float32."""
        w, h = (int(s) for s in size)
        x = (np.arange(w, dtype=np.float32) - (w - 1) / 2) / max((w - 1) / 2, 1)
        y = (np.arange(h, dtype=np.float32) - (h - 1) / 2) / max((h - 1) / 2, 1)
        gx, gy = self.gradient
        lin = 1 + gx * x[None, :] + gy * y[:, None]
        vig = 1 - self.vignetting * 0.5 * (x[None, :] ** 2 + y[:, None] ** 2)
        return np.asarray(self.gain * lin * vig, dtype=np.float32)


@dataclass(frozen=True)
class Scene:
    """Planar objects in front of a uniform background, with optional lighting."""

    #: tuple of PlanarObject. The objects; the nearest one wins per image sample (occlusion).
    objects: tuple[PlanarObject, ...]
    #: Radiance of everything that is not an object, in [0, 1].
    background: float = 0.5
    #: Multiplicative illumination over the image; None = uniform.
    lighting: Lighting | None = None

    def __post_init__(self) -> None:
        objs = tuple(self.objects)
        for o in objs:
            if not isinstance(o, PlanarObject):
                raise InputError(f"Scene objects must be PlanarObject, got {type(o).__name__}")
        b = float(self.background)
        if not np.isfinite(b) or not 0 <= b <= 1:
            raise InputError(f"Scene background must be a radiance in [0, 1], got {b}")
        if self.lighting is not None and not isinstance(self.lighting, Lighting):
            raise InputError(f"Scene lighting must be a Lighting or None, got {self.lighting!r}")
        object.__setattr__(self, "objects", objs)
        object.__setattr__(self, "background", b)


def facing_pose(
    size_m: Any,
    distance_m: float,
    *,
    tilt_rad: Any = (0.0, 0.0, 0.0),
    center_m: Any = (0.0, 0.0),
) -> Transform:
    """Pose ``T_cam_chart`` of a chart whose centre is ``distance_m`` in front of a camera.

    The chart faces the camera (its +z along the camera's +z, u along x, v along y), is rotated
    by ``tilt_rad`` (rotation vector about its own centre, radians: (about x, about y, about z))
    and its centre is at (center_m[0], center_m[1], distance_m) in the camera frame.

    Examples
    --------
    >>> T = facing_pose((0.4, 0.3), 2.0)
    >>> T.apply([[0.2, 0.15, 0.0]]).tolist()          # chart centre on the optical axis
    [[0.0, 0.0, 2.0]]
    """
    w, h = (float(v) for v in np.ravel(size_m))
    d = float(distance_m)
    if not np.isfinite(d) or d <= 0:
        raise PhysicsError(f"distance_m must be > 0, got {d}")
    R = Rotation.from_rotvec(np.asarray(tilt_rad, dtype=np.float64)).as_matrix()
    cx, cy = (float(v) for v in np.ravel(center_m))
    center = np.array([cx, cy, d])
    return Transform(R, center - R @ np.array([w / 2, h / 2, 0.0]))


@dataclass(frozen=True, eq=False)
class ViewPlane:
    """One object of a scene as seen by one camera."""

    #: Index of the object in ``scene.objects``.
    index: int
    #: Its chart.
    chart: SceneChart
    #: ndarray, shape (3, 3). Maps a normalised ray (x, y, 1) to (u, v, 1) / Z: chart uv (metres)
    #: and camera depth Z.
    Minv: F64
    #: Pixel box (x0, y0, x1, y1), ends exclusive, outside which the object is not seen.
    box: tuple[int, int, int, int]


def view_planes(
    camera: Camera, T_cam_world: Transform, scene: Scene, rays: tuple[F64, F64]
) -> list[ViewPlane]:
    """The objects a camera can see, with their ray → chart homographies and pixel boxes.

    A chart seen edge-on or from behind (camera on its +z side) is skipped: its back is not
    printed. ``rays`` is the camera's ray field at pixel centres or corners
    (:func:`phonestereo.sim.optics.ray_field`), used to find the box: nodes every 8 px whose ray
    hits the chart, plus the chart outline projected into the image, grown by 10 px.
    """
    w, h = camera.size
    off = -0.5 if rays[0].shape == (h + 1, w + 1) else 0.0
    sx, sy = rays[0][::8, ::8], rays[1][::8, ::8]
    gy, gx = (g + off for g in np.mgrid[0 : rays[0].shape[0] : 8, 0 : rays[0].shape[1] : 8])
    lo, hi = float(np.nanmin([sx.min(), sy.min()])), float(np.nanmax([sx.max(), sy.max()]))
    out = []
    for i, obj in enumerate(scene.objects):
        T = T_cam_world @ obj.T_world_chart
        R, t = T.R, T.t
        if float(R[:, 2] @ t) <= 1e-12:
            continue
        Minv = np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], t]))
        cw, ch = (float(v) for v in obj.chart.size_m)
        corners = T.apply(np.array([[0, 0, 0], [cw, 0, 0], [cw, ch, 0], [0, ch, 0]], float))
        if np.any(corners[:, 2] <= 1e-9):
            out.append(ViewPlane(i, obj.chart, Minv, (0, 0, w, h)))
            continue
        quad = corners[:, :2] / corners[:, 2:]
        e = np.roll(quad, -1, axis=0) - quad
        cross = e[:, 0, None, None] * (sy[None] - quad[:, 1, None, None]) - e[:, 1, None, None] * (
            sx[None] - quad[:, 0, None, None]
        )
        inside = np.all(cross >= 0, axis=0) | np.all(cross <= 0, axis=0)
        s = np.linspace(0.0, 1.0, 65)[:-1, None]
        edge = (quad[:, None, :] + s[None] * e[:, None, :]).reshape(-1, 2)
        edge = edge[np.all((edge >= lo - 0.05) & (edge <= hi + 0.05), axis=1)]
        q = camera.normalized_to_pixel(camera.lens.distort(edge))
        q = q[camera.contains(q)]
        xs = np.concatenate([gx[inside], q[:, 0]])
        ys = np.concatenate([gy[inside], q[:, 1]])
        if len(xs) == 0:
            continue
        m = 10
        box = (
            max(int(np.floor(xs.min())) - m, 0),
            max(int(np.floor(ys.min())) - m, 0),
            min(int(np.ceil(xs.max())) + m + 1, w),
            min(int(np.ceil(ys.max())) + m + 1, h),
        )
        out.append(ViewPlane(i, obj.chart, Minv, box))
    return out


def cast_rays(
    planes: list[ViewPlane], x: F64, y: F64, background: float
) -> tuple[F64, NDArray[np.int16], F64]:
    """What rays (x, y, 1) see: the nearest object with a finite chart intensity.

    Parameters
    ----------
    planes : list of ViewPlane
        From :func:`view_planes`.
    x, y : ndarray, shape (N,)
        Undistorted normalised ray coordinates (NaN rays see the background).
    background : float
        Radiance where no object is hit.

    Returns
    -------
    value : ndarray, shape (N,)
        Radiance (chart reflectance, or ``background``).
    index : ndarray, shape (N,), int16
        Object index; −1 for the background.
    depth : ndarray, shape (N,)
        Camera-frame Z of the hit, metres; inf for the background.
    """
    n = len(x)
    value = np.full(n, background, dtype=np.float64)
    index = np.full(n, -1, dtype=np.int16)
    depth = np.full(n, np.inf, dtype=np.float64)
    for a in range(0, n, _BLOCK):  # cache-sized blocks: every temporary stays in the CPU cache
        b = slice(a, a + _BLOCK)
        _cast_block(planes, x[b], y[b], value[b], index[b], depth[b])
    return value, index, depth


_BLOCK = 1 << 15


def _cast_block(
    planes: list[ViewPlane], x: F64, y: F64, value: F64, index: NDArray[np.int16], depth: F64
) -> None:
    uv = np.empty((len(x), 2))
    for p in planes:
        m = p.Minv
        g2 = m[2, 0] * x + m[2, 1] * y + m[2, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            z = 1.0 / g2
            np.multiply(m[0, 0] * x + m[0, 1] * y + m[0, 2], z, out=uv[:, 0])
            np.multiply(m[1, 0] * x + m[1, 1] * y + m[1, 2], z, out=uv[:, 1])
            front = g2 > 0
            if not front.all():
                uv[~front] = -1.0  # behind the camera or NaN ray: a point off every chart
            val = np.asarray(p.chart.intensity(uv), dtype=np.float64)
            hit = front & (z < depth) & np.isfinite(val)
        value[hit], index[hit], depth[hit] = val[hit], p.index, z[hit]


def cast_grid(
    planes: list[ViewPlane], rays: tuple[F64, F64], background: float
) -> tuple[F64, NDArray[np.int16], F64]:
    """:func:`cast_rays` over a ray field (R, C) at pixel centres or corners, per object box.

    Returns value, index and depth, each shape (R, C). Corner fields are one larger than the
    image, and a box's last corner row/column is its end (x1, y1).
    """
    shape = rays[0].shape
    value = np.full(shape, background, dtype=np.float64)
    index = np.full(shape, -1, dtype=np.int16)
    depth = np.full(shape, np.inf, dtype=np.float64)
    for p in planes:
        x0, y0, x1, y1 = p.box
        sl = (slice(y0, y1 + 1), slice(x0, x1 + 1))
        v, i, d = cast_rays([p], rays[0][sl].ravel(), rays[1][sl].ravel(), background)
        sub = rays[0][sl].shape
        v, i, d = v.reshape(sub), i.reshape(sub), d.reshape(sub)
        near = d < depth[sl]
        value[sl][near], index[sl][near], depth[sl][near] = v[near], i[near], d[near]
    return value, index, depth
