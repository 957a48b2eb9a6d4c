"""The calibration bundle: residuals and their analytic sparse Jacobian (thesis §1.3.2).

One flat parameter vector holds, in order: the intrinsics of each camera ``[fx, fy, cx, cy,
lens coefficients…]``, then (stereo only) ``T_tele_wide`` as ``[rotvec, t]``, then one board pose
``T_cam0_board`` per view as ``[rotvec, t]``. Observation m of camera c in view v predicts::

    p = R_v X + t_v                       (board → wide/camera-0 frame)
    p = R_rel p + t_rel                   (camera 1 only: wide → tele, T_tele_wide)
    q = K · distort(p_xy / p_z)

Rotation derivatives use the SO(3) left Jacobian: d(R(ω)·y)/dω = −[R(ω)·y]ₓ · J_l(ω).
Hand-written because no library differentiates OpenCV-style lens models analytically with a
sparse layout; it is checked against finite differences in the tests.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.spatial.transform import Rotation

from phonestereo.geometry import Camera, LensModel, Transform
from phonestereo.geometry.epipolar import skew


def left_jacobian(rotvec: np.ndarray) -> np.ndarray:
    """SO(3) left Jacobian J_l(ω), shape (3, 3).

    Examples
    --------
    >>> bool(np.allclose(left_jacobian(np.zeros(3)), np.eye(3)))
    True
    """
    theta = float(np.linalg.norm(rotvec))
    w = skew(rotvec)
    if theta < 1e-8:
        return np.eye(3) + 0.5 * w
    return (
        np.eye(3)
        + (1 - np.cos(theta)) / theta**2 * w
        + (theta - np.sin(theta)) / theta**3 * (w @ w)
    )


@dataclass(frozen=True, eq=False)
class Observations:
    """All corners of a bundle, flattened: M points."""

    camera: np.ndarray  # (M,) int, 0 = wide/mono, 1 = tele
    view: np.ndarray  # (M,) int
    object_points: np.ndarray  # (M, 3) metres, board frame
    image_points: np.ndarray  # (M, 2) pixels
    ids: np.ndarray  # (M,) corner ids


@dataclass(frozen=True)
class Layout:
    """Where each block sits in the parameter vector."""

    lenses: tuple[LensModel, ...]  # model templates per camera
    sizes: tuple[tuple[int, int], ...]
    n_views: int
    stereo: bool

    @property
    def n_intrinsics(self) -> tuple[int, ...]:
        return tuple(4 + lens.n_coefficients for lens in self.lenses)

    def intrinsic_slice(self, cam: int) -> slice:
        start = sum(self.n_intrinsics[:cam])
        return slice(start, start + self.n_intrinsics[cam])

    @property
    def rel_start(self) -> int:
        return sum(self.n_intrinsics)

    @property
    def views_start(self) -> int:
        return self.rel_start + (6 if self.stereo else 0)

    @property
    def n_params(self) -> int:
        return self.views_start + 6 * self.n_views

    def parameter_names(self) -> tuple[str, ...]:
        names: list[str] = []
        for c, lens in enumerate(self.lenses):
            cam = ("wide" if self.stereo else "camera") if c == 0 else "tele"
            names += [f"{cam}.{k}" for k in ("fx", "fy", "cx", "cy")]
            names += [f"{cam}.{lens.name}[{i}]" for i in range(lens.n_coefficients)]
        if self.stereo:
            names += [f"T_tele_wide.{k}" for k in ("rx", "ry", "rz", "tx", "ty", "tz")]
        for v in range(self.n_views):
            names += [f"view{v}.{k}" for k in ("rx", "ry", "rz", "tx", "ty", "tz")]
        return tuple(names)

    # --- packing ---------------------------------------------------------------------------
    def pack(
        self, cameras: tuple[Camera, ...], rel: Transform | None, poses: tuple[Transform, ...]
    ) -> np.ndarray:
        x = np.zeros(self.n_params)
        for c, cam in enumerate(cameras):
            x[self.intrinsic_slice(c)] = [cam.fx, cam.fy, cam.cx, cam.cy, *cam.lens.coefficients]
        if self.stereo and rel is not None:
            x[self.rel_start : self.rel_start + 6] = [*rel.rotvec, *rel.t]
        for v, pose in enumerate(poses):
            s = self.views_start + 6 * v
            x[s : s + 6] = [*pose.rotvec, *pose.t]
        return x

    def camera(self, x: np.ndarray, cam: int) -> Camera:
        p = x[self.intrinsic_slice(cam)]
        lens = self.lenses[cam].with_coefficients(p[4:])
        return Camera(self.sizes[cam], p[0], p[1], p[2], p[3], lens)

    def rel(self, x: np.ndarray) -> Transform | None:
        if not self.stereo:
            return None
        s = self.rel_start
        return Transform.from_rotvec(x[s : s + 3], x[s + 3 : s + 6])

    def poses(self, x: np.ndarray) -> tuple[Transform, ...]:
        s = self.views_start
        return tuple(
            Transform.from_rotvec(x[s + 6 * v : s + 6 * v + 3], x[s + 6 * v + 3 : s + 6 * v + 6])
            for v in range(self.n_views)
        )


def _view_rotations(x: np.ndarray, layout: Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    block = x[layout.views_start :].reshape(layout.n_views, 6)
    rotvecs = block[:, :3]
    return Rotation.from_rotvec(rotvecs).as_matrix(), block[:, 3:], rotvecs


def residuals_and_jacobian(
    x: np.ndarray, layout: Layout, obs: Observations, *, with_jacobian: bool = True
) -> tuple[np.ndarray, sparse.csr_matrix | None]:
    """Reprojection residuals (predicted − observed), shape (2M,), and their sparse Jacobian.

    Rows are interleaved per point: (x₀, y₀, x₁, y₁, …).
    """
    m = obs.camera.shape[0]
    R_v, t_v, rotvecs = _view_rotations(x, layout)
    obj = obs.object_points
    ry = np.einsum("mij,mj->mi", R_v[obs.view], obj)  # R_v X
    p = ry + t_v[obs.view]
    is1 = obs.camera == 1
    if layout.stereo:
        s = layout.rel_start
        R_rel = Rotation.from_rotvec(x[s : s + 3]).as_matrix()
        p_w1 = p[is1]
        p[is1] = p_w1 @ R_rel.T + x[s + 3 : s + 6]
    res = np.empty((m, 2))
    blocks_rows: list[np.ndarray] = []
    blocks_cols: list[np.ndarray] = []
    blocks_vals: list[np.ndarray] = []
    rows2 = np.stack([2 * np.arange(m), 2 * np.arange(m) + 1], axis=1)  # (M, 2)

    def add(sel: np.ndarray, cols: np.ndarray, vals: np.ndarray) -> None:
        # vals: (k, 2, n) derivative of the two residuals of each selected point w.r.t. cols.
        k, _, n = vals.shape
        blocks_rows.append(np.repeat(rows2[sel], n, axis=1).reshape(-1))
        blocks_cols.append(np.broadcast_to(cols, (k, 2, n)).reshape(-1))
        blocks_vals.append(vals.reshape(-1))

    for c in range(len(layout.lenses)):
        sel = np.flatnonzero(obs.camera == c)
        if sel.size == 0:
            continue
        cam = layout.camera(x, c)
        pc = p[sel]
        z = pc[:, 2]
        xn = pc[:, :2] / z[:, None]
        xd = cam.lens.distort(xn)
        res[sel] = cam.normalized_to_pixel(xd) - obs.image_points[sel]
        if not with_jacobian:
            continue
        k = sel.size
        # d pixel / d intrinsics
        icols = np.arange(layout.intrinsic_slice(c).start, layout.intrinsic_slice(c).stop)
        di = np.zeros((k, 2, icols.size))
        di[:, 0, 0], di[:, 1, 1] = xd[:, 0], xd[:, 1]
        di[:, 0, 2], di[:, 1, 3] = 1.0, 1.0
        jc = cam.lens.jacobian_coefficients(xn)  # (k, 2, nc)
        di[:, 0, 4:] = cam.fx * jc[:, 0, :]
        di[:, 1, 4:] = cam.fy * jc[:, 1, :]
        add(sel, icols, di)
        # d pixel / d camera point
        jp = cam.lens.jacobian_point(xn)  # (k, 2, 2)
        jp[:, 0, :] *= cam.fx
        jp[:, 1, :] *= cam.fy
        dn = np.zeros((k, 2, 3))
        dn[:, 0, 0] = dn[:, 1, 1] = 1 / z
        dn[:, 0, 2] = -xn[:, 0] / z
        dn[:, 1, 2] = -xn[:, 1] / z
        dq_dp = jp @ dn  # (k, 2, 3)
        if c == 1 and layout.stereo:
            s = layout.rel_start
            Rr = Rotation.from_rotvec(x[s : s + 3]).as_matrix()
            Jl = left_jacobian(x[s : s + 3])
            r_pw = p[sel] - x[s + 3 : s + 6]  # R_rel · p_wide
            d_rot = -np.einsum("kab,bc->kac", _skew_many(r_pw), Jl)
            add(sel, np.arange(s, s + 6), np.concatenate([dq_dp @ d_rot, dq_dp], axis=2))
            dq_dpw = dq_dp @ Rr  # chain through the wide frame
        else:
            dq_dpw = dq_dp
        # d p_wide / d view pose
        views = obs.view[sel]
        Jl_v = np.stack([left_jacobian(rv) for rv in rotvecs])  # (V, 3, 3), V small
        d_rot_v = -np.einsum("kab,kbc->kac", _skew_many(ry[sel]), Jl_v[views])
        vals = np.concatenate([dq_dpw @ d_rot_v, dq_dpw], axis=2)  # (k, 2, 6)
        cols = layout.views_start + 6 * views[:, None, None] + np.arange(6)[None, None, :]
        k2 = sel.size
        blocks_rows.append(np.repeat(rows2[sel], 6, axis=1).reshape(-1))
        blocks_cols.append(np.broadcast_to(cols, (k2, 2, 6)).reshape(-1))
        blocks_vals.append(vals.reshape(-1))
    r = res.reshape(-1)
    if not with_jacobian:
        return r, None
    jac = sparse.csr_matrix(
        (np.concatenate(blocks_vals), (np.concatenate(blocks_rows), np.concatenate(blocks_cols))),
        shape=(2 * m, layout.n_params),
    )
    return r, jac


def _skew_many(v: np.ndarray) -> np.ndarray:
    """[v]ₓ for each row of v (K, 3) → (K, 3, 3)."""
    out = np.zeros((v.shape[0], 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -v[:, 2], v[:, 1]
    out[:, 1, 0], out[:, 1, 2] = v[:, 2], -v[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -v[:, 1], v[:, 0]
    return out
