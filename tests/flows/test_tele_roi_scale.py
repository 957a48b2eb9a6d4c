"""The W-T pre-scale of a part of the tele window is the whole-window warp's, bit for bit
(flows/tele_roi_scale.py): the coarse step's choice must not change with the speed-up."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phonestereo.flows.coarse import rescale_tele
from phonestereo.flows.coarse_gate import coarse_peak
from phonestereo.flows.roi_config import RoiConfig
from phonestereo.flows.tele_roi_scale import coarse_reads, fixed_point_maps, scaled_part


def _texture(h: int, w: int, seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (h, w)).astype(np.float32), (0, 0), 1.5)
    return np.clip(img, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("seed", range(6))
def test_a_part_is_the_whole_window_warps(seed: int) -> None:
    rng = np.random.default_rng(seed)
    h, w = (int(v) for v in rng.integers(200, 700, 2))
    img = _texture(h, w, seed)
    scale = float(1 + rng.uniform(-0.04, 0.04))  # periscopes: up to ~4 % (random-1013: 3.7 %)
    center = (float(rng.uniform(0, w)), float(rng.uniform(0, h)))
    whole = rescale_tele(img, scale, center)
    for _ in range(4):
        x0, y0 = int(rng.integers(0, w // 2)), int(rng.integers(0, h // 2))
        x1, y1 = int(rng.integers(x0 + 1, w + 1)), int(rng.integers(y0 + 1, h + 1))
        # exact: a warp of the part with its own origin differs on a few % of the pixels
        assert np.array_equal(scaled_part(img, scale, center, (x0, y0, x1, y1)),
                              whole[y0:y1, x0:x1])


def test_the_maps_take_a_source_origin_and_refuse_a_rotation() -> None:
    img = _texture(300, 400, 7)
    m = np.float32([[0.98, 0, 3.7], [0, 0.98, -2.2]])
    flags = cv2.WARP_INVERSE_MAP | cv2.INTER_CUBIC
    whole = cv2.warpAffine(img, m, (400, 300), flags=flags)
    # the source handed over as a part of the image (every tap of the box inside it)
    xy, a = fixed_point_maps(m, (100, 80, 300, 200), origin=(60, 40))
    part = cv2.remap(img[40:260, 60:360], xy, a, cv2.INTER_CUBIC)
    assert np.array_equal(part, whole[80:200, 100:300])
    with pytest.raises(ValueError, match="axis-aligned"):
        fixed_point_maps(np.float32([[1, 0.01, 0], [0, 1, 0]]), (0, 0, 10, 10))


def test_the_coarse_step_chooses_the_same_with_the_partial_pre_scale() -> None:
    # a 3 % W-T scale about (300, 350) and d = 12 px: the first box's tiles show it and the
    # tele is pre-scaled (coarse_peak); with `partial` only each tried box's strip is
    left = _texture(700, 600, 11)
    m = np.float32([[1 / 1.03, 0, 300 * (1 - 1 / 1.03) + 12], [0, 1 / 1.03, 350 * (1 - 1 / 1.03)]])
    right = cv2.warpAffine(left, m, (600, 700), flags=cv2.WARP_INVERSE_MAP | cv2.INTER_CUBIC)
    boxes = [(120, 100, 360, 500), (200, 250, 200, 200)]
    cfg = RoiConfig()
    whole = coarse_peak(left, right, boxes, 64, cfg, (300.0, 350.0))
    part = coarse_peak(left, right, boxes, 64, cfg, (300.0, 350.0), partial=True)
    assert whole.scale != 1.0 and whole.reason == ""  # the pre-scaled path was taken
    assert (part.box, part.peak, part.contrast, part.scale, part.tile_zncc) == (
        whole.box, whole.peak, whole.contrast, whole.scale, whole.tile_zncc)
    x0, y0, x1, y1 = coarse_reads(part.box, -2, 64, cfg.coarse_rows, (600, 700))
    assert np.array_equal(part.right[y0:y1, x0:x1], whole.right[y0:y1, x0:x1])
    # outside the strip the tele is left as it was (fine_window resamples its part again)
    assert np.array_equal(part.right[:, : x0], right[:, : x0])
