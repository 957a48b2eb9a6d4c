"""The ROI window's two resamplings (flows/roi_window.py): the matcher reads Lanczos-4 pixels.

The coarse step reads a cubic window; the part the fine matcher and the blur equalisation read
is resampled again with the rectification's default. Every pixel of the matcher's crop (and of
the blur's reach around it) must be exactly the whole-window Lanczos-4 remap's, with and
without the W-T pre-scale, or the fine disparities would change with the speed-up.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phonestereo.features.subpixel import PREFILTER_MARGIN
from phonestereo.flows.coarse import rescale_tele
from phonestereo.flows.roi_config import RoiConfig
from phonestereo.flows.roi_window import (
    FineAhead,
    _fine_part,
    coarse_lazy,
    coarse_window,
    fine_window,
)
from phonestereo.flows.tele_roi_lazy import RIGHT_REACH
from phonestereo.flows.tele_roi_scale import coarse_reads
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.rectification import Rectification, RectifyOptions


def _setup() -> tuple[Rectification, np.ndarray, np.ndarray]:
    wide = Camera((800, 600), 600.0, 600.0, 399.5, 299.5)
    tele = Camera((800, 600), 1800.0, 1800.0, 401.0, 298.0)
    rig = Rig(wide, tele, Transform.from_rotvec([0.002, -0.003, 0.004], [0.0, -0.012, 0.0]))
    # a 3x ROI context box with a 40-px disparity margin, as measure_roi builds it
    opts = RectifyOptions(roi=(200, 150, 400, 300), margin_px=40, grid_step_px=16)
    rect = Rectification.from_rig(rig, "canonical", opts)
    rng = np.random.default_rng(3)
    w = cv2.GaussianBlur(rng.uniform(0, 255, (600, 800)).astype(np.float32), (0, 0), 1.0)
    t = cv2.GaussianBlur(rng.uniform(0, 255, (600, 800)).astype(np.float32), (0, 0), 1.0)
    return rect, w.astype(np.uint8), t.astype(np.uint8)


@pytest.mark.parametrize("scale", [1.0, 1.03])
def test_the_matchers_part_is_the_whole_window_lanczos_remap(scale: float) -> None:
    rect, w, t = _setup()
    W, H = rect.wide_rect.size
    sources = rect.sources(w, t)
    box = (W // 3, H // 3, W // 3, H // 3)  # the expanded ROI inside the 3x context window
    cfg = RoiConfig()
    lw, rt, two_pass = coarse_window(sources, box, 40, cfg)
    assert two_pass  # the fine part is a small share of this window
    d0, e0, center = 12.3, -2.0, (W / 2 + 17.0, H / 2 - 9.0)
    rt_coarse = rescale_tele(rt, scale, center) if scale != 1.0 else rt
    fw, ft = fine_window(sources, lw, rt_coarse, box, d0, e0, scale, center, cfg)
    whole_w, whole_t = rect.remap(w, t)  # Lanczos-4 everywhere
    lo_d, hi_d = int(np.floor(d0)) - cfg.fine_range_px, int(np.ceil(d0)) + cfg.fine_range_px
    x0, y0, x1, y1 = part = _fine_part(box, lo_d, hi_d, e0, cfg, (W, H))
    if scale != 1.0:
        # the fine part is the pre-scale of that part of the Lanczos-4 window, pixel for pixel
        # (fine_window warps it from the tele's part alone, in two row bands)
        part_t = rescale_tele(whole_t, scale, center, part)
        assert np.array_equal(ft[y0:y1, x0:x1], part_t[y0:y1, x0:x1])
        whole_t = rescale_tele(whole_t, scale, center)
    # The matcher's crop for d0 ± fine_range_px and the row band, plus the blur's 12-px reach:
    # every pixel there is the whole-window remap's (fine_window's guard is 16 px).
    ty = max(cfg.match.row_tolerance, int(abs(e0)) + 2)
    reach = cfg.match.radius + ty + 3 + PREFILTER_MARGIN + 12
    x, y, bw, bh = box
    sl = np.s_[y - reach : y + bh + reach, x - hi_d - reach : x + bw - lo_d + reach]
    assert np.array_equal(fw[sl], whole_w[sl])
    if scale == 1.0:
        assert np.array_equal(ft[sl], whole_t[sl])
    else:
        # the pre-scale of a part rounds OpenCV's fixed-point coordinates differently on a few
        # pixels (1/32-px map steps): within a few DN, on < 3 % of the pixels
        diff = np.abs(ft[sl].astype(int) - whole_t[sl].astype(int))
        assert (diff > 0).mean() < 0.03 and diff.max() <= 12
    # outside the part the coarse (cubic, pre-scaled) pixels are left as they were
    outside = np.ones((H, W), bool)
    outside[y0:y1, x0:x1] = False
    assert np.array_equal(fw[outside], lw[outside]) and not np.array_equal(fw, whole_w)
    assert np.array_equal(ft[outside], rt_coarse[outside])


@pytest.mark.parametrize(("scale", "d0", "e0"), [(1.0, 12.3, -2.0), (1.03, 1.2, -6.0),
                                                 (1.03, 30.7, 0.0), (0.98, -1.5, 4.0)])
def test_the_parts_resampled_ahead_give_the_same_pixels(
    scale: float, d0: float, e0: float
) -> None:
    # measure_roi resamples the left's fine part about the box (and, once the coarse step
    # pre-scales the tele, the tele's) before the coarse disparity is known; fine_window then
    # adds the bands d0 and e0 ask for: the same pixels as resampling the whole parts
    rect, w, t = _setup()
    W, H = rect.wide_rect.size
    sources = rect.sources(w, t)
    box = (W // 3, H // 3, W // 3, H // 3)
    cfg = RoiConfig()
    lw, rt, _ = coarse_window(sources, box, 40, cfg)
    center = (W / 2 + 17.0, H / 2 - 9.0)
    rt_coarse = rescale_tele(rt, scale, center) if scale != 1.0 else rt
    ahead = FineAhead(sources, box, cfg, center)
    if scale != 1.0:
        ahead.prescaled(scale)
    assert ahead.left is not None and (scale == 1.0) == (ahead.tele is None)
    fw, ft = fine_window(sources, lw, rt_coarse, box, d0, e0, scale, center, cfg, ahead)
    fw0, ft0 = fine_window(sources, lw, rt_coarse, box, d0, e0, scale, center, cfg)
    assert np.array_equal(fw, fw0) and np.array_equal(ft, ft0)
    # a core chosen for another pre-scale is not used
    other = FineAhead(sources, box, cfg, center)
    other.prescaled(1.01)
    fw1, ft1 = fine_window(sources, lw, rt_coarse, box, d0, e0, scale, center, cfg, other)
    assert np.array_equal(fw1, fw0) and np.array_equal(ft1, ft0)


def test_the_coarse_pair_is_resampled_where_the_coarse_step_reads_only() -> None:
    # measure_roi resamples the cubic pair where the first coarse box is read (the box in the
    # left, its search strip and tiles in the right), the next boxes' parts when they are
    # tried; every pixel read is the whole remap's, the rest zero
    rect, w, t = _setup()
    W, H = rect.wide_rect.size
    sources = rect.sources(w, t)
    box = (W // 3, H // 3, W // 3, H // 3)
    first, second = (W // 4, H // 4, W // 2, H // 2), (W // 3, H // 5, W // 3, H // 2)
    pair = coarse_lazy(sources, box, 40, RoiConfig(), first)
    whole_l, whole_r, two_pass = coarse_window(sources, box, 40, RoiConfig())
    assert pair is not None and two_pass and pair.left.shape == whole_l.shape

    def check(boxes: list[tuple[int, int, int, int]]) -> None:
        read_l, read_r = np.zeros((H, W), bool), np.zeros((H, W), bool)
        for x, y, bw, bh in boxes:
            read_l[y : y + bh, x : x + bw] = True
            x0, y0, x1, y1 = coarse_reads((x, y, bw, bh), -2, 40, RoiConfig().coarse_rows,
                                          (W, H), RIGHT_REACH)
            read_r[y0:y1, x0:x1] = True
        assert np.array_equal(pair.left[read_l], whole_l[read_l]) and not pair.left[~read_l].any()
        assert np.array_equal(pair.right[read_r], whole_r[read_r])
        assert not pair.right[~read_r].any() and read_r.mean() < 0.9

    check([first])
    pair.cover_box(second)
    check([first, second])
    pair.cover_right((0, 0, 10, 12))
    assert np.array_equal(pair.right[:12, :10], whole_r[:12, :10])
