"""The slow tests' wall seconds, measured in `make acceptance` on 2 cores (session 26's first
run, `--durations=0`, setup + call; a parametrised test's figure is one parameter's), and the heavy
module fixtures of `make unit`: :func:`order_slowest_first` puts them in that order, longest
first. The Makefile's ``--dist loadscope --no-loadscope-reorder`` hands whole test modules to
whichever worker is free in that order (longest-processing-time first), so the long tests
start at once on both workers and a module's fixture is built on one. xdist's default load
scheduling sent each worker its first ~dozen tests as one block, which with this order put the
five longest on one worker (session 25: ~20 min of the acceptance stage on one worker while the
other idled). Session 26's first run (one test at a time): 1965 s wall for 3887 s of tests
(replaying the scheduler over those durations: 1943 s, half the total); with whole modules and
the naive breakdown in `make bench`: 1601 s for 3158 s.

A test missing here counts 0 and keeps its collection order after the listed ones; re-measure
with ``make acceptance`` (it prints every duration) when a slow test is added.
"""

from __future__ import annotations

from collections.abc import MutableSequence
from typing import Any

SECONDS = {
    "test_calib_sim::test_twenty_seeds_every_parameter_within_its_covariance": 746,
    "test_rows_off_module::test_rows_off_by_12_px_are_learned_and_measured": 701,
    "test_false_heating_slope::test_a_warm_module_does_not_learn_a_heating_slope_from_its_capture_order": 418,  # noqa: E501
    "test_lever_weighted_field::test_faces_far_from_the_tele_centre_do_not_decide_the_chart_correction": 342,  # noqa: E501
    "test_naive::test_naive_error_breakdown_by_effect": 327,  # `make bench` only
    "test_analysis_heating::test_default_scenario": 221,
    "test_hot_folded_module::test_hot_folded_module_meets_the_random_modules_lines": 206,
    "test_analysis_wt_scale::test_autofocus_failure_flagged_and_left_out": 106,
    "test_guide::test_imported_android_set_scores_like_the_native_set": 69,
    "test_analysis_handheld::test_default_scenario": 61,
    "test_guide::test_every_guide_command_succeeds": 47,
    "test_sim_render::test_full_size_corner_accuracy_table": 44,
    "test_analysis_essential::test_default_scenario": 41,
    "test_verification_sweep::test_sweep_never_mislabels_and_detects_most": 39,
    "test_analysis_distortion::test_with_calibration_captures": 39,
    "test_analysis_wt_scale::test_refocus_all_effects": 36,
    "test_analysis_orientation::test_default_scenario": 36,
    "test_verification_sweep::test_tele_partial_views_are_labelled_or_rejected": 30,
    "test_coarse_gate::test_random_1013_chart_at_2_4_m_is_gated_or_right": 27,
    "test_analysis_heating::test_temperature_reporting_module": 25,
    "test_learn::test_cli_learn_mediapipe": 25,
    "test_roi_slanted_surface::test_random_1011_surface_error_at_the_roi": 24,
    "test_analysis_repeatability::test_focus_effects_only": 22,
    "test_batch::test_batch_calibrate_on_a_rendered_calibration_set": 21,
    "test_landmarks_sim::test_face_chart_depth_median_within_1p5_percent": 20,
    # make unit: the test that builds its module's shared fixture, setup + call (session 26,
    # `--durations=10`), so the heaviest modules are handed out first
    "test_flow_bench::test_full_flow_fixes_the_naive_error": 94,
    "test_calib_sim::test_boards_recover_truth_within_covariance": 34,
    "test_analysis_wt_scale::test_refocus_range_shrinks_and_scale_recovered": 27,
    "test_analysis_repeatability::test_median_normalisation_and_averaging": 26,
    "test_learn::test_learn_capture_set_into_store": 18,
    "test_analysis_heating::test_quick_set_tau_saturation_and_gates": 18,
    "test_match_isp::test_real_phone_pairs_consistency_lower_bound": 17,
}


def _key(nodeid: str) -> str:
    """``file stem::function`` of a node id (no folder, no parameters)."""
    path, _, name = nodeid.split("[", 1)[0].rpartition("::")
    return f"{path.rsplit('/', 1)[-1].removesuffix('.py')}::{name}"


def order_slowest_first(items: MutableSequence[Any]) -> None:
    """Sort pytest ``items`` in place by their measured seconds, longest first (stable)."""
    items[:] = sorted(items, key=lambda it: -SECONDS.get(_key(it.nodeid), 0))
