"""The face chart's grid as its plane's ruler (learning/chart_pitch.py, flows' IpdMode.chart)."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.errors import InputError
from phonestereo.flows.learning import IpdMode
from phonestereo.geometry import Camera
from phonestereo.learning.chart_pitch import CHART_PITCH_M, grid_scale
from phonestereo.learning.ipd import fit_face_plane

CAM = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)


def _chart(depth: float, yaw_deg: float, ipd_scale: float) -> np.ndarray:
    """Pupils (8, 2, 2) of the shipped 4 × 2 chart at ``depth`` turned by ``yaw_deg``, every
    IPD drawn ``ipd_scale`` times its printed 63 mm (a detector's inward or outward bias)."""
    t = np.deg2rad(yaw_deg)
    u, v = np.array([np.cos(t), 0.0, np.sin(t)]), np.array([0.0, 1.0, 0.0])
    grid = [(a - 1.5, b - 0.5) for b in range(2) for a in range(4)]
    mids = np.array([[0.0, 0.0, depth] + CHART_PITCH_M * (a * u + b * v) for a, b in grid])
    half = 0.0315 * ipd_scale * u
    return np.asarray(CAM.project(np.stack([mids - half, mids + half], axis=1)))


@pytest.mark.parametrize(("depth", "yaw"), [(1.0, 0.0), (2.0, 12.0), (3.0, -20.0)])
def test_grid_removes_a_detector_ipd_bias(depth: float, yaw: float) -> None:
    # IPDs read 0.4 % short place the IPD plane 0.4 % too far; the midpoints' grid (five or more
    # IPDs long, unmoved by a symmetric bias) puts it back within 0.05 % (measured ≤ 0.021 %: at
    # 20° the plane's tilt from the biased IPDs is a little off, which the scale cannot undo).
    pupils = _chart(depth, yaw, 0.996)
    fit = fit_face_plane(pupils, CAM)
    assert np.median(fit.depth_m) > 1.003 * depth
    scale, pairs = grid_scale(fit.depth_m, pupils, CAM)
    assert pairs == 28  # every pair of the 8 faces lies on the grid
    # the depths of the faces' midpoints, against the truth along each face's ray
    truth = np.array(
        [depth + CHART_PITCH_M * (a - 1.5) * np.sin(np.deg2rad(yaw)) for b in range(2)
         for a in range(4)]
    )
    assert np.max(np.abs(fit.depth_m * scale / truth - 1)) < 5e-4


def test_no_pair_on_the_grid_leaves_the_scale() -> None:
    pupils = _chart(2.0, 0.0, 1.0)[:1]
    assert grid_scale([2.0], pupils, CAM) == (1.0, 0)
    # faces 1.5 pitch apart fit no grid length within 2.5 %
    one = _chart(2.0, 0.0, 1.0)[:1]
    two = np.concatenate([one, one + np.array([365.625, 0.0])])
    assert grid_scale([2.0, 2.0], two, CAM) == (1.0, 0)


def test_chart_mode_takes_the_shipped_pitch_and_refuses_a_short_one() -> None:
    assert IpdMode.chart().pitch_m == CHART_PITCH_M == 0.325
    assert IpdMode.chart(63.0, 0.0).pitch_m is None  # 0: the IPDs alone
    assert IpdMode.population().pitch_m is None
    with pytest.raises(InputError, match="--face-pitch-mm"):
        IpdMode.chart(63.0, 100.0)
