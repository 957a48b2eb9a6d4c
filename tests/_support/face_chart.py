"""A small rendered face-chart capture set for the learning tests (the virtual module's truth)."""

from __future__ import annotations

import json
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


def tele_principal_point_off(folder: Path, axis: int, delta_px: float, name: str) -> Path:
    """A copy of the set's calibration, named ``name`` beside ``folder``, whose tele principal
    point is ``delta_px`` off along ``axis`` (0: c_x, 1: c_y); returns its path."""
    cal = json.loads((folder / "calibration.json").read_text())
    cal["tele"]["K"][axis][2] += delta_px
    path = folder.parent / name
    path.write_text(json.dumps(cal))
    return path
