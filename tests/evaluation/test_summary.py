"""Stage scoring of a simulated capture set (the table `phonestereo demo` prints)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from phonestereo.evaluation.summary import score_capture_set
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import VerificationConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set


def test_naive_stage_scored_per_distance(tmp_path: Path) -> None:
    cfg = VerificationConfig(distances_m=(1.0, 2.0, 4.0), attempts=2)
    plan = plan_scenario("verification", load_module("folded-x3"), 3, config=cfg)
    write_capture_set(tmp_path, plan, render=False)
    scores = score_capture_set(tmp_path)
    assert scores["captures"] == 6
    naive = scores["stages"]["naive"]
    # docs/architecture.md: the naive formula on the factory calibration is ~30 % off at 1–4 m.
    assert 0.1 < naive["median_rel_err"] < 0.5
    per = {
        row["distance_m"]: row["stages"]["naive"]["median_rel_err"]
        for row in scores["per_distance"]
    }
    assert sorted(per) == [1.0, 2.0, 4.0]
    # A disparity offset (heating drift) hurts more with distance: error grows with Z.
    assert np.all(np.diff([per[1.0], per[2.0], per[4.0]]) > 0)
