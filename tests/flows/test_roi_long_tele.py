"""The coarse W-T correlation on a long tele (issue #18: the held-out ×5 module had every
verification capture gated for ZNCC 0.17-0.42): the 3×-ROI context box is larger than a ×5
tele's field (a fifth of the wide's), so the coarse step retries on the ROI box alone."""

from __future__ import annotations

from dataclasses import replace

import pytest

from phonestereo.evaluation.bench import apply_all
from phonestereo.flows.config import FlowConfig
from phonestereo.io import load_capture_set
from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import VerificationConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set


@pytest.mark.slow  # ~15 s alone, 100 s on the shared machine (rendering + matching)
def test_periscope_x5_roi_is_measured(tmp_path) -> None:
    cfg = VerificationConfig(distances_m=(1.3, 3.0), attempts=1)
    plan = plan_scenario("verification", load_module("periscope-x5"), 0, config=cfg)
    write_capture_set(tmp_path, plan)
    cs = load_capture_set(tmp_path)
    res = apply_all(replace(FlowConfig(), learned_correction=False), cs, None)
    gt = load_ground_truth(tmp_path / GROUND_TRUTH_NAME)
    for r in res:
        # Without the retry, 15 of the 18 verification captures of `demo --module
        # periscope-x5` were gated "the ROI does not correlate with the tele (ZNCC 0.29-0.47)";
        # with it 18 of 18 are measured. The uncorrected depth is within the factory
        # calibration's few % (the learned correction is off here; the demo measured 3.3 %).
        assert r.ok, r.reason
        z = gt.capture(r.capture_id).roi_depth_m
        assert abs(r.depth_uncorrected_m / z - 1) < 0.08
