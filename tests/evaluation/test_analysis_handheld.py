"""Handheld analysis (thesis §3.5.3, Figure 3-27): the optimal correction on handheld stacks.

Acceptance (issue #5): runs on its scenario with readable figures; the optimal correction
shrinks the per-corner disparity range of handheld stacks (the thesis: "works very well even
in a handheld scenario"); missing captures → InputError.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import pytest

from phonestereo.errors import InputError
from phonestereo.evaluation.analyses import AnalysisSpec
from phonestereo.evaluation.analyses.handheld import run
from phonestereo.io import load_capture_set, write_manifest
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import HandheldConfig, StackConfig, plan_handheld, plan_scenario
from phonestereo.sim.writer import write_capture_set


@pytest.fixture(scope="module")
def quick_set(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Every effect on, handheld, 3 manual refocus attempts at 1.5 m."""
    folder = tmp_path_factory.mktemp("handheld") / "set"
    write_capture_set(folder, plan_handheld(load_module("folded-x3"), 0, HandheldConfig.quick()))
    return folder


def test_optimal_correction_handheld(quick_set: Path, tmp_path: Path) -> None:
    res = run(quick_set, tmp_path)
    assert res.ok, res.reason
    g = res.table["groups"]["H00"]
    # measured 0.186 → 0.035 px (5.3×) with ~0.3–0.8° / 4–6 mm of true hand motion
    assert g["range_shrink"] > 2.5
    assert g["after"]["median_relative_error_pct"] < 0.5 * g["before"]["median_relative_error_pct"]
    motion = g["truth"]["motion"]
    assert motion[0]["rotation_deg"] == 0.0 and all(m["rotation_deg"] > 0.05 for m in motion[1:])
    assert len(g["fits"]) == 3 and g["fits"][0]["wide"]["ok"]
    assert any("H00" in line and "×" in line for line in res.summary)
    names = sorted(p.name for p in res.files)
    assert names == ["handheld.json", "handheld_ranges.png"]
    img = cv2.imread(str(tmp_path / "handheld_ranges.png"))
    assert img is not None and img.shape[1] > 600
    table = json.loads((tmp_path / "handheld.json").read_text())
    assert "_ranges" not in table["groups"]["H00"]["before"]


def test_refocus_handheld_option_moves_the_device() -> None:
    """StackConfig(handheld=True) turns the refocus scenario into one handheld stack; the
    default stays a tripod (existing behaviour)."""
    spec = load_module("folded-x3")
    tri = plan_scenario("refocus", spec, 0, quick=True).ground_truth()
    hand = plan_scenario("refocus", spec, 0, config=StackConfig(attempts=2, handheld=True))
    assert not any(c.handheld for c in tri.captures)
    assert all(c.handheld for c in hand.ground_truth().captures)


def test_missing_stack_is_an_input_error(quick_set: Path, tmp_path: Path) -> None:
    one = tmp_path / "one"
    shutil.copytree(quick_set, one)
    cs = load_capture_set(one)
    write_manifest(one, cs.manifest.model_copy(update={"captures": list(cs.captures()[:1])}))
    with pytest.raises(InputError, match=r"handheld analysis needs a refocus stack"):
        run(one, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize(
    "isp",
    [
        False,
        pytest.param(
            True,
            marks=pytest.mark.xfail(
                strict=True,
                reason="phone-ISP renders (issue #16): shrink 3.36 / 1.79 / 3.10× (linear "
                "5.5 / 3.51 / 5.63×, seed 0): the ISP's matching bias is not corrected yet",
            ),
        ),
    ],
)
def test_default_scenario(tmp_path: Path, isp: bool) -> None:
    """Three handheld stacks at 1, 1.5, 2.5 m (15 captures): measured ~7 s, shrink 3.5–5.6×."""
    folder = tmp_path / "set"
    spec = load_module("folded-x3")
    spec = spec if isp else spec.with_effects(isp=False)
    write_capture_set(folder, plan_handheld(spec, 0, HandheldConfig()))
    res = run(folder, tmp_path)
    # The analysis reports its own time (~7 s quiet); speed is not asserted in tests (timed
    # unit tests fail under load: 93.7 s at load 14), only that it is recorded.
    assert res.ok and res.table["seconds"] > 0
    assert all(g["range_shrink"] > 2.5 for g in res.table["groups"].values())


def test_registry_entry_loads() -> None:
    spec = AnalysisSpec("handheld", "s", "n", "phonestereo.evaluation.analyses.handheld:run")
    assert spec.load() is run
