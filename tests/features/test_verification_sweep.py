"""Full-size robustness sweep of verification-chart detection (slow; `make bench` runs it).

The wide (2000 × 1500, f = 1500 px, the folded-x3 odd-order distortion) and the tele (f = 4500
px, the central part of the chart only) at 0.8–4 m, tilted 0–60° about a random axis, rolled
±30°, with sensor noise, defocus blur (σ ≤ 1.5 px) and uneven light. Every detection must carry
correct labels; the detection rate is measured and printed (run with ``-s`` to see it).
"""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.charts.verification import VerificationChart
from phonestereo.features.verification import detect_verification_chart
from phonestereo.geometry import Camera, Transform, make_lens
from phonestereo.sim.render import render_view
from phonestereo.sim.scene import Lighting, PlanarObject, Scene, facing_pose
from phonestereo.sim.sensor import capture

CHART = VerificationChart()
COLS = CHART.pattern[0]
WIDE_LENS = make_lens("radial-odd", [0.006, -0.07, 0.03, 0.01, 0.0004, -0.0003])


def _case(rng: np.random.Generator, f: float, dist: float, tilt_deg: float) -> tuple:
    w, h = 2000, 1500
    lens = WIDE_LENS if f < 2000 else None
    cam = Camera((w, h), f, f, (w - 1) / 2, (h - 1) / 2, **({"lens": lens} if lens else {}))
    az = rng.uniform(0, 2 * np.pi)
    roll = np.radians(rng.uniform(-30, 30))
    tilt = np.radians(tilt_deg) * np.array([np.cos(az), np.sin(az), 0.0]) + [0, 0, roll]
    centre = rng.uniform(-0.1, 0.1, 2) if f > 2000 else rng.uniform(-0.1, 0.1, 2) * dist
    blur = float(rng.uniform(0.0, 1.5))
    T = facing_pose(CHART.size_m, dist, tilt_rad=tilt, center_m=centre)
    light = Lighting(gradient=(0.3, -0.2), vignetting=0.3)
    scene = Scene((PlanarObject(CHART, T),), background=0.5, lighting=light)
    rad = render_view(cam, Transform.identity(), scene, defocus_sigma_px=lambda z: blur).radiance
    uv = CHART.corners_uv()
    return capture(rad, rng), cam.project(T.apply(np.c_[uv, np.zeros(len(uv))])), cam


@pytest.mark.slow
@pytest.mark.parametrize("f", [1500.0, 4500.0], ids=["wide", "tele"])
def test_sweep_never_mislabels_and_detects_most(f: float) -> None:
    rng = np.random.default_rng(7 if f < 2000 else 8)
    found = total = 0
    corners = visible = 0
    worst = 0.0
    for dist in (0.8, 1.5, 2.5, 4.0):
        for tilt in (0.0, 30.0, 45.0, 60.0):
            img, truth, cam = _case(rng, f, dist, tilt)
            det = detect_verification_chart(img)
            total += 1
            visible += int(cam.contains(truth, 5.0).sum())
            if not det.found:
                assert det.reason  # rejected with a reason
                continue
            found += 1
            corners += len(det.ids)
            err = np.hypot(*(det.points - truth[det.ids[:, 0] * COLS + det.ids[:, 1]]).T)
            worst = max(worst, float(err.max()))
    print(
        f"\nf={f:.0f}: detected {found}/{total}, corners {corners}/{visible}, worst {worst:.3f} px"
    )
    assert worst < 0.5  # never a wrong label (that is ≥ 1 square, ≥ 4 px here)
    # measured 15–16 of 16 (the misses: circles < 1.5 px across at 2.5–4 m and 60°)
    assert found >= 13


@pytest.mark.slow
def test_tele_partial_views_are_labelled_or_rejected() -> None:
    """The tele slid over the chart: whatever part it sees is labelled right or rejected."""
    rng = np.random.default_rng(3)
    found = 0
    for cx in (-0.25, -0.15, -0.05, 0.05, 0.15, 0.25):
        for cy in (-0.15, 0.0, 0.15):
            w, h = 2000, 1500
            cam = Camera((w, h), 4500.0, 4500.0, (w - 1) / 2, (h - 1) / 2)
            T = facing_pose(CHART.size_m, 0.8, tilt_rad=(0.1, -0.15, 0.1), center_m=(cx, cy))
            rad = render_view(cam, Transform.identity(), Scene((PlanarObject(CHART, T),))).radiance
            det = detect_verification_chart(capture(rad, rng))
            if det.found:
                found += 1
                uv = CHART.corners_uv()
                truth = cam.project(T.apply(np.c_[uv, np.zeros(len(uv))]))
                err = np.hypot(*(det.points - truth[det.ids[:, 0] * COLS + det.ids[:, 1]]).T)
                assert err.max() < 0.5, (cx, cy, err.max())
            else:
                assert det.reason
    print(f"\ntele partial views detected: {found}/18")
    assert found >= 6  # views that hold two or more circles
