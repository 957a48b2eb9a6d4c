"""Scenarios planned per module (issue #18 item 2): the face and verification charts fall where
both cameras see them, the presets' bench is unchanged, and what a module cannot cover is said."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.cli.demo import QUICK
from phonestereo.sim.coverage import BLUR_BUDGET_PX, tele_blur_px
from phonestereo.sim.ground_truth import GroundTruth
from phonestereo.sim.module import ModuleSpec, load_module
from phonestereo.sim.random_module import random_module
from phonestereo.sim.scenarios import BenchConfig, plan_scenario


def _faces_in_both(plan) -> list[int]:
    """Per face capture: faces with both pupils inside the wide and the tele."""
    out = []
    for c in plan.captures:
        if c.state.conditions.kind != "face":
            continue
        t = c.truth.objects[0].keypoints["pupils"].arrays()
        both = np.isfinite(t.tele_px).all(1) & np.isfinite(t.wide_px).all(1)
        out.append(int(both.reshape(-1, 2).all(axis=1).sum()))
    return out


def _circles_in_tele(plan) -> list[float]:
    """Per verification capture: the fraction of circle-pair centres inside the tele."""
    out = []
    for c in plan.captures:
        if c.state.conditions.kind == "verification":
            t = c.truth.objects[0].keypoints["circles"].arrays()
            out.append(float(np.isfinite(t.tele_px).all(axis=1).mean()))
    return out


@pytest.mark.parametrize("preset", ["folded-x3", "nonfolded-x2"])
@pytest.mark.parametrize("config", [QUICK, BenchConfig()], ids=["quick", "full"])
def test_presets_keep_the_thesis_bench(preset: str, config: BenchConfig) -> None:
    # Their bench already fits: same distances, same focus, no notes (so folded-x3's bench
    # numbers cannot move).
    plan = plan_scenario("thesis-bench", load_module(preset), 0, config=config)
    assert plan.notes == ()
    for pc in plan.captures:
        c = pc.state.conditions
        assert c.focus_m == 1.5
    ver = [pc.truth.roi_depth_m for pc in plan.captures
           if pc.state.conditions.kind == "verification"]
    # The ROI depth is the chart distance within the 4° tilt over the ROI (< 5 cm).
    planned = np.repeat(config.verification.distances_m, config.verification.attempts)
    assert ver == pytest.approx(planned, abs=0.05)


def test_periscope_x5_faces_farther_and_a_range_that_fits() -> None:
    plan = plan_scenario("thesis-bench", load_module("periscope-x5"), 0, config=QUICK)
    # On main, 5 of the 15 face captures (the 1 m ones) had no face with both pupils in the
    # tele; planned for the x5, every face capture has at least one.
    assert min(_faces_in_both(plan)) >= 1
    assert min(_circles_in_tele(plan)) == 1.0  # every circle pair in the tele at 0.9-4 m
    text = " | ".join(plan.notes)
    assert "faces planned at 1.65-3 m" in text and "cannot cover faces nearer than 1.63 m" in text
    assert "verification chart planned at 0.9-4 m" in text
    gt = GroundTruth.model_validate(plan.ground_truth().model_dump())
    assert gt.notes == list(plan.notes)  # written into ground_truth.json


SEEDS = [pytest.param(s, marks=[] if s % 4 == 0 else [pytest.mark.slow]) for s in range(1000, 1020)]


@pytest.mark.parametrize("seed", SEEDS)  # ~5 s each: every 4th seed unless -m slow
def test_random_modules_see_faces_and_circles(seed: int) -> None:
    spec: ModuleSpec = random_module(seed)
    plan = plan_scenario("thesis-bench", spec, 0, config=QUICK)
    faces = _faces_in_both(plan)
    # A face in both cameras on >= 80 % of the face captures (hand shake and the ±0.5
    # sensor positions may push the one whole face out of the tele on a few).
    assert np.mean(np.array(faces) > 0) >= 0.8, faces
    assert np.mean(_circles_in_tele(plan)) >= 0.95
    rois = [pc.roi for pc in plan.captures if pc.state.conditions.kind == "verification"]
    assert all(r is not None for r in rois)
    # The tele's blur at each verification chart stays within the budget (one focus or per
    # stack), up to the autofocus/lens-position noise the capture adds on top.
    for pc in plan.captures:
        c = pc.state.conditions
        if c.kind == "verification":
            z = pc.truth.roi_depth_m
            assert tele_blur_px(spec, c.focus_m, z) <= BLUR_BUDGET_PX + 1e-9


def test_faces_take_the_verification_focus_regime() -> None:
    # random-1013's ×4.2 periscope needs each verification stack focused on its chart (one
    # manual focus would blur the tele by 33 px). Its faces, learned at one manual focus
    # (1.81 m), taught the correction nothing of the tele's principal-point shift with focus,
    # and the application's 0.8-4 m focus states turned it into a 2.7 % gain error (median
    # 1.08 %); with the faces focused per stack too: 0.15 % (docs/module-random.md, session
    # 12). So the planner focuses both alike.
    plan = plan_scenario("thesis-bench", random_module(1013), 1013, config=QUICK)
    faces = [pc for pc in plan.captures if pc.state.conditions.kind == "face"]
    ver = [pc for pc in plan.captures if pc.state.conditions.kind == "verification"]
    assert {round(pc.state.conditions.focus_m, 2) for pc in ver} == {
        round(d, 2) for d in QUICK.verification.distances_m}
    # each face stack is focused on its own chart: three focus states, one per distance
    assert len({pc.state.conditions.focus_m for pc in faces}) == len(QUICK.learning.distances_m)
    assert any("one focus regime" in n for n in plan.notes)
    # a module whose verification chart keeps one focus keeps it for the faces too (1002)
    plan = plan_scenario("thesis-bench", random_module(1002), 1002, config=QUICK)
    assert {pc.state.conditions.focus_m for pc in plan.captures} == {1.5}


def test_heated_start_follows_the_module_warm_up() -> None:
    # the presets (τ = 70 s) keep their 300 s start: 1.4 % of the drift to come, within the
    # 1.5 % that "heated" allows; a module that warms with τ = 118 s starts at 4.2 τ instead
    # (at 300 s 7.9 % would still be to come, learned by near-to-far faces as a gain)
    from phonestereo.sim.coverage import HEATED_DRIFT_LEFT, heated_start_s

    notes: list[str] = []
    folded = load_module("folded-x3")
    assert heated_start_s(folded, 300.0, notes) == 300.0 and notes == []
    slow = folded.model_copy(update={"heating": folded.heating.model_copy(update={"tau_s": 118.0})})
    start = heated_start_s(slow, 300.0, notes)
    assert np.exp(-start / 118.0) <= HEATED_DRIFT_LEFT < np.exp(-(start - 1.0) / 118.0)
    assert len(notes) == 1 and "τ = 118 s" in notes[0]
    # without the heating effect there is nothing to wait for
    assert heated_start_s(slow.with_effects(heating=False), 300.0, []) == 300.0
    # the thesis bench's first face capture is at the heated start
    plan = plan_scenario("thesis-bench", slow, 0, config=QUICK)
    first = min(c.state.conditions.time_s for c in plan.captures)
    assert first == start, first
