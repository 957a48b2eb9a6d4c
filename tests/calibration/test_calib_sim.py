"""Calibration on rendered charts with known truth (issue #3 part 2, thesis §1.3.2).

The ``calibration`` scenario of ``folded-x3`` with every effect on (sensor noise, defocus,
heated, odd-order true lenses) is rendered, corners are detected in the PNGs by the shipped
``features.chessboard.find_chessboard`` (what ``phonestereo calibrate`` runs; never the truth),
and the stereo calibration is compared with the ground
truth through its own covariance: z = (estimate − truth) / σ for every parameter (both
cameras' intrinsics and lenses, T_tele_wide, every board pose).

The criterion of the 20-seed test (stated here because "every parameter within 3σ" cannot
hold literally: with 134 parameters per seed a Gaussian puts 0.27 % of them beyond 3σ):

- the covariance as a whole: the mean over seeds of the squared Mahalanobis distance per
  parameter, (x − x_true)ᵀ C⁻¹ (x − x_true) / P, is in [0.85, 1.2] (1 ± 0.027 for an exact
  covariance);
- per parameter: ≥ 98 % of all z within ±3 (also over the 26 camera + rig parameters alone)
  and RMS z ≤ 1.3 — looser than an exact covariance gives (99.7 %, 1.0) because z of one
  seed are strongly correlated (its 18 board poses share a few modes), so they come in lumps.

Measured on the shipped detector with the per-view weights on by default (session 29; this
test's printed summary): d²/P 1.086, 99.85 % within 3σ (99.23 % on the 26 camera + rig
parameters), RMS z 1.063 (rig 1.088), max |z| 3.82; its iid reference d²/P 1.011, 99.40 %,
RMS z 1.043, and over 8 draws d²/P 0.968–1.075, 98.40–99.96 %, RMS z 0.922–1.112 (rig
0.923–1.067), max |z| 3.04–3.79. With every corner alike (issue #19; ``benchmarks/
bench_calibrate_sim.py --seeds 20 --jobs 2 --iid-reps 8``): d²/P 1.091, 99.85 % within 3σ
(99.23 % on the 26 camera + rig parameters), RMS z 1.040 (rig 1.092), max |z| 3.86. The iid
reference on the same geometry (true projections + iid noise at each solve's σ, so the
covariance is exact by construction): d²/P 1.006, 99.40 %, RMS z 1.042, max |z| 3.69; over 8
draws of its noise d²/P 0.966–1.073, 98.40–99.96 % within 3σ, RMS z 0.927–1.110, max |z|
3.13–3.79; "every z within 3" held in 0 of the 8 draws (2 of 8 on the camera + rig parameters
alone), so the literal wording is out of reach of any exact covariance. Ours is inside that
range on the fraction within 3σ and on RMS z over all parameters, slightly above its top on
d²/P (1.086 vs 1.075) and RMS z of the camera + rig parameters (1.088 vs 1.067): a few %
optimistic in σ, in the weak modes. The rendered corner errors are not iid (a deterministic
part from quantisation and aliasing, tele corners noisier than wide ones, slightly heavy
tails), which the covariance does not model. (Before issue #19 the test bypassed the shipped
detector — cv2.findChessboardCorners on a half-size image + a 12 px saddle window — and
measured d²/P 1.136, RMS z 1.18.) Tried then and not kept (d²/P still above the draws' range):
a σ per camera in weights, threshold and covariance, rejection at the χ²₂ 99.9 / 99.99 %
quantile, and weights from each corner's predicted covariance. A σ of each view's own, for
every view, read d²/P 1.079 but RMS z 1.103 (session 28): its own estimation error goes into
the covariance; the default gives a view its own σ only where it differs beyond chance.
"""

from __future__ import annotations

import json
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from _support.calib_sim import (
    evaluate_seed,
    render_set,
    sim_views,
    true_parameters,
    z_scores,
    z_summary,
)
from phonestereo.calibration.solve import CalibrationOptions, calibrate_stereo
from phonestereo.charts.three_plane import ThreePlaneChart
from phonestereo.errors import InputError
from phonestereo.sim.calib_scenario import CalibrationConfig
from phonestereo.sim.ground_truth import ground_truth_json
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import plan_scenario
from phonestereo.sim.writer import write_capture_set

# The linear sensor path (isp off): these tests check the solver against a sensor-noise model.
# On the presets' phone-ISP renders (CFA, demosaicing, sharpening, JPEG) corners carry a
# structured error the model lacks: RMS per point 0.074 px instead of < 0.02 (issue #16).
SPEC = load_module("folded-x3").with_effects(isp=False)
#: Fast variant: the 9 sensor positions once, 3 tele poses.
FAST = CalibrationConfig(wide_poses=9, tele_poses=3)


def _visible(kp, role: str) -> np.ndarray:
    return np.isfinite(kp.wide_px if role == "wide" else kp.tele_px).all(axis=1)


# --- the chart and the plan (no rendering) -----------------------------------------------------


def test_three_plane_chart_is_three_distinct_planes() -> None:
    chart = ThreePlaneChart()
    ids, pts = chart.corner_ids(), chart.object_points()
    assert len(np.unique(ids)) == len(ids) == 108
    normals = []
    for plane in chart.planes:
        p = plane.corners_chart()
        centred = p - p.mean(axis=0)
        _, sv, vt = np.linalg.svd(centred)
        assert sv[2] < 1e-12  # each board is flat
        normals.append(vt[2] * np.sign(vt[2, 2]))
    for a in range(3):
        for b in range(a + 1, 3):  # pairwise ≥ 35° apart: a well-conditioned 3-D target
            assert np.degrees(np.arccos(normals[a] @ normals[b])) > 35
    assert np.allclose(chart.object_points_for(ids[::-1]), pts[::-1])
    with pytest.raises(InputError, match="not corners"):
        chart.object_points_for([5000])
    with pytest.raises(InputError, match="wall_deg"):
        ThreePlaneChart(wall_deg=85)


def test_calibration_plan_has_one_true_state_and_whole_boards() -> None:
    plan = plan_scenario("calibration", SPEC, 3)
    truths = [pc.truth for pc in plan.captures]
    assert len(truths) == 18 and all(t.kind == "calibration" for t in truths)
    for role in ("wide", "tele"):
        cams = [getattr(t, role).true_camera() for t in truths]
        # Focus locked, tripod, heated: the true camera is the same in every capture (heating
        # drift over the 34 s of captures at t ≥ 600 s: < 1e-3 px).
        assert max(abs(c.cx - cams[0].cx) + abs(c.cy - cams[0].cy) for c in cams) < 1e-3
        assert max(abs(c.fx - cams[0].fx) for c in cams) < 1e-9
    assert len({json.dumps(t.T_tele_wide) for t in truths}) == 1
    for t in truths:
        kp = t.objects[0].keypoints["corners"].arrays()
        assert _visible(kp, "wide").all()  # every board whole in the wide
        if t.id.startswith("T"):
            assert _visible(kp, "tele").all()  # tele poses: whole in the tele too
    again = plan_scenario("calibration", SPEC, 3).ground_truth()
    assert ground_truth_json(again) == ground_truth_json(plan.ground_truth())


def test_three_plane_plan_is_one_capture_seen_whole_by_both() -> None:
    plan = plan_scenario("calibration-3plane", SPEC, 0)
    same = plan_scenario("calibration", SPEC, 0, config=CalibrationConfig(chart="three-plane"))
    assert ground_truth_json(plan.ground_truth()) == ground_truth_json(same.ground_truth())
    (pc,) = plan.captures
    assert [o.name for o in pc.truth.objects] == ["left", "right", "floor"]
    for o in pc.truth.objects:
        kp = o.keypoints["corners"].arrays()
        assert _visible(kp, "wide").all() and _visible(kp, "tele").all()


def test_bad_calibration_configs() -> None:
    with pytest.raises(InputError, match="cols \\+ rows odd"):
        CalibrationConfig(pattern=(8, 6))
    with pytest.raises(InputError, match="chart must be"):
        CalibrationConfig(chart="sphere")  # type: ignore[arg-type]
    with pytest.raises(InputError, match="does not fit the tele"):
        plan_scenario("calibration", SPEC, 0, config=CalibrationConfig(tele_distance_m=0.2))


# --- rendered: accuracy against truth ----------------------------------------------------------


@pytest.mark.parametrize("seed", [0, 1])
def test_boards_recover_truth_within_covariance(seed: int) -> None:
    run = evaluate_seed(seed, FAST, iid_reps=2)
    assert run["views"][0] == 12 and run["views"][1] >= 3  # every planned board found
    s = z_summary([run])
    # The iid reference's further draw: fresh noise on the same geometry, same guard as below.
    assert run["z_iid_1"] != run["z_iid"] and len(run["z_iid_1"]) == len(run["z"])
    assert z_summary([run], "_iid_1")["max_abs_z_all"] < 5.0
    print(json.dumps({k: v for k, v in run.items() if k not in ("z", "names")}), s)
    # Rendered corners: ~0.012 px noise + ~0.005 px deterministic error per point.
    assert run["rms_px_per_point"] < 0.02
    # One seed, ~100 correlated z: the 20-seed criterion (slow test) is the real one; here
    # a guard that catches a wrong truth or a broken covariance (those give |z| ≫ 5).
    assert s["within_3sigma_all"] >= 0.97 and s["max_abs_z_all"] < 5.0
    # Odd-order true lens: the odd model fits ≥ 2× better than OpenCV's even one on the same
    # corners (no rejection: the even model's rejection drops exactly its misfit corners).
    assert run["even_all"][0] >= 2.0 * run["odd_all"][0]
    # With rejection on both, the wide camera (strong odd terms) still ≥ 2×.
    assert run["even_reject"][1] >= 2.0 * run["odd_reject"][1]


def test_phone_isp_far_views_get_their_own_sigma(tmp_path: Path) -> None:
    # The presets' phone ISP (CFA, demosaicing, denoising, sharpening, JPEG) on, as on a real
    # phone: the wide's views of the far tele poses (9-11) err ~3× its near ones, and one
    # pooled σ took their corners for outliers. Measured on seeds 0 / 1 / 2: pooled 73 / 31 / 32
    # of 810 corners rejected, per view 0 / 2 / 2, the far wide views at 3.2-4.4 / 2.2-3.3 /
    # 1.6-2.9× the pooled σ; over six seeds d²/P 1.31 pooled, 1.00 per view
    # (calibration/view_weights.py). ~20 s: one render of 12 poses through the ISP.
    write_capture_set(
        tmp_path, plan_scenario("calibration", load_module("folded-x3"), 0, config=FAST)
    )
    views = sim_views(tmp_path, FAST.pattern, FAST.square_m)
    runs = {
        vw: calibrate_stereo(
            views.wide, views.tele, views.sizes,
            CalibrationOptions("radial-odd", n_radial=4, view_weights=vw),
        )
        for vw in (False, True)
    }
    own = runs[True].view_sigma_ratios()
    assert runs[False].n_outliers >= 25 and runs[True].n_outliers <= 5
    assert all(own.get((0, v), 0.0) >= 2.0 for v in (9, 10, 11)), own
    d2 = {}
    for vw, res in runs.items():
        err = res.parameters - true_parameters(res, views, FAST.square_m)
        d2[vw] = float(err @ np.linalg.solve(res.covariance, err)) / err.size
    # one seed: d²/P of an exact covariance is 1 ± 0.14 (P ≈ 100, in lumps); measured 1.46
    # pooled, 0.90 per view
    assert d2[True] < 1.3 and d2[True] < d2[False], d2


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_three_plane_single_shot_recovers_truth(seed: int, tmp_path: Path) -> None:
    views = render_set(tmp_path, seed, CalibrationConfig(chart="three-plane"))
    assert views.wide[0].n_points == views.tele[0].n_points == 108  # all three boards
    res = calibrate_stereo(
        views.wide, views.tele, views.sizes, CalibrationOptions("radial-odd", n_radial=4)
    )
    z = z_scores(res, true_parameters(res, views, None))
    assert res.rms_px_per_point < 0.02
    assert np.max(np.abs(z)) < 4.0, dict(zip(res.parameter_names, np.round(z, 2), strict=True))
    # One shot of a chart covering the image centre: the tele is calibrated to < 1 px of
    # principal point, the wide's distortion only where the chart was (large σ, stated).
    sd = res.std
    assert sd["tele.cx"] < 2.0 and sd["wide.fx"] < 2.0


# 20 rendered seeds through the shipped detector: ~51 s of CPU a seed since session 26 (84 s
# before the quick chessboard check, the sparse ray field and the reused heap); 746 s wall in
# `make acceptance` beside the other worker.
@pytest.mark.slow
def test_twenty_seeds_every_parameter_within_its_covariance() -> None:
    with ProcessPoolExecutor() as pool:
        runs = list(pool.map(evaluate_seed, range(20), [CalibrationConfig()] * 20))
    s = z_summary(runs)
    ref = z_summary(runs, "_iid")
    ratio_all = [r["even_all"][0] / r["odd_all"][0] for r in runs]
    ratio_wide = [r["even_reject"][1] / r["odd_reject"][1] for r in runs]
    print(json.dumps(s), json.dumps(ref), "ratios", np.round(ratio_all, 2), np.round(ratio_wide, 2))
    # Every board found where it was planned whole (a centred wide pose may fit the tele too).
    assert all(r["views"][0] == 18 and r["views"][1] >= 6 for r in runs)
    # The covariance as a whole: mean d²/P = 1 ± 0.027 for an exact one (20 × χ²₁₃₄); the
    # band allows a σ off by 10 %.
    assert 0.85 <= s["mean_mahalanobis2_per_parameter"] <= 1.2
    # Per parameter (the wording): ≥ 98 % within 3σ and RMS z ≤ 1.3. An exact
    # covariance gives 99.7 % and 1.0, but the 18 board poses of a seed share a few modes
    # (scale/distance, the principal point), so one mode at 3σ puts ~20 z beyond 3: the
    # per-parameter figures are lumpy; the deterministic corner error of the renders
    # (≈ 0.005 px) makes the covariance a few % optimistic in exactly those weak modes.
    assert s["within_3sigma_all"] >= 0.98 and s["within_3sigma_rig"] >= 0.98
    assert 0.8 <= s["rms_z_all"] <= 1.3 and 0.8 <= s["rms_z_rig"] <= 1.3
    assert min(ratio_all) >= 2.0 and min(ratio_wide) >= 2.0
    # The reference: the same solves on the true projections + iid noise at each solve's σ,
    # where the covariance is exact by construction. Even there not every z is within 3 (an
    # exact covariance puts 0.27 % beyond, ~7 of 2680, in lumps): measured 99.40 %, max |z|
    # 3.69, RMS z 1.04, d²/P 1.011 (the machinery is right); the rendered corners through the
    # shipped detector: 99.85 %, max |z| 3.82, RMS z 1.06, d²/P 1.086 (with the per-view
    # weights, session 29; every corner alike: 3.86, 1.04, 1.091).
    assert 0.9 <= ref["mean_mahalanobis2_per_parameter"] <= 1.12
    assert ref["within_3sigma_all"] >= 0.99 and 0.85 <= ref["rms_z_all"] <= 1.1
