"""Sparse matching on pairs rendered by the virtual module: honest σ and no pixel locking.

The renderer area-samples a smooth random texture on planes (sim/render.py), the sensor adds
shot + read noise and quantises to 8 bits; the true left disparity is f·B/Z at every pixel.
The helpers are shared with benchmarks/bench_match.py (tests/_support/stereo_eval.py), so
tests and benchmark measure the same thing.
"""

from __future__ import annotations

import numpy as np
import pytest

import _support.stereo_eval as bench
from phonestereo.features.matching import match_rectified


def _errors(planes, size=(320, 240), max_d=32, seed=0):
    left, right, d_true = bench.render_pair(planes, size=size, seed=seed)
    res = match_rectified(left, right, max_disparity=max_d)
    xi = np.rint(res.xy).astype(int)
    return res, res.d - d_true[xi[:, 1], xi[:, 0]]


@pytest.mark.parametrize("tilt", [(0.0, 0.0, 0.0), (0.0, 0.5, 0.0)])
def test_sigma_is_honest_on_rendered_planes(tilt: tuple[float, float, float]) -> None:
    res, err = _errors([(16.3, tilt, (0.0, 0.0))])
    assert len(res) > 1000
    frac = float(np.mean(np.abs(err) <= res.sigma_d))
    # acceptance: |d − d_GT| / σ_d ≤ 1 for 68 % ± 10 % of the matches (measured 0.66–0.67)
    assert 0.58 <= frac <= 0.78, frac
    assert np.median(np.abs(err)) < 0.02  # px, shot noise ≈ 2 DN on a 40 DN texture


def test_scene_with_two_depths() -> None:
    planes = [(14.0, (0.0, 0.3, 0.0), (0.0, 0.0)), (25.0, (0.0, 0.0, 0.0), (0.03, 0.0))]
    res, err = _errors(planes, max_d=32, seed=2)
    assert len(res) > 800
    assert np.mean(np.abs(err) <= 0.5) > 0.99  # occlusion edges are filtered, not smeared
    assert np.median(np.abs(err)) < 0.02


@pytest.mark.parametrize("fractions", [[0.0, 0.25, 0.5, 0.75]])
def test_no_pixel_locking_on_rendered_pairs(fractions: list[float]) -> None:
    out = bench.pixel_locking(np.array(fractions), size=(200, 150))
    # acceptance ≤ 0.02 px at every fraction; measured ≤ 0.002 px (standard error 0.0005)
    assert np.max(np.abs(out["bias_px"])) <= 0.01, out


@pytest.mark.slow
def test_pixel_locking_full_sweep() -> None:
    out = bench.pixel_locking(np.round(np.arange(0.0, 1.0, 0.1), 2))
    assert np.max(np.abs(out["bias_px"])) <= 0.02, out
