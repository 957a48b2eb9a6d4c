"""Scenario plans and their ground truth, without rendering (docs/architecture.md)."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.errors import InputError
from phonestereo.io import load_capture_set
from phonestereo.sim.ground_truth import ground_truth_json, load_ground_truth
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import (
    SCENARIOS,
    HeatingConfig,
    StackConfig,
    plan_scenario,
)
from phonestereo.sim.writer import write_capture_set

SPEC = load_module("folded-x3")
QUICK_COUNTS = {
    "heating": 4,
    "refocus": 2,
    "orientation": 2,
    "dual-depth": 2,
    "handheld": 3,
    "learning": 4,
    "verification": 4,
    "thesis-bench": 8,
    "calibration": 6,
    "calibration-3plane": 1,
}


def _both(kp):
    return np.isfinite(kp.wide_px).all(axis=1) & np.isfinite(kp.tele_px).all(axis=1)


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_every_scenario_plans_and_writes_a_valid_set(name, tmp_path) -> None:
    plan = plan_scenario(name, SPEC, 0, quick=True)
    assert len(plan.captures) == QUICK_COUNTS[name]
    result = write_capture_set(tmp_path, plan, render=False)
    cs = load_capture_set(tmp_path, check_images=False)  # the io contract validates it
    assert [c.id for c in cs.captures()] == [pc.state.id for pc in plan.captures]
    assert result.captures == len(plan.captures) and not result.rendered
    gt = load_ground_truth(tmp_path)
    assert gt.scenario == name and [c.id for c in gt.captures] == [c.id for c in cs.captures()]
    # The module does not report temperature: the manifest has none, the ground truth has it.
    assert all(c.temperature_c is None for c in cs.captures())
    assert all(c.temperature_c >= 25.0 for c in gt.captures)


def test_same_seed_same_plan_other_seed_other_plan() -> None:
    a = ground_truth_json(plan_scenario("verification", SPEC, 5, quick=True).ground_truth())
    b = ground_truth_json(plan_scenario("verification", SPEC, 5, quick=True).ground_truth())
    c = ground_truth_json(plan_scenario("verification", SPEC, 6, quick=True).ground_truth())
    assert a == b and a != c


def test_factory_calibration_depends_only_on_module_and_seed() -> None:
    v = plan_scenario("verification", SPEC, 3, quick=True).calibration.rig
    b = plan_scenario("thesis-bench", SPEC, 3, quick=True).calibration.rig
    assert np.array_equal(v.wide.K, b.wide.K) and np.array_equal(v.T_tele_wide.t, b.T_tele_wide.t)


def test_bad_scenario_requests() -> None:
    with pytest.raises(InputError, match=r"unknown scenario 'warmup'.*heating.*thesis-bench"):
        plan_scenario("warmup", SPEC)
    with pytest.raises(InputError, match="HeatingConfig"):
        plan_scenario("heating", SPEC, config=StackConfig())
    with pytest.raises(InputError, match="seed"):
        plan_scenario("refocus", SPEC, -1)


def test_heating_runs_from_cold_with_the_focus_locked() -> None:
    plan = plan_scenario("heating", SPEC, 0, config=HeatingConfig(interval_s=120.0))
    times = [pc.state.conditions.time_s for pc in plan.captures]
    assert times == [0.0, 120.0, 240.0, 360.0, 480.0, 600.0]
    scales = {round(pc.state.tele.focal_scale, 15) for pc in plan.captures}
    assert len(scales) == 1  # focus lock: the same lens position in every capture
    assert all(not pc.truth.handheld for pc in plan.captures)


def test_refocus_stack_varies_the_focal_scale_only() -> None:
    plan = plan_scenario("refocus", SPEC, 0)
    assert [pc.state.conditions.focus_attempt for pc in plan.captures] == list(range(7))
    tele = np.array([pc.truth.tele.focal_scale for pc in plan.captures])
    # Manual focus at 1.5 m: thin-lens −1.27 % from the 0.6 m calibration, σ 8e-4 per attempt.
    assert tele.mean() == pytest.approx(0.98729, abs=3 * 8e-4)
    assert 1e-4 < tele.std() < 3e-3
    poses = {tuple(np.round(pc.state.T_world_device.t, 12)) for pc in plan.captures}
    assert len(poses) == 1  # tripod


def test_autofocus_refocus_stack_records_its_failures(tmp_path) -> None:
    cfg = StackConfig(distance_m=2.0, focus_m=2.0, attempts=30, focus_mode="auto")
    plan = plan_scenario("refocus", SPEC, 0, config=cfg)
    write_capture_set(tmp_path, plan, render=False)
    assert {c.focus_mode for c in load_capture_set(tmp_path, check_images=False).captures()} == {
        "auto"
    }
    gt = load_ground_truth(tmp_path)
    failed = np.array([[c.wide.af_failed, c.tele.af_failed] for c in gt.captures])
    dioptre = np.array([1 / c.tele.focus_distance_m for c in gt.captures])[~failed[:, 1]]
    assert 0 < failed.sum() < 12  # 5 % of 60 camera captures, recorded per camera
    assert dioptre.mean() == pytest.approx(0.5, abs=0.02)  # aimed at the chart (0.5 D)
    assert 0.01 < dioptre.std() < 0.06  # with a 0.03 D aim error


def test_verification_rois_and_depths() -> None:
    plan = plan_scenario("verification", SPEC, 0)
    assert len(plan.captures) == 45
    depths, moved = [], set()
    for pc in plan.captures:
        t = pc.truth
        x, y, w, h = t.roi
        assert (w, h) == (200, 150) and 0 <= x and x + w <= 2000 and 0 <= y and y + h <= 1500
        corners = t.objects[0].keypoints["corners"].arrays()
        chart_z = np.nanmedian(corners.depth_m)
        assert t.roi_depth_m == pytest.approx(chart_z, rel=0.02)  # ROI is on the chart centre
        assert _both(corners).sum() > 100  # enough corners in both cameras (0.8 m: ~140)
        depths.append(chart_z)
        moved.add(tuple(np.round(pc.state.T_world_device.t, 9)))
    assert min(depths) == pytest.approx(0.8, abs=0.02) and max(depths) == pytest.approx(4, abs=0.1)
    assert len(moved) == 45  # handheld: every capture from a slightly different pose


def test_dual_depth_has_two_depths_and_occlusion() -> None:
    plan = plan_scenario("dual-depth", SPEC, 0, quick=True)
    t = plan.captures[0].truth
    near, far = t.object("near"), t.object("far")
    for obj, z in ((near, 1.0), (far, 2.0)):
        circles = obj.keypoints["circles"].arrays()
        assert _both(circles).all()  # every circle pair seen by both cameras
        assert np.nanmedian(obj.keypoints["corners"].arrays().depth_m) == pytest.approx(z, 1e-6)
    # Far corners behind the near chart are hidden (NaN) although inside the wide image.
    fc = far.keypoints["corners"].arrays()
    state = plan.captures[0].state
    from phonestereo.sim.truth import ray_depths

    proj = state.wide.camera.project(
        state.T_cam_world("wide").apply(
            plan.captures[0]
            .scene.objects[1]
            .T_world_chart.apply(
                np.column_stack(
                    [plan.captures[0].scene.objects[1].chart.corners_uv(), np.zeros(1053)]
                )
            )
        )
    )
    hidden = np.isnan(fc.wide_px[:, 0]) & state.wide.camera.contains(proj)
    assert hidden.sum() > 30
    assert np.allclose(
        ray_depths(state, plan.captures[0].scene.objects, proj[hidden], "wide"), 1.0, atol=0.01
    )


def test_learning_puts_faces_at_several_sensor_positions() -> None:
    plan = plan_scenario("learning", SPEC, 0, quick=True)
    assert {pc.truth.kind for pc in plan.captures} == {"face"}
    groups = [pc.state.conditions.focus_group for pc in plan.captures]
    assert groups == ["L00p00", "L00p00", "L00p01", "L00p01"]
    centres = []
    for pc in plan.captures:
        pupils = pc.truth.objects[0].keypoints["pupils"].arrays()
        assert np.isfinite(pupils.wide_px).all()  # all 8 faces in the wide at 1.5 m
        assert _both(pupils).sum() >= 4  # at least two faces in the tele
        assert np.nanmedian(pupils.depth_m) == pytest.approx(1.5, abs=0.05)
        obj = pc.scene.objects[0]
        centre = obj.T_world_chart.apply([[*np.divide(obj.chart.size_m, 2), 0.0]])
        st = pc.state
        centres.append(st.tele.camera.project(st.T_cam_world("tele").apply(centre))[0])
    # Position (0.5, 0): the chart lands half the tele's half-width (500 px) to the right.
    assert centres[2][0] - centres[0][0] == pytest.approx(500, abs=60)


def test_temperature_is_reported_only_if_the_module_reports_it(tmp_path) -> None:
    spec = load_module("nonfolded-x2")
    write_capture_set(tmp_path, plan_scenario("heating", spec, 0, quick=True), render=False)
    temps = [c.temperature_c for c in load_capture_set(tmp_path, check_images=False).captures()]
    assert temps[0] == pytest.approx(25.0) and temps[-1] == pytest.approx(
        25 + 15 * (1 - np.exp(-180 / 70)), abs=1e-3
    )
