"""The demosaicer's grid-locked error and the CFA filter of the matcher (features/cfa.py, #16).

Two pairs with ground truth independent of each other: a plane rendered through the virtual
module's ISP with only the demosaicer's stages on (no noise, denoise, sharpening or JPEG), and
Middlebury-Q colour pairs re-mosaiced on RGGB and demosaiced by OpenCV (the real-data judge: the
effect is the demosaicer's, not the renderer's).
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import _support.stereo_eval as bench
from _support import match_isp
from phonestereo.features.cfa import cfa_phase_contrast, suppress_cfa
from phonestereo.features.matching import MatchConfig, match_rectified

needs_data = pytest.mark.skipif(not bench.DATA.exists(), reason="shared/data not beside the clone")


def _remosaic(bgr: np.ndarray) -> np.ndarray:
    """A colour image sampled on an RGGB mosaic, demosaiced by OpenCV's EA, to grey."""
    m = np.empty(bgr.shape[:2], np.uint8)
    m[0::2, 0::2], m[1::2, 1::2] = bgr[0::2, 0::2, 2], bgr[1::2, 1::2, 0]
    m[0::2, 1::2], m[1::2, 0::2] = bgr[0::2, 1::2, 1], bgr[1::2, 0::2, 1]
    bgr = cv2.demosaicing(m, cv2.COLOR_BayerRGGB2BGR_EA)
    return np.asarray(cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))


def _demosaic_only_pair(d: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A fronto-parallel plane at disparity d through CFA + EA demosaic + tone curve only."""
    from phonestereo.sim.isp import IspSpec, apply_isp
    from phonestereo.sim.render import render_view
    from phonestereo.sim.sensor import SensorModel

    plane = (d, (0.0, 0.0, 0.0), (0.0, 0.0))
    scene, cam, poses, d_true = match_isp.bench_scene([plane], (320, 240), 0)
    spec = IspSpec(denoise_strength=0.0, sharpen_amount=0.0, jpeg_quality=None)
    rng = np.random.default_rng(0)
    imgs = [
        cv2.cvtColor(
            apply_isp(render_view(cam, p, scene).radiance, spec, SensorModel(), rng, noise=False),
            cv2.COLOR_BGR2GRAY,
        )
        for p in poses
    ]
    return imgs[0], imgs[1], d_true


@pytest.mark.parametrize(("d", "sign"), [(16.5, -1.0), (17.5, 1.0)])
def test_filter_removes_the_pull_to_even_disparities(d: float, sign: float) -> None:
    left, right, d_true = _demosaic_only_pair(d)
    assert min(cfa_phase_contrast(left), cfa_phase_contrast(right)) > 0.4  # measured 0.6–0.9

    def bias(cfa: bool) -> float:
        res = match_rectified(
            left, right, max_disparity=32, config=MatchConfig(cfa_filter=cfa, noise_sigma=0.5)
        )
        assert res.cfa_filtered == cfa and len(res) > 1500  # measured 1851–1891
        xi = np.rint(res.xy).astype(int)
        return float(np.median(res.d - d_true[xi[:, 1], xi[:, 0]]))

    # without the filter d is pulled toward the nearest even value: measured −0.035 at 16.5 and
    # +0.035 at 17.5 (noise-free, so this is all bias); with it −0.0016 / +0.0017. 0.005 px is
    # a quarter of the ISP renders' median σ_d.
    assert sign * bias(False) > 0.025
    assert abs(bias(True)) < 0.005


@needs_data
@pytest.mark.parametrize(("scene", "before"), [("Adirondack", -0.040), ("Piano", -0.085)])
def test_remosaiced_middlebury_pull_shrinks(scene: str, before: float) -> None:
    """err ≈ A·sin(π·d_GT) + B·cos(π·d_GT) + C over the matches within 0.5 px of the GT."""
    left, right, gt, ndisp = bench.load_middlebury(scene)
    folder = bench.DATA / f"middeval3_Q_{scene}"
    pair = [_remosaic(cv2.imread(str(folder / f"im{i}.png"))) for i in (0, 1)]
    # the original quarter-size images have no CFA phase left (measured 0.012–0.019), the
    # re-mosaiced ones do (0.63–0.67)
    assert max(cfa_phase_contrast(left), cfa_phase_contrast(right)) < 0.05
    assert min(cfa_phase_contrast(p) for p in pair) > 0.4

    def amplitude(cfa: bool) -> float:
        res = match_rectified(*pair, max_disparity=ndisp, config=MatchConfig(cfa_filter=cfa))
        g = bench.gt_at(gt, res.xy)
        err = res.d - g
        ok = np.isfinite(g) & (np.abs(err) <= 0.5)
        a = np.column_stack([np.sin(np.pi * g), np.cos(np.pi * g), np.ones_like(g)])[ok]
        return float(np.linalg.lstsq(a, err[ok], rcond=None)[0][0])

    # measured A without / with the filter: Adirondack −0.040 / −0.016, Piano −0.085 / −0.037:
    # the demosaicer's pull is real and the filter removes more than half of it (the rest sits
    # in mid frequencies no filter separates from the texture)
    a0, a1 = amplitude(False), amplitude(True)
    assert a0 == pytest.approx(before, abs=0.01)
    assert abs(a1) < 0.5 * abs(a0)


def test_suppress_cfa_noise_factors() -> None:
    rng = np.random.default_rng(0)
    noise = rng.normal(0.0, 2.0, (300, 300)).astype(np.float32)
    tex = cv2.GaussianBlur(rng.normal(0.0, 40.0, (300, 300)).astype(np.float32), (0, 0), 1.5)
    _, _, g, sf = suppress_cfa(tex + noise, tex + noise, (2.0, 2.0))
    # the filtered noise per pixel is σ·Σk² = 0.375·σ (measured on pure noise to 1 %)
    pure, _, _, _ = suppress_cfa(noise, noise, (2.0, 2.0))
    assert float(pure[5:-5, 5:-5].std()) == pytest.approx(2.0 * g, rel=0.02)
    # on a smooth texture the shift sees most of the low-frequency noise: √ρ well above Σk²
    assert g < sf[0] <= 1.0
