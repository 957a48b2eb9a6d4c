"""The matcher on imperfectly rectified pairs (issue #18 item 6): rows off ±1 px, a 0.1° roll.

The pairs are Middlebury-Q Adirondack and Piano with the right image rotated about its centre
and shifted in rows, the ground truth mapped alike (tests/_support/match_imperfect.py, shared
with benchmarks/bench_match_imperfect.py). Acceptance: ≥ 95 % of the matches within 0.5 px, at a
median |d − d_true| no worse than 1.2× the aligned pair's.
"""

from __future__ import annotations

import pytest

from _support import match_imperfect as imp

needs_data = pytest.mark.skipif(
    not imp.bench.DATA.exists(), reason="shared/data not beside the clone"
)


@pytest.fixture(scope="module")
def aligned() -> dict[str, dict]:
    return {s: imp.evaluate(s, 0.0, 0.0) for s in imp.SCENES}


# measured (matches, within 0.5 px, median px): aligned Adirondack 883, 0.978, 0.0188; Piano 663,
# 0.964, 0.0678 (699, 0.966, 0.0676 since the search refills, features/search_budget.py; the
# misaligned figures below are from before it). Misaligned: Adirondack 757–876 matches, 0.971–0.978,
# 0.97–1.08× the aligned median; Piano 574–689, 0.963–0.973, 0.92–1.09×. The matcher's ±3 row search
# and its fitted e take the row offset (dy = 1 px alone: 1.00×); the roll's disparity gradient along
# y is the fitted slant. With one image resampled bilinearly instead (order 1) the medians read
# 1.9–2.0× (Adirondack) and 1.45× (Piano): the interpolation's own bias at fractional offsets, not
# the matcher's (cubic B-spline: 1.07–1.18×). OpenCV's remap of the 0.1° roll alone: INTER_LINEAR
# 1.95× (signed +0.028 px against +0.001 aligned), INTER_CUBIC 1.16×, INTER_LANCZOS4 1.05×
# (Adirondack): the product's rectification remaps bilinearly by default
@needs_data
@pytest.mark.parametrize("scene", imp.SCENES)
@pytest.mark.parametrize(("dy_px", "roll_deg"), imp.CASES)
def test_misaligned_pair_keeps_its_accuracy(
    aligned: dict, scene: str, dy_px: float, roll_deg: float
) -> None:
    ref, out = aligned[scene], imp.evaluate(scene, dy_px, roll_deg)
    assert out["within_0.5px"] >= 0.95, out  # acceptance (issue #18)
    assert out["median_abs_err_px"] <= 1.2 * ref["median_abs_err_px"], (out, ref)
    # not an acceptance figure: the rows and roll cost at most ~15 % of the matches (measured
    # 86–104 %); a guard that the search still finds the shifted rows
    assert out["matches"] >= 0.75 * ref["matches"], (out, ref)
