"""Rectification.remap blurs and samples only the raw box its maps reach: bit-identical output.

A window rectification (an ROI) of a ×3 tele samples a part of the raw tele; blurring the whole
12 MP tele against aliasing cost ~10 ms of CPU per remap for nothing. The box must hold every
interpolation tap plus the blur kernel, or pixels near it change: compared exactly here with
``maps.remap_image`` on the whole image.
"""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.rectification import Rectification, RectifyOptions, maps


def _rig() -> Rig:
    wide = Camera((800, 600), 600.0, 600.0, 399.5, 299.5)
    tele = Camera((800, 600), 1800.0, 1800.0, 401.0, 298.0)
    return Rig(wide, tele, Transform.from_rotvec([0.002, -0.003, 0.004], [0.0, -0.012, 0.0]))


@pytest.mark.parametrize("dtype", [np.uint8, np.float32])
@pytest.mark.parametrize("interpolation", ["lanczos4", "linear"])
@pytest.mark.parametrize("roi", [(340, 250, 60, 50), (300, 200, 200, 150), None])
def test_remap_equals_the_whole_image_remap(dtype: type, interpolation: str, roi: tuple | None
                                            ) -> None:
    rig = _rig()
    opts = RectifyOptions(roi=roi, margin_px=20) if roi is not None else RectifyOptions()
    rect = Rectification.from_rig(rig, "canonical", opts)
    rng = np.random.default_rng(0)
    wide = rng.integers(0, 256, (600, 800)).astype(dtype)
    tele = rng.integers(0, 256, (600, 800)).astype(dtype)
    lw, rt = rect.remap(wide, tele, interpolation=interpolation)
    shrink = rig.tele.f / rect.tele_rect.f
    assert shrink > 2.9  # the tele is blurred before it is shrunk
    whole_w = maps.remap_image(wide, *rect.maps_wide(), rig.wide.f / rect.wide_rect.f,
                               True, interpolation)
    whole_t = maps.remap_image(tele, *rect.maps_tele(), shrink, True, interpolation)
    # Exact: the same OpenCV arithmetic on the same pixels, only fewer of them.
    assert np.array_equal(lw, whole_w)
    assert np.array_equal(rt, whole_t)
    box = rect._source("tele", shrink, (800, 600))[0]
    if roi is not None and roi[2] < 100:  # a small window reads a part of the tele only
        assert (box[2] - box[0]) * (box[3] - box[1]) < 0.5 * 800 * 600


def test_antialias_sigma_is_remap_images_rule() -> None:
    # Rectification.remap sizes its box with maps.antialias_sigma; remap_image must blur with
    # the same σ (a Gaussian of that σ applied by hand gives the same image).
    import cv2

    img = np.random.default_rng(1).integers(0, 256, (60, 80)).astype(np.uint8)
    ident = np.meshgrid(np.arange(80, dtype=np.float32), np.arange(60, dtype=np.float32))
    s = maps.antialias_sigma(3.0)
    by_hand = cv2.GaussianBlur(img, (0, 0), sigmaX=s, sigmaY=s)
    assert np.array_equal(maps.remap_image(img, *ident, 3.0, True, "linear"), by_hand)
    assert maps.antialias_sigma(1.0) == 0.0


@pytest.mark.parametrize("interpolation", ["lanczos4", "cubic"])
def test_source_parts_equal_the_whole_remap(interpolation: str) -> None:
    # Rectification.sources + Source.remap(box=...): the ROI flow resamples its window twice
    # (cubic for the coarse step, Lanczos-4 for the matcher's part, flows/roi_window.py); a
    # part must be exactly the same pixels as the whole window's remap there (cv2.remap treats
    # every output pixel on its own).
    rig = _rig()
    rect = Rectification.from_rig(rig, "canonical", RectifyOptions(roi=(300, 200, 200, 150),
                                                                   margin_px=20))
    rng = np.random.default_rng(2)
    wide = rng.integers(0, 256, (600, 800)).astype(np.uint8)
    tele = rng.integers(0, 256, (600, 800)).astype(np.uint8)
    lw, rt = rect.remap(wide, tele, interpolation=interpolation)
    src_w, src_t = rect.sources(wide, tele)
    assert np.array_equal(src_w.remap(interpolation), lw)
    assert np.array_equal(src_t.remap(interpolation), rt)
    box = (13, 7, 101, 66)  # (x0, y0, x1, y1)
    assert np.array_equal(src_w.remap(interpolation, box), lw[7:66, 13:101])
    assert np.array_equal(src_t.remap(interpolation, box), rt[7:66, 13:101])
