"""The rectification's resampling must not bias disparities (real Middlebury-Q data).

The right image of Adirondack is resampled by the product's :func:`maps.remap_image` through a
0.1° roll about its centre (the fractional offsets a rectification gives), the ground truth is
mapped alike, and the sparse matcher's median |d − d_true| is compared with the aligned pair's.
A bilinear resampling of one image low-passes it by an amount that depends on each sample's
sub-pixel phase, and that moves d: this is why the default is Lanczos-4
(maps.DEFAULT_INTERPOLATION).
"""

from __future__ import annotations

import numpy as np
import pytest

from _support import match_imperfect as mi
from _support import stereo_eval as bench
from phonestereo.features.matching import match_rectified
from phonestereo.rectification import maps

pytestmark = pytest.mark.skipif(not bench.DATA.exists(), reason="shared/data not beside the clone")


def _rolled_median(interpolation: str | None) -> float:
    left, right, gt, ndisp = bench.load_middlebury("Adirondack")
    h, w = right.shape
    t = np.deg2rad(0.1)
    a = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
    c = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    inv = np.linalg.inv(a)  # rolled pixel p' = A (p − c) + c  ⇒  source p = A⁻¹ (p' − c) + c
    map_x = (inv[0, 0] * (xs - c[0]) + inv[0, 1] * (ys - c[1]) + c[0]).astype(np.float32)
    map_y = (inv[1, 0] * (xs - c[0]) + inv[1, 1] * (ys - c[1]) + c[1]).astype(np.float32)
    kw = {} if interpolation is None else {"interpolation": interpolation}
    rolled = maps.remap_image(right, map_x, map_y, 1.0, **kw)
    _, d_true, _ = mi.misaligned(right, gt, 0.0, 0.1)  # the same roll: the GT mapped alike
    res = match_rectified(left, rolled, max_disparity=ndisp)
    xi = np.rint(res.xy).astype(np.int64)
    dt = d_true[xi[:, 1], xi[:, 0]]
    ok = np.isfinite(dt)
    return float(np.median(np.abs(res.d - dt)[ok]))


def test_default_resampling_keeps_the_aligned_accuracy() -> None:
    aligned = mi.evaluate("Adirondack", 0.0, 0.0)["median_abs_err_px"]
    default = _rolled_median(None)
    linear = _rolled_median("linear")
    # measured: aligned 0.0188 px; rolled with Lanczos-4 (the default) 1.05×, bilinear 1.95×. The
    # bound 1.2× is issue #18's "median no worse than 1.2× the aligned pair's"; bilinear must
    # read clearly worse, or the default's reason (maps.DEFAULT_INTERPOLATION) is gone.
    assert default <= 1.2 * aligned, (default, aligned)
    assert linear >= 1.5 * aligned, (linear, aligned)
