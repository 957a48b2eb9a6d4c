"""A small rendered face-chart capture set for the learning tests (the virtual module's truth)."""

from __future__ import annotations

from pathlib import Path

from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import LearningConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set


def write_face_chart_set(folder: Path, *, attempts: int = 1, seed: int = 5) -> Path:
    """Write ``attempts`` face-chart captures of ``folded-x3`` at 1.5 m, centred (noise on,
    seeded) into ``folder``; returns it."""
    cfg = LearningConfig(distances_m=(1.5,), positions=((0, 0),), attempts=attempts)
    plan = plan_scenario("learning", load_module("folded-x3"), seed=seed, config=cfg)
    write_capture_set(folder, plan)
    return folder
