"""Blur equalisation in the ROI (flows/blur_equalise.py): the blur it adds is the pair's blur
difference, not a penalty for misalignment.

A periscope module (random-1000) has its rectified rows 4 px off (heating, factory error) and a
tele 1.8 % smaller than calibrated (focus breathing). Comparing the box at the coarse disparity
alone, the estimator blurred the wide by 2.4-3 px (a misaligned pair correlates better the more
it is blurred), and the windows then slid along the chart's edges: ±0.7 px per match.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phonestereo.flows.blur_equalise import equalise_blur


def _pair(blur_right: float, scale: float, d: float, e: float) -> tuple[np.ndarray, np.ndarray]:
    """A textured left image and the right one: the same scene seen ``d`` px to the left,
    ``e`` rows up, scaled by ``scale`` about the centre, blurred by ``blur_right`` more."""
    rng = np.random.default_rng(7)
    tex = cv2.GaussianBlur(rng.uniform(0, 255, (480, 640)).astype(np.float32), (0, 0), 1.2)
    tex = 60 + 0.6 * (tex - tex.min())  # mid-grey texture, no clipping
    cy, cx = 240.0, 320.0
    M = np.float32([[scale, 0, cx + d - scale * cx], [0, scale, cy + e - scale * cy]])
    right = cv2.warpAffine(tex, M, (640, 480), flags=cv2.INTER_LANCZOS4 | cv2.WARP_INVERSE_MAP,
                           borderMode=cv2.BORDER_REFLECT)
    if blur_right > 0:
        right = cv2.GaussianBlur(right, (0, 0), blur_right)
    return tex, right


@pytest.mark.parametrize("e", [0.0, -4.3])
@pytest.mark.parametrize("scale", [1.0, 0.982])
def test_equal_blur_adds_none_whatever_the_misalignment(e: float, scale: float) -> None:
    left, right = _pair(0.0, scale, 20.4, e)
    # The pair has the same blur: at most the smallest candidate (0.4 px) may be added, for the
    # Lanczos resampling of the right image (main chose 2.4 px with e = -4.3 and scale 0.982).
    _, _, s_l, s_r = equalise_blur(left, right, (170, 120, 300, 240), 20.4, round(e))
    assert s_l <= 0.4 and s_r == 0.0


@pytest.mark.parametrize("e", [0.0, -4.3])
def test_a_blurrier_tele_gets_its_blur_back(e: float) -> None:
    left, right = _pair(1.4, 0.982, 20.4, e)
    # The right image is blurred by σ = 1.4 px more: the wide gets the candidate nearest to it
    # (1.0 or 1.4; the candidates are 0.4, 0.7, 1.0, 1.4, 1.8, ...).
    _, _, s_l, _ = equalise_blur(left, right, (170, 120, 300, 240), 20.4, round(e))
    assert 1.0 <= s_l <= 1.4


def test_a_large_box_is_thinned_evenly_and_chooses_the_same_blur() -> None:
    from phonestereo.flows import blur_equalise as be

    # A 12 MP ROI's box (~190 tiles of 40 px) keeps every other tile in x and y, spread over
    # the box with both ends kept; a box of <= _MAX_TILES tiles keeps them all.
    xs, ys = be._tile_starts(10, 1230, 5, 905)
    assert len(xs) * len(ys) <= be._MAX_TILES and xs[0] == 10 and ys[0] == 5
    assert xs[-1] == 10 + 40 * 29 and ys[-1] == 5 + 40 * 21  # the last whole tiles
    xs, ys = be._tile_starts(0, 320, 0, 240)
    assert (len(xs), len(ys)) == (8, 6)
    # On the blurrier-tele pair, a box of 300 tiles (thinned to ~75) still finds the blur.
    left, right = _pair(1.4, 1.0, 20.4, 0.0)
    big = (30, 20, 600, 440)
    _, _, s_l, _ = equalise_blur(left, right, big, 20.4, 0)
    assert 1.0 <= s_l <= 1.4


@pytest.mark.parametrize("part", [(150, 100, 420, 300), (0, 0, 300, 480), (200, 50, 640, 470)])
def test_the_blur_of_a_part_is_the_whole_images_there(part: tuple[int, int, int, int]) -> None:
    # measure_roi blurs only the part its matcher reads (issue #18): every pixel there must be
    # the whole image's blur (exactly: the fine disparities must not change), the rest untouched
    left, right = _pair(1.4, 0.982, 20.4, 0.0)
    whole, _, s_l, _ = equalise_blur(left, right, (170, 120, 300, 240), 20.4, 0)
    blurred, _, s_part, _ = equalise_blur(left, right, (170, 120, 300, 240), 20.4, 0, part=part)
    assert s_l == s_part > 0
    x0, y0, x1, y1 = part
    assert np.array_equal(blurred[y0:y1, x0:x1], whole[y0:y1, x0:x1])
    outside = np.ones(left.shape, bool)
    outside[y0:y1, x0:x1] = False
    assert np.array_equal(blurred[outside], left[outside])


def test_tile_shift_is_opencvs_lanczos_warp() -> None:
    """The tiles' sub-pixel alignment (a separable filter, ~3× faster) gives what
    cv2.warpAffine's Lanczos-4 translation gives: the same 1/32-px fixed-point shift and taps,
    float32 sums in another order (a wrong table or rounding of the shift moves values by
    whole DN on this texture)."""
    from phonestereo.flows.blur_equalise import _shifted

    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(300):
        tile = rng.uniform(0, 255, (66, 66)).astype(np.float32)
        sx, sy = 3 + rng.uniform(-3.5, 3.5, 2)  # r = 3 plus the tile's own offset, ±(r + ½)
        m = np.float32([[1, 0, sx], [0, 1, sy]])
        ref = cv2.warpAffine(tile, m, (60, 60), flags=cv2.INTER_LANCZOS4 | cv2.WARP_INVERSE_MAP,
                             borderMode=cv2.BORDER_REFLECT)
        worst = max(worst, float(np.abs(_shifted(tile, m[0, 2], m[1, 2], 60) - ref).max()))
    # float32 rounding of 64-term sums of values up to 255: measured 2e-4 DN (1e-6 relative)
    assert worst < 1e-3
    # a shift beyond the filter's border is OpenCV's own warp, exactly
    tile = rng.uniform(0, 255, (66, 66)).astype(np.float32)
    m = np.float32([[1, 0, 9.3], [0, 1, -6.2]])
    ref = cv2.warpAffine(tile, m, (60, 60), flags=cv2.INTER_LANCZOS4 | cv2.WARP_INVERSE_MAP,
                         borderMode=cv2.BORDER_REFLECT)
    assert np.array_equal(_shifted(tile, m[0, 2], m[1, 2], 60), ref)
