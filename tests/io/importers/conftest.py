"""Fixtures of the importer tests: planned scenarios written without rendering, with blank
images of the right sizes (the importers read only the image sizes)."""

from __future__ import annotations

from pathlib import Path

import pytest
from PIL import Image

from phonestereo.io import Calibration, Manifest, load_calibration, load_capture_set
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import plan_scenario
from phonestereo.sim.writer import write_capture_set

ROUND_TRIP_SCENARIOS = ("verification", "thesis-bench", "orientation")


def blank_images(root: Path, names: list[tuple[str, tuple[int, int]]]) -> None:
    """Write black 8-bit PNGs of the given sizes (fast: constant images compress to nothing)."""
    for rel, size in names:
        p = root / rel
        p.parent.mkdir(parents=True, exist_ok=True)
        Image.new("L", size).save(p, compress_level=1)


def write_sim_set(root: Path, scenario: str) -> tuple[Calibration, Manifest]:
    """A quick scenario of folded-x3, seed 0, JSON files and blank images."""
    plan = plan_scenario(scenario, load_module("folded-x3"), 0, quick=True)
    write_capture_set(root, plan, render=False)
    cal = load_calibration(root / "calibration.json")
    cs = load_capture_set(root, check_images=False)
    names = []
    for c in cs.manifest.captures:
        names += [(c.wide, cal.rig.wide.size), (c.tele, cal.rig.tele.size)]
    blank_images(root, names)
    return cal, cs.manifest


@pytest.fixture(scope="module", params=ROUND_TRIP_SCENARIOS)
def sim_set(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A written quick scenario (verification, thesis-bench, orientation)."""
    root = tmp_path_factory.mktemp(request.param) / "native"
    write_sim_set(root, request.param)
    return root


@pytest.fixture(scope="session")
def write_sim() -> object:
    """The :func:`write_sim_set` helper, as a fixture (tests are not a package)."""
    return write_sim_set
