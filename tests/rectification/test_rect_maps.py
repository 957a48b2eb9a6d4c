"""Remap maps and image rectification: the coarse-grid maps against the exact point maps, the
images against the points, and the typed errors on bad images."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.errors import InputError, ShapeError
from phonestereo.geometry import Rig
from phonestereo.rectification import INVALID, MODES, Rectification, RectifyOptions
from phonestereo.sim.capture import calibration_rig
from phonestereo.sim.module import load_module


@pytest.fixture(scope="module")
def folded() -> Rig:
    return calibration_rig(load_module("folded-x3"))


def _map_error(rect: Rectification, role: str, n: int = 4000) -> float:
    """Max |map − exact inverse point map| over random rectified pixels, px."""
    mx, my = rect.maps_wide() if role == "wide" else rect.maps_tele()
    inverse = rect.unrectify_wide if role == "wide" else rect.unrectify_tele
    h, w = mx.shape
    rng = np.random.default_rng(7)
    ij = np.stack([rng.integers(0, w, n), rng.integers(0, h, n)], axis=-1)
    exact = inverse(ij.astype(float))
    got = np.stack([mx[ij[:, 1], ij[:, 0]], my[ij[:, 1], ij[:, 0]]], axis=-1)
    ok = np.isfinite(exact).all(axis=-1) & (got[:, 0] != INVALID)
    assert ok.mean() > 0.95
    return float(np.max(np.abs(got[ok] - exact[ok])))


@pytest.mark.parametrize("mode", MODES)
@pytest.mark.parametrize("resolution", ["wide", "tele"])
def test_coarse_maps_match_the_exact_point_maps(folded: Rig, mode: str, resolution: str) -> None:
    rect = Rectification.from_rig(folded, mode, RectifyOptions(resolution=resolution))
    for role in ("wide", "tele"):
        # Spline on an 8-px grid: measured ≤ 2.5e-4 px, of which 6e-5 is float32 rounding at
        # ~1000 px; 1e-3 px is 1 % of the thesis's 0.1 px disparity budget (docs/equations.md).
        assert _map_error(rect, role) <= 1e-3, role


def _inside(maps: tuple[np.ndarray, ...], size: tuple[int, int], pad: float = -0.5) -> np.ndarray:
    mx, my = maps
    return (mx >= pad) & (my >= pad) & (mx <= size[0] - 1 - pad) & (my <= size[1] - 1 - pad)


def test_wide_fov_maps_and_empty_border(folded: Rig) -> None:
    rect = Rectification.from_rig(folded, "canonical", RectifyOptions(fov="wide"))
    assert _map_error(rect, "wide") <= 1e-3
    # The undistorted, 7°-tilted wide does not fill its bounding box: the corners sample
    # outside the raw image and come out 0.
    inside = _inside(rect.maps_wide(), folded.wide.size)
    assert 0.7 < inside.mean() < 1.0
    tele_inside = _inside(rect.maps_tele(), folded.tele.size)
    assert tele_inside.mean() < 0.2  # the ×3 tele sees ~1/9 of the wide's view
    out_w, out_t = rect.remap(
        np.full((1500, 2000), 200, np.uint8), np.full((1500, 2000), 9, np.uint8)
    )
    # Lanczos-4 sampling (the default, 8 × 8 taps) reaches four pixels beyond the image;
    # further out everything is 0; a sample three pixels inside the border sees only the image.
    far_w = ~_inside(rect.maps_wide(), folded.wide.size, pad=-4.0)
    far_t = ~_inside(rect.maps_tele(), folded.tele.size, pad=-4.0)
    assert np.all(out_w[far_w] == 0) and np.all(out_t[far_t] == 0)
    assert np.all(out_w[_inside(rect.maps_wide(), folded.wide.size, pad=3.0)] == 200)


def _blobs(size: tuple[int, int], centres: np.ndarray, sigma: float) -> np.ndarray:
    """Float32 image with unit Gaussian blobs at sub-pixel centres (drawn in local patches)."""
    w, h = size
    img = np.zeros((h, w), np.float32)
    r = int(5 * sigma)
    for cx, cy in centres:
        x0, y0 = round(cx) - r, round(cy) - r
        yy, xx = np.mgrid[y0 : y0 + 2 * r + 1, x0 : x0 + 2 * r + 1]
        g = np.exp(-((xx - cx) ** 2 + (yy - cy) ** 2) / (2 * sigma**2))
        img[y0 : y0 + 2 * r + 1, x0 : x0 + 2 * r + 1] += g.astype(np.float32)
    return img


def _centroids(img: np.ndarray, guesses: np.ndarray, r: int) -> np.ndarray:
    out = []
    for gx, gy in guesses:
        x0, y0 = round(gx) - r, round(gy) - r
        patch = img[y0 : y0 + 2 * r + 1, x0 : x0 + 2 * r + 1].astype(np.float64)
        yy, xx = np.mgrid[y0 : y0 + 2 * r + 1, x0 : x0 + 2 * r + 1]
        out.append([(patch * xx).sum() / patch.sum(), (patch * yy).sum() / patch.sum()])
    return np.array(out)


@pytest.mark.parametrize("mode", MODES)
def test_remapped_images_agree_with_the_point_maps(folded: Rig, mode: str) -> None:
    """A blob at raw q lands at points_*(q) in the remapped image."""
    rect = Rectification.from_rig(folded, mode)
    gx, gy = np.meshgrid(np.linspace(300, 1700, 4), np.linspace(250, 1250, 3))
    q_tele = np.stack([gx.ravel(), gy.ravel()], axis=-1) + 0.37
    P = folded.T_tele_wide.inverse().apply(folded.tele.unproject(q_tele) * 2.0)
    q_wide = folded.wide.project(P)
    zoom = folded.zoom
    wide_img = _blobs(folded.wide.size, q_wide, 2.5)
    tele_img = _blobs(folded.tele.size, q_tele, 2.5 * zoom)
    out_w, out_t = rect.remap(wide_img, tele_img)
    assert out_w.shape == out_t.shape == rect.wide_rect.size[::-1]
    for img, expected in ((out_w, rect.points_wide(q_wide)), (out_t, rect.points_tele(q_tele))):
        got = _centroids(img, expected, 12)
        # Lanczos-4 resampling of a σ = 2.5 px blob (its phase error) and the lens's curvature
        # across it move the centroid a little (measured ≤ 0.016 px; bilinear 0.013, OpenCV's
        # cubic 0.046 — maps.DEFAULT_INTERPOLATION); the sign, offset and
        # half-pixel errors this guards against are ≥ 0.5 px.
        np.testing.assert_allclose(got, expected, atol=0.03)


def test_tele_to_wide_wide_image_is_an_exact_crop(folded: Rig) -> None:
    rect = Rectification.from_rig(folded, "tele-to-wide")
    raw = np.random.default_rng(0).integers(0, 256, (1500, 2000), dtype=np.uint8)
    out_w, _ = rect.remap(raw, np.zeros((1500, 2000), np.uint8))
    turned = np.rot90(raw, 1)  # k = 1: (x', y') = (y, W − 1 − x)
    x0, y0 = np.round(rect.points_wide([[0.0, 0.0]])[0] - [0, 1999]).astype(int) * -1
    h, w = out_w.shape
    np.testing.assert_array_equal(out_w, turned[y0 : y0 + h, x0 : x0 + w])


def test_bad_images_raise_typed_errors(folded: Rig) -> None:
    rect = Rectification.from_rig(folded, "canonical")
    ok = np.zeros((1500, 2000), np.uint8)
    with pytest.raises(InputError, match="differ in size"):
        rect.remap(ok, np.zeros((750, 1000), np.uint8))
    with pytest.raises(InputError, match=r"calibration is for wide 2000×1500"):
        rect.remap(np.zeros((750, 1000), np.uint8), np.zeros((750, 1000), np.uint8))
    with pytest.raises(ShapeError, match="non-empty"):
        rect.remap(np.zeros((0, 0), np.uint8), ok)
    with pytest.raises(InputError, match="dtype float64"):
        rect.remap(ok.astype(np.float64), ok)
    with pytest.raises(InputError, match="interpolation"):
        rect.remap(ok, ok, interpolation="lanczos")


def test_small_window_uses_the_exact_map(folded: Rig) -> None:
    """An ROI window under 4 grid steps a side is mapped exactly at every pixel."""
    opts = RectifyOptions(roi=(990, 740, 20, 16))
    rect = Rectification.from_rig(folded, "tele-to-wide", opts)
    assert min(rect.wide_rect.size) < 4 * opts.grid_step_px
    np.testing.assert_array_equal(rect.maps_tele()[0], rect.maps_tele(step=1)[0])
    assert _map_error(rect, "tele") <= 1e-4  # float32 rounding only
