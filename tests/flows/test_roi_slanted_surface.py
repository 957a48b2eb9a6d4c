"""The ROI's disparity surface on a slanted disparity field (issue #18, random-1011).

random-1011's ×3.93 periscope breathes 1.7 % at focus, so before the W-T scale the chart's
disparity runs 0.012 px per px across the ROI box (5 px over it). The majority vote kept a
constant-disparity band (±0.75 px): a strip ~130 px wide whose place moved from capture to
capture, and the plane extrapolated its slope over the ROI — matcher errors of −0.25 … +0.16 px
at the ROI against a claimed σ of ~0.02 px (`benchmarks/bench_oracle.py`: SD 0.11 px over the 18
captures of the kept render). The selection now follows the plane, and the surface has
quadratic terms for the factory rectification's curvature.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from phonestereo.evaluation.module_bench import demo_quick_config
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.roi_disparity import measure_roi, reference_rectification
from phonestereo.io import load_calibration, load_capture_set, read_gray
from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth
from phonestereo.sim.random_module import load_ranges, random_module
from phonestereo.sim.scenarios import plan_scenario
from phonestereo.sim.writer import write_capture_set

# The three captures with the largest errors before (px at the ROI: −0.25, −0.15, −0.20).
CAPTURES = ("V01_1", "V04_1", "V06_1")


@pytest.mark.slow  # ~10 s alone (three 3040 × 2280 renders); much more on a loaded machine
def test_random_1011_surface_error_at_the_roi(tmp_path) -> None:
    spec = random_module(1011, load_ranges())
    # OpenCV 4.11's VNG demosaic (this module's tele) shifts its output 2 rows
    # (opencv/opencv#27225), a constant +0.28 px that is not the matcher's: edge-aware instead.
    tele = spec.tele.model_copy(update={"isp": spec.tele.isp.model_copy(update={"demosaic": "ea"})})
    spec = spec.model_copy(update={"tele": tele})
    plan = plan_scenario("thesis-bench", spec, 1011, config=demo_quick_config())
    plan = replace(plan, captures=tuple(
        c for c in plan.captures if c.state.conditions.id in CAPTURES))
    write_capture_set(tmp_path, plan)
    cs = load_capture_set(tmp_path)
    cal = load_calibration(cs.calibration_path())
    gt = load_ground_truth(tmp_path / GROUND_TRUTH_NAME)
    cfg = FlowConfig()
    ref = reference_rectification(cal.rig, cfg.mode)
    for c in cs.captures():
        kp = gt.capture(c.id).objects[0].keypoints["corners"].arrays()
        x, y, w, h = c.roi
        qw, qt = kp.wide_px, kp.tele_px
        inside = (np.isfinite(qw).all(1) & np.isfinite(qt).all(1) & (qw[:, 0] >= x)
                  & (qw[:, 0] <= x + w) & (qw[:, 1] >= y) & (qw[:, 1] <= y + h))
        wide, tele_img = (read_gray(p) for p in cs.image_paths(c.id))
        m = measure_roi(cal.rig, wide, tele_img, c.roi, cfg.roi, ref, mode=cfg.mode,
                        wt_scale=False)
        assert m.ok and m.plane is not None, m.reason
        q = ref.points_wide(qw[inside])
        d_true, _ = ref.disparity(qw[inside], qt[inside])
        d, sd = m.plane.predict(q)
        err, sigma = float(np.median(d - d_true)), float(np.median(sd))
        # The matcher's error at the chart's true corners in the ROI: 0.15-0.25 px on these
        # captures before, ≤ 0.02 px after (SD 0.013 px over all 18). 0.06 px is a third of the
        # smallest error before; and within 4σ of its own claim (issue #18's bound).
        assert abs(err) < 0.06, (c.id, err)
        assert abs(err) <= 4 * sigma, (c.id, err, sigma)
