"""The renderer of the virtual module (sim/scene.py, sim/render.py, sim/optics.ray_field).

The central claim (docs/architecture.md): a noise-free render of a chessboard puts its
corners where the camera model projects them, to ~0.02 px, since every later sub-pixel claim
rests on it. Two independent corner estimators check it:

* ``edge_fit_corner`` — each of the two edges through a corner is located row by row (or column
  by column) from the area coverage of a run of pixels across it (for an area-sampled step
  between levels a and b, Σ (I − b)/(a − b) over the run is the edge's position in the run),
  fitted with a quadratic and intersected. Exact for area sampling up to the edges' curvature.
* ``cv2.cornerSubPix`` — the usual tool. On a sharp (area-sampled, unblurred) image it is biased
  towards the pixel grid ("pixel locking", ±0.08 px with the phase of the corner); the test
  ``test_cornersubpix_pixel_locking_is_the_estimator`` shows that the bias follows the sub-pixel
  phase while the edge fit does not. With a lens-like blur (σ = 1.5 px) it agrees to < 0.02 px.
"""

from __future__ import annotations

from math import erf
from typing import Any

import cv2
import numpy as np
import pytest

from phonestereo.errors import InputError, PhysicsError
from phonestereo.geometry import Camera, Transform, make_lens
from phonestereo.sim.optics import defocus_sigma_function, ray_field
from phonestereo.sim.render import render_view
from phonestereo.sim.scene import Lighting, PlanarObject, Scene, facing_pose

LENS = make_lens("opencv5", (-0.05, 0.02, 3e-4, -2e-4, 0.0))  # realistic phone wide-ish lens
TILT = (0.2, -0.25, 0.05)  # rad: ~11° and ~14° out of plane, 3° in plane
SIZE = (2000, 1500)
LO, HI = 0.05, 0.95


class Board:
    """A chessboard chart (the renderer's side of ``charts.base.Chart``), square 25 mm."""

    name = "board"

    def __init__(self, nx: int = 12, ny: int = 9, sq: float = 0.025, margin: float = 0.02):
        self.nx, self.ny, self.sq, self.margin = nx, ny, sq, margin
        self.size_m = (nx * sq + 2 * margin, ny * sq + 2 * margin)

    def intensity(self, uv: Any) -> np.ndarray:
        uv = np.asarray(uv, dtype=float)
        i = np.floor((uv[:, 0] - self.margin) / self.sq)
        j = np.floor((uv[:, 1] - self.margin) / self.sq)
        board = (i >= 0) & (i < self.nx) & (j >= 0) & (j < self.ny)
        out = np.where(board & ((i + j) % 2 == 0), LO, HI)
        w, h = self.size_m
        out[(uv[:, 0] < 0) | (uv[:, 0] > w) | (uv[:, 1] < 0) | (uv[:, 1] > h)] = np.nan
        return out

    def corners_uv(self) -> np.ndarray:
        i, j = np.meshgrid(np.arange(1, self.nx), np.arange(1, self.ny))
        return np.stack([i.ravel(), j.ravel()], -1) * self.sq + self.margin


def corner_truth(cam: Camera, T: Transform, uv: np.ndarray, sq: float) -> tuple[np.ndarray, ...]:
    """Projected corners (N, 2) and the projected one-square vectors along u and v (N, 2)."""

    def proj(p: np.ndarray) -> np.ndarray:
        return cam.project(T.apply(np.c_[p, np.zeros(len(p))]))

    q = proj(uv)
    return q, proj(uv + np.array([sq, 0])) - q, proj(uv + np.array([0, sq])) - q


def _edge_points(
    img: np.ndarray, q: np.ndarray, dl: np.ndarray, dm: np.ndarray, guard: float
) -> np.ndarray:
    """Points of the edge through corner q along dl (one square), from pixel-run coverage."""
    d, sq = dl / np.linalg.norm(dl), np.linalg.norm(dl)
    n_m = np.array([-dm[1], dm[0]]) / np.linalg.norm(dm)
    n_l = np.array([-d[1], d[0]])
    rows = abs(d[1]) >= abs(d[0])  # a steep edge crosses pixel rows
    r = int(max(2, min(0.3 * min(sq, np.linalg.norm(dm)), 8)))
    h, w = img.shape
    pts, seen = [], set()
    for t in np.concatenate([np.arange(1.0, sq - 1), -np.arange(1.0, sq - 1)]):
        p = q + t * d
        line = round(p[1]) if rows else round(p[0])
        if line in seen:
            continue
        seen.add(line)
        if rows:
            x0 = int(np.floor(q[0] + (line - q[1]) * d[0] / d[1])) - r
            pix = np.stack([np.arange(x0, x0 + 2 * r + 2), np.full(2 * r + 2, line)], -1)
        else:
            y0 = int(np.floor(q[1] + (line - q[0]) * d[1] / d[0])) - r
            pix = np.stack([np.full(2 * r + 2, line), np.arange(y0, y0 + 2 * r + 2)], -1)
        if pix.min() < 0 or pix[:, 0].max() >= w or pix[:, 1].max() >= h:
            continue
        dist_m = np.abs((pix - q) @ n_m)  # clear of the crossing edge and its next parallels
        if np.any(dist_m < guard) or np.any(dist_m > abs(dl @ n_m) - guard):
            continue
        if np.any(np.abs((pix - q) @ n_l) > abs(dm @ n_l) - guard):
            continue
        run = img[pix[:, 1], pix[:, 0]].astype(float)
        a, b = run[0], run[-1]
        if min(abs(a - LO), abs(a - HI)) > 0.02 or min(abs(b - LO), abs(b - HI)) > 0.02:
            continue
        if abs(a - b) < 0.5:
            continue
        pos = -0.5 + np.sum((run - b) / (a - b))  # length of the a side in the run
        pts.append((pix[0, 0] + pos, line) if rows else (line, pix[0, 1] + pos))
    return np.array(pts).reshape(-1, 2)


def edge_fit_corner(
    img: np.ndarray, q: np.ndarray, du: np.ndarray, dv: np.ndarray, guard: float = 1.2
) -> np.ndarray:
    """Corner estimate (2,) as the intersection of its two edges (see the module docstring).

    ``guard``: pixels closer than this to another edge are not used (grow it with blur).
    """
    fits = []
    for dl, dm in ((du, dv), (dv, du)):
        pts = _edge_points(img, q, dl, dm, guard)
        if len(pts) < 2:
            return np.full(2, np.nan)
        a, b = (0, 1) if abs(dl[1]) >= abs(dl[0]) else (1, 0)  # coordinate a = poly(b)
        fits.append(
            (a, b, np.polyfit(pts[:, b] - q[b], pts[:, a] - q[a], 2 if len(pts) >= 8 else 1))
        )
    p = np.zeros(2)
    for _ in range(50):
        for a, b, c in fits:
            p[a] = np.polyval(c, p[b])
    return q + p


def corner_errors(
    img: np.ndarray, cam: Camera, T: Transform, board: Board, margin: float, guard: float = 1.2
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Edge-fit errors (N, 2) of the corners well inside ``img``; also q, du, dv."""
    q, du, dv = corner_truth(cam, T, board.corners_uv(), board.sq)
    ok = cam.contains(q, margin=margin)
    q, du, dv = q[ok], du[ok], dv[ok]
    est = np.array([edge_fit_corner(img, q[i], du[i], dv[i], guard) for i in range(len(q))])
    return est - q, q, np.minimum(np.linalg.norm(du, axis=1), np.linalg.norm(dv, axis=1))


def crop(cam: Camera, x0: int, y0: int, w: int, h: int) -> Camera:
    """The camera of the window [x0, x0 + w) × [y0, y0 + h) of ``cam`` (same lens field)."""
    return Camera((w, h), cam.fx, cam.fy, cam.cx - x0, cam.cy - y0, cam.lens)


def rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.nanmean(np.sum(e**2, axis=1))))


def board_scene(f: float, z: float) -> tuple[Board, Transform, Scene]:
    sq_px = f * 0.025 / z
    board = Board(
        int(np.clip(0.6 * SIZE[0] / sq_px, 4, 40)), int(np.clip(0.6 * SIZE[1] / sq_px, 4, 30))
    )
    T = facing_pose(board.size_m, z, tilt_rad=TILT, center_m=(0.05 * z, -0.03 * z))
    return board, T, Scene((PlanarObject(board, T, "board"),))


# --- ray field ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "name, coeffs",
    [
        ("opencv5", (-0.05, 0.02, 3e-4, -2e-4, 0.0)),
        ("opencv8", (-0.1, 0.05, 1e-3, -5e-4, 0.0, 0.05, 0.0, 0.0)),
        # r¹ term: the field is only C¹ at the principal point, the hardest case for a spline.
        ("radial-odd", (0.01, -0.06, 0.0, 0.02, 0, 0, 3e-4, -2e-4)),
    ],
)
@pytest.mark.parametrize("f", [1500.0, 4500.0])
@pytest.mark.parametrize("corners", [False, True])
def test_ray_field_interpolation_error_below_1e3_px(name, coeffs, f, corners) -> None:
    cam = Camera(SIZE, f, f, 1002.8, 747.4, make_lens(name, coeffs))
    nx, ny = ray_field(cam, corners=corners)
    assert nx.shape == ((SIZE[1] + 1, SIZE[0] + 1) if corners else (SIZE[1], SIZE[0]))
    rng = np.random.default_rng(0)
    iy, ix = rng.integers(0, nx.shape[0], 30000), rng.integers(0, nx.shape[1], 30000)
    q = np.stack([ix, iy], -1) - (0.5 if corners else 0.0)
    # Re-project the interpolated rays with the exact forward model: the error in pixels.
    err = np.abs(cam.project(np.stack([nx[iy, ix], ny[iy, ix], np.ones(len(ix))], -1)) - q)
    assert err.max() < 1e-3  # brief; measured ≤ 5e-5 px (the built-in check targets 1e-4)


def test_ray_field_of_pinhole_is_exact() -> None:
    cam = Camera((8, 6), 10.0, 12.0, 3.5, 2.5)
    nx, ny = ray_field(cam)
    assert nx[0, 0] == pytest.approx(-0.35) and ny[5, 0] == pytest.approx(2.5 / 12)


# --- corner accuracy ---------------------------------------------------------------------------
@pytest.mark.parametrize("f", [1500.0, 4500.0])
@pytest.mark.parametrize("z", [0.8, 2.0, 4.0])
def test_corners_land_on_projection_edge_fit(f, z) -> None:
    """Windows of the full 2000 × 1500 camera (centre and a distorted corner region)."""
    cam = Camera(SIZE, f, f, 1003.2, 747.9, LENS)
    board, T, scene = board_scene(f, z)
    sq_px = f * 0.025 / z
    s = int(min(2.2 * sq_px + 24, 420))
    q, _, _ = corner_truth(cam, T, board.corners_uv(), board.sq)
    errs = []
    for target in ((1000, 750), (1650, 1200)):  # centre; 0.8 of the half-diagonal out
        k = np.nanargmin(np.linalg.norm(q - target, axis=1))
        x0, y0 = (int(v) - s // 2 for v in q[k])
        c = crop(cam, x0, y0, s, s)
        img = render_view(c, Transform.identity(), scene).radiance
        e, _, _ = corner_errors(img, c, T, board, margin=min(sq_px, 40) + 3)
        errs.append(e)
    e = np.concatenate(errs)
    assert len(e) >= 2 and np.all(np.isfinite(e))
    # Renderer measured at ≤ 0.001 px RMS; 0.005 leaves room for the estimator's own error.
    assert rms(e) < 0.005, rms(e)


def test_cornersubpix_pixel_locking_is_the_estimator() -> None:
    """Shift a board by sub-pixel steps: the edge fit tracks it, cornerSubPix locks to pixels."""
    f, z = 1200.0, 1.0
    board = Board(6, 6)
    T = facing_pose(board.size_m, z)  # axis-aligned: every corner has the same phase
    scene = Scene((PlanarObject(board, T),))
    bias, fit = [], []
    for phase in np.arange(8) / 8:
        cam = Camera((220, 220), f, f, 109.5 + phase, 109.5)
        img = render_view(cam, Transform.identity(), scene).radiance
        e, q, _ = corner_errors(img, cam, T, board, margin=35)
        crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-6)
        r = cv2.cornerSubPix(
            img, (q + 0.3).astype(np.float32).reshape(-1, 1, 2), (8, 8), (-1, -1), crit
        )
        bias.append(np.mean(r.reshape(-1, 2)[:, 0] - q[:, 0]))
        fit.append(rms(e))
    bias_a = np.array(bias)
    assert max(fit) < 0.002  # the render follows the shift to 2 millipixels at every phase
    assert np.abs(bias_a).max() > 0.05  # cornerSubPix: ~±0.08 px, a function of the phase ...
    assert abs(bias_a[0]) < 0.01 and abs(bias_a[4]) < 0.01  # ... zero at 0 and 1/2 px ...
    assert np.allclose(bias_a[1:4], -bias_a[7:4:-1], atol=0.01)  # ... and odd about them


def test_cornersubpix_with_lens_blur_within_002_px() -> None:
    """With a lens-like blur (σ = 1.5 px) cornerSubPix agrees with the projection."""
    cam = Camera(SIZE, 1500.0, 1500.0, 1003.2, 747.9, LENS)
    board, T, scene = board_scene(1500.0, 0.8)
    c = crop(cam, 700, 450, 420, 320)
    img = cv2.GaussianBlur(render_view(c, Transform.identity(), scene).radiance, (0, 0), 1.5)
    q, _, _ = corner_truth(c, T, board.corners_uv(), board.sq)
    q = q[c.contains(q, margin=30)]
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-6)
    r = cv2.cornerSubPix(
        img, (q + 0.3).astype(np.float32).reshape(-1, 1, 2), (11, 11), (-1, -1), crit
    )
    assert len(q) >= 6 and rms(r.reshape(-1, 2) - q) < 0.02


def _reference(cam: Camera, T: Transform, board: Board, n: int) -> np.ndarray:
    """Brute force: n × n sub-samples per pixel, each undistorted exactly (Newton)."""
    w, h = cam.size
    o = (np.arange(n) + 0.5) / n - 0.5
    ox, oy = (a.ravel() for a in np.meshgrid(o, o))
    px = np.broadcast_to(np.arange(w)[None, :, None] + ox, (h, w, n * n))
    py = np.broadcast_to(np.arange(h)[:, None, None] + oy, (h, w, n * n))
    nrm = cam.pixel_to_normalized(np.stack([px, py], -1).reshape(-1, 2))
    R, t = T.R, T.t
    g = np.c_[nrm, np.ones(len(nrm))] @ np.linalg.inv(np.column_stack([R[:, 0], R[:, 1], t])).T
    return board.intensity(g[:, :2] / g[:, 2:]).reshape(h, w, n * n).mean(axis=-1)


def test_render_matches_brute_force_area_integral() -> None:
    cam = Camera(SIZE, 1500.0, 1500.0, 1003.2, 747.9, LENS)
    board, T, scene = board_scene(1500.0, 0.8)
    q, _, _ = corner_truth(cam, T, board.corners_uv(), board.sq)
    x0, y0 = (int(v) - 12 for v in q[len(q) // 3])
    c = crop(cam, x0, y0, 24, 24)
    mine = render_view(c, Transform.identity(), scene).radiance
    ref = _reference(c, T, board, 64)
    # The reference's own error is ≤ 0.9/128 on axis-aligned edges, ~1e-3 on tilted ones.
    assert np.abs(mine - ref).max() < 0.012
    assert np.abs(mine - ref).mean() < 1e-3


# --- scene semantics -------------------------------------------------------------------------
class Flat:
    def __init__(self, value: float, size: tuple[float, float] = (1.0, 1.0)):
        self.value, self.size_m = value, size

    def intensity(self, uv: Any) -> np.ndarray:
        uv = np.asarray(uv, dtype=float)
        w, h = self.size_m
        inside = (uv[:, 0] >= 0) & (uv[:, 0] <= w) & (uv[:, 1] >= 0) & (uv[:, 1] <= h)
        return np.where(inside, self.value, np.nan)


def test_occlusion_index_depth_and_background() -> None:
    cam = Camera((80, 60), 100.0, 100.0, 39.5, 29.5)
    far = PlanarObject(Flat(0.2, (2.0, 2.0)), facing_pose((2.0, 2.0), 3.0), "far")
    near = PlanarObject(
        Flat(0.8, (0.3, 0.3)), facing_pose((0.3, 0.3), 1.0, center_m=(0.3, 0)), "near"
    )
    scene = Scene((far, near), background=0.5)
    rv = render_view(cam, Transform.identity(), scene)
    # near square: 30 px wide at 1 m, centred 30 px right of the principal point
    assert rv.object_index[30, 55] == 1 and rv.radiance[30, 55] == pytest.approx(0.8)
    assert rv.object_index[30, 10] == 0 and rv.depth_m[30, 10] == pytest.approx(3.0, rel=1e-6)
    assert rv.depth_m[30, 55] == pytest.approx(1.0, rel=1e-6)
    # the near square spans x ∈ [54.5, 84.5] px − its left edge is a pixel boundary
    assert rv.radiance[30, 54] == pytest.approx(0.2, abs=1e-3)
    small = Scene((PlanarObject(Flat(0.9, (0.1, 0.1)), facing_pose((0.1, 0.1), 2.0)),), 0.3)
    rv = render_view(cam, Transform.identity(), small)
    assert rv.object_index[0, 0] == -1 and np.isnan(rv.depth_m[0, 0])
    assert rv.radiance[0, 0] == pytest.approx(0.3)
    # a 5 × 5 px square: the total light is exact (area sampling conserves it)
    excess = float(np.sum(rv.radiance.astype(float) - 0.3))
    assert excess == pytest.approx(25 * 0.6, rel=1e-3)


def test_back_of_a_chart_is_not_rendered() -> None:
    cam = Camera((40, 30), 50.0, 50.0, 19.5, 14.5)
    T = Transform.from_rotvec([0, np.pi, 0], [0.5, -0.5, 1.0])  # +z towards the camera
    rv = render_view(cam, Transform.identity(), Scene((PlanarObject(Flat(0.9), T),)))
    assert np.all(rv.object_index == -1)


def test_world_frame_and_camera_pose_compose() -> None:
    cam = Camera((40, 30), 50.0, 50.0, 19.5, 14.5)
    T_world_chart = facing_pose((1.0, 1.0), 2.0)
    T_cam_world = Transform.from_rotvec([0, 0, 0], [0, 0, 1.0])  # camera 1 m further back
    rv = render_view(cam, T_cam_world, Scene((PlanarObject(Flat(0.9), T_world_chart),)))
    assert np.nanmax(rv.depth_m) == pytest.approx(3.0, rel=1e-6)


def test_defocus_blur_has_the_requested_sigma_and_keeps_corners() -> None:
    cam = Camera((200, 60), 500.0, 500.0, 99.5, 29.5)
    strip = Flat(0.9, (0.2, 1.0))  # u ∈ [0, 0.2]: from the left border to x = 99.5 px
    scene = Scene((PlanarObject(strip, facing_pose((0.4, 1.0), 1.0)),), background=0.1)
    sigma = 2.0
    rv = render_view(cam, Transform.identity(), scene, defocus_sigma_px=lambda z: sigma)
    d = -np.diff(rv.radiance[30].astype(float))  # the falling edge, sampled at x = i + 0.5
    x = np.arange(len(d)) + 0.5
    m = np.sum(d * x) / np.sum(d)
    sd = np.sqrt(np.sum(d * (x - m) ** 2) / np.sum(d))
    # The sharp edge lies on a pixel boundary (a clean step), so the spread is the Gaussian's.
    assert sd == pytest.approx(sigma, rel=0.01)
    assert m == pytest.approx(99.5, abs=0.01) and np.sum(d) == pytest.approx(0.8, abs=1e-4)
    cam2 = Camera(SIZE, 4500.0, 4500.0, 1003.2, 747.9, LENS)
    board, T2, scene2 = board_scene(4500.0, 2.0)
    c = crop(cam2, 900, 650, 200, 200)
    df = defocus_sigma_function(12.6e-3, 2.8, 1.5, 2.8e-6)  # σ = 0.85 px at 2 m
    img = render_view(c, Transform.identity(), scene2, defocus_sigma_px=df).radiance
    e, _, _ = corner_errors(img, c, T2, board, margin=45, guard=4.0)
    assert len(e) >= 4 and rms(e) < 0.005  # a symmetric blur does not move corners


def test_lighting_multiplies_the_image() -> None:
    cam = Camera((41, 31), 40.0, 40.0, 20.0, 15.0)
    lit = Scene(
        (PlanarObject(Flat(0.8, (4.0, 4.0)), facing_pose((4.0, 4.0), 1.0)),),
        0.5,
        Lighting(vignetting=0.25, gradient=(0.1, 0.0)),
    )
    img = render_view(cam, Transform.identity(), lit).radiance
    assert img[15, 20] == pytest.approx(0.8, abs=1e-6)
    assert img[0, 0] == pytest.approx(0.8 * 0.9 * 0.75, abs=1e-5)
    assert img[15, 40] == pytest.approx(0.8 * 1.1 * (1 - 0.125), abs=1e-5)


def test_render_is_deterministic_and_typed() -> None:
    cam = Camera((60, 40), 60.0, 60.0, 29.5, 19.5, LENS)
    board = Board(6, 4)
    scene = Scene((PlanarObject(board, facing_pose(board.size_m, 0.5, tilt_rad=TILT)),))
    a = render_view(cam, Transform.identity(), scene)
    b = render_view(cam, Transform.identity(), scene)
    assert np.array_equal(a.radiance, b.radiance)
    assert a.radiance.dtype == np.float32 and a.object_index.dtype == np.int16
    assert a.depth_m.dtype == np.float32 and a.radiance.shape == (40, 60)
    assert 0.0 <= a.radiance.min() and a.radiance.max() <= 1.0


def test_bad_input_raises_typed_errors() -> None:
    cam = Camera((10, 10), 10.0, 10.0, 4.5, 4.5)
    scene = Scene((PlanarObject(Flat(0.5), facing_pose((1.0, 1.0), 1.0)),))
    with pytest.raises(InputError, match="aa"):
        render_view(cam, Transform.identity(), scene, aa=0)
    with pytest.raises(InputError, match="T_cam_world"):
        render_view(cam, np.eye(4), scene)  # type: ignore[arg-type]
    with pytest.raises(PhysicsError, match="defocus"):
        render_view(cam, Transform.identity(), scene, defocus_sigma_px=lambda z: -1.0)
    with pytest.raises(InputError, match="size_m"):
        PlanarObject(object(), Transform.identity())  # type: ignore[arg-type]
    with pytest.raises(InputError, match="background"):
        Scene((), background=1.5)
    with pytest.raises(PhysicsError, match="gradient"):
        Lighting(gradient=(0.7, 0.5))


class Waves:
    """0.5 + 0.3·sin(2πu/λ)·sin(2πv/λ): smooth content with an analytic area mean."""

    def __init__(self, wavelength_m: float, size: tuple[float, float] = (1.0, 1.0)):
        self.lam, self.size_m = wavelength_m, size

    def intensity(self, uv: Any) -> np.ndarray:
        uv = np.asarray(uv, dtype=float)
        k = 2 * np.pi / self.lam
        out = 0.5 + 0.3 * np.sin(k * uv[:, 0]) * np.sin(k * uv[:, 1])
        w, h = self.size_m
        out[(uv[:, 0] < 0) | (uv[:, 0] > w) | (uv[:, 1] < 0) | (uv[:, 1] > h)] = np.nan
        return out


@pytest.mark.parametrize("period_px", [9.0, 2.3])  # smooth (5-point rule) / aliased (aa × aa)
def test_smooth_texture_area_mean_is_exact(period_px) -> None:
    f, z = 100.0, 1.0  # 1 px = 1 cm on the chart
    cam = Camera((60, 40), f, f, 29.5, 19.5)
    chart = Waves(period_px * z / f)
    T = Transform.from_rotvec([0, 0, 0], [-0.5, -0.5, z])  # chart origin 50 px up-left
    rv = render_view(cam, Transform.identity(), Scene((PlanarObject(chart, T),)))
    a = z / f  # pixel footprint on the chart, metres
    u = (np.arange(60) - 29.5) * a + 0.5
    v = (np.arange(40) - 19.5) * a + 0.5
    k = 2 * np.pi / chart.lam
    truth = 0.5 + 0.3 * np.outer(np.sin(k * v), np.sin(k * u)) * np.sinc(a / chart.lam) ** 2
    err = np.abs(rv.radiance - truth)
    # 5-point rule: 4th-order error ~1e-4; 8 × 8 samples of a 2.3 px period: ~2e-3.
    assert err.max() < (5e-4 if period_px > 5 else 5e-3), err.max()


def test_verification_chart_renders_with_exact_corners() -> None:
    """The charts helper's VerificationChart through the renderer (tele at 2 m, its centre)."""
    verification = pytest.importorskip("phonestereo.charts.verification")
    chart = verification.VerificationChart()
    cam = Camera(SIZE, 4500.0, 4500.0, 1003.2, 747.9, LENS)
    T = facing_pose(chart.size_m, 2.0, tilt_rad=(0.1, -0.15, 0.02))
    scene = Scene((PlanarObject(chart, T, "verification"),))
    c = crop(cam, 650, 400, 700, 600)
    img = render_view(c, Transform.identity(), scene).radiance
    uv = chart.corners_uv()
    circles = np.concatenate([p.centers_uv for p in chart.circle_pairs])
    far = np.min(np.linalg.norm(uv[:, None] - circles[None], axis=2), axis=1) > 2 * chart.square_m
    q, du, dv = corner_truth(c, T, uv[far], chart.square_m)
    ok = c.contains(q, margin=70)
    est = np.array([edge_fit_corner(img, *a) for a in zip(q[ok], du[ok], dv[ok], strict=True)])
    assert ok.sum() >= 10 and rms(est - q[ok]) < 0.005
    # the circles are there: a dark circle in a white square is dark at its centre
    dark = next(p for p in chart.circle_pairs if p.polarity == "dark")
    qc = c.project(T.apply(np.c_[dark.centers_uv, np.zeros(2)]))
    inside = c.contains(qc, margin=2)
    xs, ys = np.round(qc[inside]).astype(int).T
    assert np.all(img[ys, xs] < 0.1)


@pytest.mark.slow
def test_full_size_corner_accuracy_table() -> None:
    """The acceptance of the brief at full size: wide and tele, charts at 0.8, 2 and 4 m."""
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 200, 1e-6)
    print("\ncamera  Z_m  square_px  corners  edge_fit_rms  cornerSubPix_rms(sharp, blur 1.5)")
    for f in (1500.0, 4500.0):
        cam = Camera(SIZE, f, f, 1003.2, 747.9, LENS)
        for z in (0.8, 2.0, 4.0):
            board, T, scene = board_scene(f, z)
            sq = f * 0.025 / z
            img = render_view(cam, Transform.identity(), scene).radiance
            e, q, _ = corner_errors(img, cam, T, board, margin=30)
            win = int(np.clip(0.35 * sq, 5, 15))
            res = []
            for im in (img, cv2.GaussianBlur(img, (0, 0), 1.5)):
                start = (q + 0.3).astype(np.float32).reshape(-1, 1, 2)
                r = cv2.cornerSubPix(im, start, (win, win), (-1, -1), crit).reshape(-1, 2)
                res.append(rms(r - q))
            row = f"{f:6.0f} {z:4.1f} {sq:9.1f} {len(q):8d} {rms(e):13.4f}"
            print(f"{row} {res[0]:8.3f} {res[1]:8.3f}")
            assert np.all(np.isfinite(e)) and rms(e) < 0.005  # measured ≤ 0.0004 px
            assert res[1] < 0.03  # estimator-limited (same on a brute-force render); ≤ 0.024


def test_defocus_is_per_object_depth_and_layers_compose() -> None:
    """A near square (1 m, blurred σ = 2 px) over a far plane (3 m, sharp) and the background."""
    cam = Camera((120, 60), 100.0, 100.0, 59.5, 29.5)
    far = PlanarObject(Flat(0.2, (0.9, 2.0)), facing_pose((1.8, 2.0), 3.0), "far")  # x < 59.5
    near = PlanarObject(Flat(0.8, (0.3, 0.3)), facing_pose((0.3, 0.3), 1.0), "near")
    scene = Scene((far, near), background=0.5)
    sigma = {1.0: 2.0, 3.0: 0.0}
    rv = render_view(cam, Transform.identity(), scene, defocus_sigma_px=lambda z: sigma[round(z)])
    sharp = render_view(cam, Transform.identity(), scene)
    row, ref = rv.radiance[5].astype(float), sharp.radiance[5].astype(float)
    assert np.array_equal(row, ref)  # row 5 sees only the far plane and the background
    assert row[58] == pytest.approx(0.2) and row[60] == pytest.approx(0.5, abs=1e-3)  # sharp
    mid = rv.radiance[29].astype(float)  # through the near square, x ∈ [44.5, 74.5]
    # Coverage of a blurred, area-sampled edge 0.5 px away: Φ(0.5 / sqrt(σ² + 1/12)) = 0.598.
    cover = 0.5 * (1 + erf(0.5 / np.sqrt(sigma[1.0] ** 2 + 1 / 12) / np.sqrt(2)))
    assert mid[44] == pytest.approx(0.8 * (1 - cover) + 0.2 * cover, abs=2e-3)  # over the far
    assert mid[74] == pytest.approx(0.8 * cover + 0.5 * (1 - cover), abs=2e-3)  # over the bg
    assert mid[40] > 0.2 + 1e-3  # the blur reaches 2σ beyond the edge
    assert rv.object_index[29, 60] == 1 and rv.depth_m[29, 60] == pytest.approx(1.0, rel=1e-6)


def test_defocus_layer_of_textured_cells_adds_up_to_the_sharp_render() -> None:
    """The defocus layer holds each refined pixel's area pieces: textured cells whose 8 × 8
    samples all see the chart as one piece (their mean), cells whose samples see the chart and
    the background sample by sample. With σ = 0 the composite is the sharp render again, pixel
    by pixel, so the pieces of both kinds add up to the pixel's area mean and its coverage
    (one object over the background: compositing is exact there, unlike at an occlusion)."""
    cam = Camera((80, 60), 100.0, 100.0, 39.5, 29.5)
    # a 2.3 px period: aliased texture, resolved on the 8 × 8 grid, also where its border
    # crosses a pixel (texture and background in one cell)
    near = PlanarObject(Waves(0.023, (0.35, 0.25)), facing_pose((0.35, 0.25), 1.0), "near")
    scene = Scene((near,), background=0.05)
    sharp = render_view(cam, Transform.identity(), scene).radiance.astype(float)
    layered = render_view(cam, Transform.identity(), scene, defocus_sigma_px=lambda z: 0.0)
    assert np.abs(layered.radiance - sharp).max() < 1e-6  # float32 rounding of the layer
    assert np.ptp(sharp[20:40, 30:50]) > 0.3  # the texture is there
    edge = sharp[29, 20:24]  # the chart's left border x = 22.0 halves pixel 22
    assert edge[0] == pytest.approx(0.05) and 0.05 < edge[2] < 0.8


def test_point_sampling_mode_empty_scene_and_chart_out_of_view() -> None:
    cam = Camera((5, 3), 10.0, 10.0, 2.0, 1.0)

    class Half:
        size_m = (2.0, 2.0)

        def intensity(self, uv: Any) -> np.ndarray:
            return np.where(np.asarray(uv)[:, 0] < 1.0, 0.0, 1.0)

    scene = Scene((PlanarObject(Half(), Transform.from_rotvec([0, 0, 0], [-1, -1, 1])),))
    # aa = 1: no refinement, a pixel is the mean of its corners (exact here: a straight edge
    # through the middle of column 2)
    row = render_view(cam, Transform.identity(), scene, aa=1).radiance[1]
    assert row.tolist() == [0.0, 0.0, 0.5, 1.0, 1.0]
    empty = render_view(cam, Transform.identity(), Scene((), background=0.25))
    assert np.all(empty.radiance == 0.25) and np.all(empty.object_index == -1)
    aside = Scene((PlanarObject(Flat(0.9), facing_pose((1.0, 1.0), 2.0, center_m=(5.0, 0))),))
    assert np.all(render_view(cam, Transform.identity(), aside).object_index == -1)
