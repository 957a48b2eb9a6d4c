"""The slow tests' wall seconds, measured in `make acceptance` on 2 cores (session 25,
`--durations=0`, setup + call; a parametrised test's figure is one parameter's):
:func:`order_slowest_first` puts them in that order, so that xdist's load scheduling hands the
long tests out first, one at a time to whichever worker is free (longest-processing-time
first). The Makefile's ``--maxschedchunk 1`` makes it one at a time: by default xdist sends
each worker its first ~dozen tests as one consecutive block, which with this order put the
five longest on one worker (session 25: ~20 min of the acceptance stage on one worker while
the other idled). Replaying xdist 3.8's scheduler over session 25's durations: 3192 s in file
order, 3750 s longest first in blocks, 2484 s longest first one at a time (half the total).

A test missing here counts 0 and keeps its collection order after the listed ones; re-measure
with ``make acceptance`` (it prints ``--durations=20``) when a slow test is added.
"""

from __future__ import annotations

from collections.abc import MutableSequence
from typing import Any

SECONDS = {
    "test_calib_sim::test_twenty_seeds_every_parameter_within_its_covariance": 1220,
    "test_false_heating_slope::test_a_warm_module_does_not_learn_a_heating_slope_from_its_capture_order": 811,  # noqa: E501
    "test_rows_off_module::test_rows_off_by_12_px_are_learned_and_measured": 533,
    "test_lever_weighted_field::test_faces_far_from_the_tele_centre_do_not_decide_the_chart_correction": 492,  # noqa: E501
    "test_naive::test_naive_error_breakdown_by_effect": 366,
    "test_analysis_heating::test_default_scenario": 326,
    "test_hot_folded_module::test_hot_folded_module_meets_the_random_modules_lines": 259,
    "test_analysis_wt_scale::test_autofocus_failure_flagged_and_left_out": 155,
    "test_analysis_handheld::test_default_scenario": 65,
    "test_verification_sweep::test_sweep_never_mislabels_and_detects_most": 31,
    "test_analysis_orientation::test_default_scenario": 58,
    "test_guide::test_every_guide_command_succeeds": 56,
    "test_analysis_wt_scale::test_refocus_all_effects": 53,
    "test_analysis_repeatability::test_focus_effects_only": 48,
    "test_analysis_distortion::test_with_calibration_captures": 43,
    "test_analysis_heating::test_temperature_reporting_module": 34,
    "test_analysis_essential::test_default_scenario": 33,
    "test_sim_render::test_full_size_corner_accuracy_table": 32,
    # make unit (whole modules per worker, `--dist loadscope`): the test that builds its
    # module's shared fixture, setup + call (session 26, `--durations=10`), so the heaviest
    # modules are handed out first
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
