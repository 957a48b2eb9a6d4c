"""The fast paths of the matcher against slow, obviously-right references (issue #4 speed).

* :func:`ncc_search` fills one (N, rows, disparities) array and analyses the peaks vectorised;
  the reference searches one keypoint at a time with ``cv2.minMaxLoc``.
* :func:`detect_dog` finds extrema with OpenCV masks and tests the Hessian on the strongest
  candidates first; the reference tests every candidate with NumPy.
"""

from __future__ import annotations

import warnings

import cv2
import numpy as np
import pytest

from phonestereo.features.keypoints import _select, detect_dog
from phonestereo.features.search import ncc_search


def _texture(shape: tuple[int, int], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return cv2.GaussianBlur(rng.uniform(0, 255, shape).astype(np.float32), (0, 0), 1.5)


def _reference_peak(left, right, x, y, r, min_d, max_d, ty, exclusion=2):
    """(d0 integer part, e0 integer part, score, second) of one keypoint, or None."""
    h, w = left.shape
    xa, xb = max(x - max_d - r, 0), min(x - min_d + r + 1, w)
    if xb - xa < 2 * r + 3 or y - ty - r < 0 or y + ty + r + 1 > h:
        return None
    c = cv2.matchTemplate(
        right[y - ty - r : y + ty + r + 1, xa:xb],
        left[y - r : y + r + 1, x - r : x + r + 1],
        cv2.TM_CCOEFF_NORMED,
    )
    _, best, _, (ix, iy) = cv2.minMaxLoc(c)
    c[:, max(ix - exclusion, 0) : ix + exclusion + 1] = -1.0
    return x - (xa + r + ix), y - (y - ty + iy), best, cv2.minMaxLoc(c)[1]


@pytest.mark.parametrize("min_d, max_d, ty", [(0, 30, 2), (-5, 40, 0), (3, 20, 3)])
def test_vectorised_search_equals_the_per_keypoint_reference(min_d, max_d, ty) -> None:
    left = _texture((120, 200), 0)
    rng = np.random.default_rng(1)
    right = np.roll(left, -9, axis=1) + rng.normal(0, 1, left.shape).astype(np.float32)
    # keypoints near every border too: clipped bands and bands that do not fit
    xy = np.stack([rng.integers(8, 192, 300), rng.integers(8, 112, 300)], axis=1)
    s = ncc_search(left, right, xy, radius=7, min_d=min_d, max_d=max_d, row_tolerance=ty)
    for i, (x, y) in enumerate(xy.tolist()):
        ref = _reference_peak(left, right, x, y, 7, min_d, max_d, ty)
        assert s.searched[i] == (ref is not None)
        if ref is None:
            continue
        # float32 NCC from the same OpenCV call: equal to rounding
        assert s.score[i] == pytest.approx(ref[2], abs=1e-6)
        assert s.second[i] == pytest.approx(ref[3], abs=1e-6)
        if not s.at_edge[i]:  # the parabola moves d0, e0 by < 0.5 px from the integer peak
            assert abs(s.d0[i] - ref[0]) <= 0.5 and abs(s.e0[i] - ref[1]) <= 0.5
    inner = s.searched & ~s.at_edge
    assert inner.sum() > 250
    assert np.median(np.abs(s.d0[inner] - 9)) < 0.05  # px: the true shift is 9


def test_zero_score_windows_search_quietly() -> None:
    # a flat right image: every NCC is 0 (OpenCV's zero-variance result); with the left-right
    # uniqueness test off (lr_uniqueness = ∞, the default) no ∞ · 0 warning, no back search
    left = _texture((60, 120), 0)
    right = np.full_like(left, 100.0)
    xy = np.array([[60, 30], [80, 25]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        s = ncc_search(left, right, xy, radius=7, min_d=0, max_d=30, row_tolerance=1)
    assert s.searched.all() and np.all(s.score == 0.0) and not s.lr_ok.any()


def _reference_dog(img, box, threshold, max_keypoints, edge_ratio=10.0):
    """The plain NumPy DoG detector: every extremum above threshold gets the Hessian test."""
    x0, y0, x1, y1 = box
    dog = cv2.GaussianBlur(img, (0, 0), 1.0) - cv2.GaussianBlur(img, (0, 0), 1.6)
    k = np.ones((3, 3), np.uint8)
    ext = (dog == cv2.dilate(dog, k)) | (dog == cv2.erode(dog, k))
    keep = np.zeros_like(ext)
    keep[y0:y1, x0:x1] = ext[y0:y1, x0:x1] & (np.abs(dog[y0:y1, x0:x1]) > threshold)
    ys, xs = np.nonzero(keep)
    c = dog[ys, xs]
    dxx = dog[ys, xs + 1] + dog[ys, xs - 1] - 2 * c
    dyy = dog[ys + 1, xs] + dog[ys - 1, xs] - 2 * c
    dxy = 0.25 * (
        dog[ys + 1, xs + 1] - dog[ys + 1, xs - 1] - dog[ys - 1, xs + 1] + dog[ys - 1, xs - 1]
    )
    tr, det = dxx + dyy, dxx * dyy - dxy * dxy
    ok = (det > 0) & (tr * tr * edge_ratio < (edge_ratio + 1) ** 2 * det)
    return _select(xs[ok], ys[ok], np.abs(c[ok]).astype(np.float64), max_keypoints, 8)


@pytest.mark.parametrize("max_keypoints", [50, 300, 100_000])
def test_dog_fast_path_equals_the_reference(max_keypoints: int) -> None:
    img = _texture((160, 240), 2)
    box = (20, 20, 220, 140)
    kp = detect_dog(img, mask_box=box, threshold=0.5, max_keypoints=max_keypoints)
    xs, ys, resp = _reference_dog(img, box, 0.5, max_keypoints)
    # the same keypoints and responses (order may differ only among equal responses)
    assert len(kp) == len(xs) and np.array_equal(kp.response, resp)
    assert set(map(tuple, kp.xy.astype(int).tolist())) == set(
        zip(xs.tolist(), ys.tolist(), strict=True)
    )
