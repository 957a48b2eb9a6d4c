"""Stereo matching evaluation shared by the matching tests and ``benchmarks/bench_match.py``.

Real pairs with ground truth (MiddEval3 quarter size from ``../shared/data/stereo_gt``,
scikit-image's ``stereo_motorcycle``), the evaluation at the matcher's own points against
cv2.StereoSGBM and a naive NCC + parabola matcher (:func:`evaluate_real`), rendered
textured-plane pairs (:func:`render_pair`) and the pixel-locking sweep (:func:`pixel_locking`),
so tests and benchmark measure the same thing. What each figure means is in the benchmark's
docstring.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np

from _support import SHARED_DATA
from phonestereo.features.matching import MatchConfig, match_rectified
from phonestereo.features.search import ncc_search

DATA: Path = SHARED_DATA / "stereo_gt"
MIDDLEBURY = ("Adirondack", "Piano")


# --- real data -----------------------------------------------------------------------------
def read_pfm(path: Path) -> np.ndarray:
    """A PFM image as float32 (H, W), rows top to bottom (PFM stores them bottom to top)."""
    with open(path, "rb") as f:
        if f.readline().strip() != b"Pf":
            raise ValueError(f"{path} is not a one-channel PFM")
        w, h = (int(v) for v in f.readline().split())
        scale = float(f.readline())
        data = np.fromfile(f, "<f4" if scale < 0 else ">f4", count=w * h)
    return np.flipud(data.reshape(h, w)).astype(np.float32)


def load_middlebury(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """(left gray, right gray, GT disparity with NaN where unknown or occluded, ndisp)."""
    d = DATA / f"middeval3_Q_{name}"
    left = cv2.imread(str(d / "im0.png"), cv2.IMREAD_GRAYSCALE)
    right = cv2.imread(str(d / "im1.png"), cv2.IMREAD_GRAYSCALE)
    gt = read_pfm(d / "disp0GT.pfm")
    mask = cv2.imread(str(d / "mask0nocc.png"), cv2.IMREAD_GRAYSCALE)
    gt = np.where(np.isfinite(gt) & (mask == 255), gt, np.nan)
    calib = dict(
        line.split("=", 1) for line in (d / "calib.txt").read_text().splitlines() if "=" in line
    )
    return left, right, gt, int(calib["ndisp"])


def nonoccluded(gt: np.ndarray, tol_px: float = 1.0) -> np.ndarray:
    """Mask (H, W) of left pixels with GT that are visible in the right image.

    Each left pixel is forward-warped to x − d on its row; it is occluded when another left
    pixel with a disparity larger by more than ``tol_px`` lands on the same right pixel
    (a z-buffer over disparity), or when x − d leaves the image.
    """
    h, w = gt.shape
    ys, xs = np.nonzero(np.isfinite(gt))
    d = gt[ys, xs].astype(np.float64)
    xr = np.rint(xs - d).astype(np.int64)
    inside = (xr >= 0) & (xr < w)
    ys, xs, d, xr = ys[inside], xs[inside], d[inside], xr[inside]
    front = np.full((h, w), -np.inf)
    np.maximum.at(front, (ys, xr), d)
    mask = np.zeros((h, w), bool)
    mask[ys, xs] = d >= front[ys, xr] - tol_px
    return mask


def load_motorcycle() -> tuple[np.ndarray, np.ndarray, np.ndarray, int] | None:
    """scikit-image's Middlebury 2014 'motorcycle' pair (quarter size, its GT shipped in the
    wheel, no download), or None without scikit-image.

    The GT has no occlusion mask: occluded pixels are found by :func:`nonoccluded` and set to
    NaN like the unknown ones (inf in the file). ``ndisp`` = max GT + 8 (a search range that
    holds every true disparity, as the Middlebury ``ndisp``).
    """
    try:
        from skimage import data  # type: ignore[import-not-found, unused-ignore]
    except ImportError:
        return None
    left, right, disp = data.stereo_motorcycle()
    gray = [cv2.cvtColor(np.asarray(im), cv2.COLOR_RGB2GRAY) for im in (left, right)]
    gt = np.where(np.isfinite(disp), disp, np.nan).astype(np.float32)
    gt = np.where(nonoccluded(gt), gt, np.nan).astype(np.float32)
    return gray[0], gray[1], gt, int(np.ceil(np.nanmax(gt))) + 8


def gt_consistent_left(left: np.ndarray, right: np.ndarray, gt: np.ndarray) -> np.ndarray:
    """The left image re-made from the right one through the GT: L(x, y) = R(x − d_GT(x, y), y).

    The pair (this, ``right``) keeps the real texture, the real surfaces (slants, curvature and
    depth edges inside the windows) and the right camera's noise, but its disparity *is* the
    GT: whatever offset the real left image has from the GT (camera differences, GT
    calibration) is gone, so a matcher's signed error on it is the matcher's own bias.

    Parameters
    ----------
    left, right : ndarray, shape (H, W), uint8
        The real pair (gray); ``left`` is kept where the GT is unknown or occluded.
    gt : ndarray, shape (H, W)
        Left GT disparity, px, NaN where unknown or occluded.

    Returns
    -------
    ndarray, shape (H, W), uint8
        R sampled at (x − d_GT, y) by cubic spline interpolation (mirror border), rounded.
    """
    from scipy import ndimage

    h, w = gt.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    known = np.isfinite(gt)
    warped = ndimage.map_coordinates(
        right.astype(np.float64), [yy, xx - np.where(known, gt, 0.0)], order=3, mode="mirror"
    )
    out = np.where(known, warped, left.astype(np.float64))
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def gt_at(gt: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear GT at pixel (x, y) points; NaN unless all four neighbours are known."""
    h, w = gt.shape
    x, y = xy[:, 0], xy[:, 1]
    x0 = np.clip(np.floor(x).astype(int), 0, w - 2)
    y0 = np.clip(np.floor(y).astype(int), 0, h - 2)
    fx, fy = x - x0, y - y0
    v = (
        gt[y0, x0] * (1 - fx) * (1 - fy)
        + gt[y0, x0 + 1] * fx * (1 - fy)
        + gt[y0 + 1, x0] * (1 - fx) * fy
        + gt[y0 + 1, x0 + 1] * fx * fy
    )
    inside = (x >= 0) & (y >= 0) & (x <= w - 1) & (y <= h - 1)
    return np.where(inside, v, np.nan)


def sgbm(left: np.ndarray, right: np.ndarray, max_d: int, block: int = 5) -> np.ndarray:
    """cv2.StereoSGBM disparity (H, W), px (1/16 sub-pixel), NaN where invalid."""
    n = int(np.ceil((max_d + 1) / 16.0)) * 16
    matcher = cv2.StereoSGBM_create(
        minDisparity=0,
        numDisparities=n,
        blockSize=block,
        P1=8 * block * block,
        P2=32 * block * block,
        mode=cv2.STEREO_SGBM_MODE_SGBM,
    )
    disp = matcher.compute(left, right).astype(np.float32) / 16.0
    return np.where(disp >= 0, disp, np.nan)


def naive_ncc(
    left: np.ndarray, right: np.ndarray, xy: np.ndarray, max_d: int, radius: int
) -> np.ndarray:
    """The naive matcher: NCC along the row only (perfect rectification assumed) + parabola."""
    s = ncc_search(
        left.astype(np.float32),
        right.astype(np.float32),
        np.rint(xy).astype(np.int64),
        radius=radius,
        min_d=0,
        max_d=max_d,
        row_tolerance=0,
        lr_min_score=np.inf,
    )
    return s.d0


def evaluate_real(
    left: np.ndarray, right: np.ndarray, gt: np.ndarray, max_d: int, cfg: MatchConfig | None = None
) -> dict[str, Any]:
    """Our matches against SGBM and naive NCC + parabola at the same points (one pair)."""
    cfg = cfg if cfg is not None else MatchConfig()
    res = match_rectified(left, right, max_disparity=max_d, config=cfg)
    g = gt_at(gt, res.xy)
    ok = np.isfinite(g)
    dense = sgbm(left, right, max_d)
    xi = np.rint(res.xy).astype(int)
    d_sgbm = dense[xi[:, 1], xi[:, 0]]
    d_ncc = naive_ncc(left, right, res.xy, max_d, cfg.radius)
    ok &= np.isfinite(d_sgbm) & np.isfinite(d_ncc)
    err = np.abs(res.d - g)[ok]
    med = {
        "ours": float(np.median(err)),
        "sgbm": float(np.median(np.abs(d_sgbm - g)[ok])),
        "ncc_parabola": float(np.median(np.abs(d_ncc - g)[ok])),
    }
    signed = {
        name: float(np.median((d - g)[ok]))
        for name, d in (("ours", res.d), ("sgbm", d_sgbm), ("ncc_parabola", d_ncc))
    }
    return {
        "matches": len(res),
        "evaluated": int(ok.sum()),
        "median_abs_err_px": med,
        "median_signed_err_px": signed,
        "ratio_to_best_baseline": med["ours"] / min(med["sgbm"], med["ncc_parabola"]),
        "within_0.5px": float(np.mean(err <= 0.5)),
        "within_1_sigma": float(np.mean(err <= res.sigma_d[ok])),
        "median_sigma_d_px": float(np.median(res.sigma_d)),
        "seconds": res.seconds,
    }


# --- rendered data -------------------------------------------------------------------------
def render_pair(
    planes: list[tuple[float, tuple[float, float, float], tuple[float, float]]],
    size: tuple[int, int] = (240, 180),
    f_px: float = 600.0,
    baseline_m: float = 0.02,
    texel_px: float = 5.0,
    seed: int = 0,
    blur: tuple[float, float] = (0.0, 0.0),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A rectified rendered pair of textured planes and the true left disparity f·B/Z per pixel.

    ``planes``: (disparity at the plane centre, tilt rotation vector (rad), centre offset (m));
    blobs are about ``texel_px`` px across at that disparity. Left camera at the origin, right
    camera at +B along x (so d = f·B/Z > 0). 8-bit images with the default sensor noise.
    ``blur``: Gaussian σ (px) of the left and right optics, applied to the radiance before the
    sensor (defocus: the noise stays white, as on a phone).
    """
    from phonestereo.charts.texture import TexturedPlane
    from phonestereo.geometry import Camera, Transform
    from phonestereo.sim.render import render_view
    from phonestereo.sim.scene import PlanarObject, Scene, facing_pose
    from phonestereo.sim.sensor import capture

    w, h = size
    cam = Camera(size, f_px, f_px, (w - 1) / 2, (h - 1) / 2)
    objs = []
    for k, (d, tilt, centre) in enumerate(planes):
        z = f_px * baseline_m / d
        fm = texel_px * z / f_px
        plane = TexturedPlane((2.5 * w * z / f_px, 2.5 * h * z / f_px), seed=seed + k, feature_m=fm)
        pose = facing_pose(plane.size_m, z, tilt_rad=tilt, center_m=centre)
        objs.append(PlanarObject(plane, pose, name=f"plane{k}"))
    scene = Scene(tuple(objs))
    left = render_view(cam, Transform.identity(), scene)
    right = render_view(cam, Transform(np.eye(3), np.array([-baseline_m, 0.0, 0.0])), scene)
    rng = np.random.default_rng(seed + 1000)
    d_true = f_px * baseline_m / left.depth_m.astype(np.float64)
    rad = [
        cv2.GaussianBlur(v.radiance, (0, 0), s) if s > 0 else v.radiance
        for v, s in zip((left, right), blur, strict=True)
    ]
    return capture(rad[0], rng), capture(rad[1], rng), d_true


def pixel_locking(
    fractions: np.ndarray, seed: int = 0, size: tuple[int, int] = (240, 180)
) -> dict[str, Any]:
    """Mean d − d_GT of a fronto-parallel plane at 12 + fraction px, per fraction."""
    bias, sem = [], []
    for frac in fractions:
        left, right, d_true = render_pair(
            [(12.0 + float(frac), (0.0, 0.0, 0.0), (0.0, 0.0))], size=size, seed=seed
        )
        res = match_rectified(left, right, max_disparity=24)
        xi = np.rint(res.xy).astype(int)
        err = res.d - d_true[xi[:, 1], xi[:, 0]]
        bias.append(float(np.mean(err)))
        sem.append(float(np.std(err) / np.sqrt(len(err))))
    return {"fractions": [round(float(f), 2) for f in fractions], "bias_px": bias, "sem_px": sem}
