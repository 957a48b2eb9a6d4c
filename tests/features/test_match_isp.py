"""The matcher on phone-like images (issue #16): degraded real pairs, ISP renders, phone pairs.

Helpers are in tests/_support (match_isp.py, match_phone.py), shared with the benchmarks
bench_match_isp.py and bench_match_phone.py, so the tests and the printed tables measure the
same thing. Measured figures are in the comments; cases that
miss the issue's acceptance are strict xfails that say by how much.
"""

from __future__ import annotations

import numpy as np
import pytest

from _support import match_isp as isp
from _support import match_phone as phone

needs_data = pytest.mark.skipif(
    not isp.bench.DATA.exists(), reason="shared/data not beside the clone"
)

# measured (matches, median |d − GT| px): clean Adirondack 883, 0.0188; Piano 699, 0.0671 (663,
# 0.0673 before the search refilled failed windows: features/search_budget.py); motorcycle 605,
# 0.0727. Passing cases measured: Adirondack q95 771 (87 %) 0.0242, q85 722 (82 %) 0.0262, q70 713
# (81 %) 0.0371 (limit 0.0388), sharpened 845 (96 %) 0.0200; Piano q95 640 (92 %) 0.0697, q85 609
# (87 %) 0.0814, q70 568 (81 %) 0.0968 (limit 0.1007; 0.907 within 0.5 px), sharpened 677 (97 %)
# 0.0649 (before the refill 579 (87 %) 0.0666, 519 (78 %) 0.0780, 500 (75 %) 0.0912, 549 (83 %)
# 0.0644); motorcycle q95 618 0.0735, q85 632 0.1009, q70 651 0.1087 (limit 0.1091: the wide window
# costs this scene's depth edges, 0.0857 / 0.0925 with the 15 × 15 one), sharpened 530 (88 %)
# 0.0728, denoised 594 (98 %) 0.0755. JPEG q85 / q70 pass since the sub-pixel fit takes a 23 × 23
# window (σ_w 5 px) on both images prefiltered by a 0.5 px Gaussian when the pair's misfit floor is
# ≥ 5 (MatchConfig.wide_floor: compression-limited; with the 15 × 15 window Adirondack read 0.0410 /
# 0.0613, Piano q70 0.1205). The denoised misses are an information loss upstream of the residual
# tests: NLM h = 5 on an image whose noise is 0.8 DN changes the right image by 6.5 DN rms (median,
# 7 px windows) where Adirondack's clean matches are lost and 3.5 where they survive; of the clean
# matches with a window σ of 8–16 DN only 17 % survive (81 % above 16 DN). The NCC score test loses
# 237 more keypoints than on the clean pair (1694 → 1333 against 1731 → 1607) and the sub-pixel fit
# 143 more (796 → 521: 229 windows still move after 10 iterations, contracting by 0.8 per step,
# because the left's gradients carry texture the right no longer has). The clean matches themselves
# (benchmarks/bench_match_denoised.py): of Adirondack's 883, 222 have no NCC ≥ min_score (0.8) left
# in the denoised pair's band and 64 more fail the uniqueness test, so at most 597 (68 %, under the
# 70 %) leave the search whatever the sub-pixel stage does; Piano's search leaves at most 521 of 663
# (79 %: 52 below the score, 90 ambiguous), the stages after it lose 123 more; fitted with the roles
# swapped (Jacobian from the denoised image) the windows only that fit converges read 0.227 px
# (Piano 0.187). Tried and not adopted: 30 iterations (535 matches at 0.0393 px, over the limit, and
# motorcycle clean 0.0727 → 0.0752; 20: Adirondack 508 of 885 at 0.0385, Piano 447 of 667, 67 %,
# motorcycle clean 0.0746), uniqueness 0.95 (Piano 468 of 771, 61 %), NCC on both images smoothed by
# 0.5 / 1 px (the score test recovers, uniqueness loses them; Adirondack clean 883 → 855 / 776), a
# symmetric prefilter before the fit (no gain in convergence), min_score 0.7 (Adirondack denoised
# 440); the keypoints ranked by the right image's texture in the search band (47 % / 60 %:
# Adirondack / Piano), and NL-means on the left image too (60 % / 63 %; docs/matching.md). The
# search's refill of windows that fail it (features/search_budget.py, adopted for the phone
# pairs) brings them only to 49 % / 60 % at its budget of 1000 windows (62 % / 59 % at 1200, Piano
# q70 then over its limit): the refilled candidates are weak and the denoiser spoiled them first
MISSES = {
    ("Adirondack", "denoised"): "keeps 49 % (429 of 883), median 0.0376 px",
    ("Piano", "denoised"): "keeps 60 % (417 of 699), median 0.0748 px",
}
PARAMS = [
    pytest.param(s, c, marks=pytest.mark.xfail(strict=True, reason=MISSES[(s, c)]))
    if (s, c) in MISSES
    else (s, c)
    for s in isp.SCENES
    for c in isp.CASES[1:]
]


@pytest.fixture(scope="module")
def clean() -> dict[str, dict]:
    pytest.importorskip("skimage")
    return {s: isp.degraded(s, "clean") for s in isp.SCENES}


@needs_data
@pytest.mark.parametrize(("scene", "case"), PARAMS)
def test_degraded_pair_keeps_matches_and_accuracy(clean: dict, scene: str, case: str) -> None:
    ref, out = clean[scene], isp.degraded(scene, case)
    # issue #16: ≥ 70 % of the clean count (JPEG q70: ≥ 50 %); median ≤ max(1.5 × clean,
    # clean + 0.02 px); ≥ 90 % within 0.5 px
    keep = 0.5 if case == "jpeg70" else 0.7
    assert out["matches"] >= keep * ref["matches"], (out, ref)
    m0 = ref["median_abs_err_px"]
    assert out["median_abs_err_px"] <= max(1.5 * m0, m0 + 0.02), (out, ref)
    assert out["within_0.5px"] >= 0.90, out


# The clean pairs' figures before the ISP work (issue #16: no more than 5 % worse). Adirondack
# and Piano read 883 / 0.0188 px and 663 / 0.0673 px, as before (their floors stay at 1); Piano
# 699 / 0.0671 px since the search refills the windows that fail it (its first 2000 pass 947,
# under the budget of 1000: features/search_budget.py). The
# motorcycle read 418 matches at 0.063 px before the misfit floor and reads 605 at 0.0727 px
# now: its own misfit (14 noise variances, growing with contrast) sets a floor of 2.3 that
# admits 149 windows at 0.099 px (the other 456 read 0.064). Tried and not adopted (measured,
# docs/matching.md "What the matcher cannot recover"): a sub-pixel left-right check (k = 1-3:
# 0.0718-0.0726 px; k = 2 costs clean Adirondack 883 -> 810), residual-structure statistics
# (none separates the 149 windows: AUC 0.49-0.55), and a floor from the misfit's 10th
# percentile (motorcycle 457 at 0.0642 px, but Adirondack denoised 415 -> 302 and the phone
# pairs >= 100 matches on 7 of 16).
CLEAN_BEFORE = [("Adirondack", 883, 0.0188), ("Piano", 663, 0.0673)]
CLEAN_MISS = "605 matches at 0.0727 px against 418 at 0.063 before (limit 0.0662)"


@needs_data
@pytest.mark.parametrize(
    ("scene", "count", "median"),
    [
        *CLEAN_BEFORE,
        pytest.param(
            "motorcycle", 418, 0.063, marks=pytest.mark.xfail(strict=True, reason=CLEAN_MISS)
        ),
    ],
)
def test_clean_pair_unchanged(scene: str, count: int, median: float) -> None:
    # the floor must not cost a clean pair more than 5 % of its matches or of its median
    out = isp.degraded(scene, "clean")
    assert out["matches"] >= 0.95 * count and out["median_abs_err_px"] <= 1.05 * median, out


# within σ_d measured, fronto-parallel / slanted (seed 0): mild 0.72 / 0.69, default 0.74 / 0.71,
# strong 0.74 / 0.72 (0.71 slanted since the search refills); seeds 1–3: 0.675–0.758 (before the CFA
# filter 0.37 / 0.53, 0.40 / 0.55, 0.55 / 0.59). The bias was the demosaicer's grid-locked error:
# both images on their sensor grids, it pulled d toward even disparities (−0.03 to −0.04 px at d =
# 16.3, common to every window of the plane); both images are now filtered by [1, 2, 1] / 4 when
# both show a CFA phase (features/cfa.py), median |d − d_true| 0.036 → 0.015 px.
@pytest.mark.parametrize(
    ("setting", "slant"), [(s, t) for s in isp.ISP_SETTINGS for t in (0.0, 0.5)]
)
def test_sigma_honest_on_isp_renders(setting: str, slant: float) -> None:
    out = isp.isp_honesty(setting, (0.0, slant, 0.0))
    assert out["matches"] > 300, out
    # the plane's common bias (measured −0.037 px before the CFA filter, |·| ≤ 0.004 after):
    # 0.01 px is a third of the median σ_d, what a common bias may cost the fraction within σ
    assert abs(out["median_err_px"]) <= 0.01, out
    # acceptance 68 % ± 10 % of |d − d_true| ≤ σ_d
    assert 0.58 <= out["within_1_sigma"] <= 0.78, out


# The phone pairs' left→right / right→left statistic (tests/_support/match_phone.py) on the same
# ISP renders, where σ_d is honest against the truth (the test above). LR and RL fit the same
# pixels, so their errors against the truth correlate (measured 0.97–0.99) and d_LR − d_RL keeps
# only the small direction-dependent part: RMS z measured 0.08–0.17 (mild / default / strong,
# fronto-parallel / slanted, seed 0), while |d − d_true| / σ_d has an RMS of 0.87–1.06. It reads
# 0.28–0.29 at JPEG q70 / q60 too, where σ_d is too small (within σ 0.38–0.43): the statistic
# does not see σ_d's honesty either way. So an honest σ_d reads far below the acceptance's lower
# bound 0.8, and the phone pairs' 0.65–1.06 says that their direction-dependent error is 0.65–1.06
# σ_d (the real pairs carry an error the renders do not: Middlebury's clean pairs read 1.0–1.27),
# not that σ_d is too large
@pytest.mark.parametrize(
    ("setting", "slant"), [(s, t) for s in isp.ISP_SETTINGS for t in (0.0, 0.5)]
)
def test_lr_rl_statistic_reads_low_for_honest_sigma(setting: str, slant: float) -> None:
    out = isp.isp_honesty(setting, (0.0, slant, 0.0))
    assert 0.58 <= out["within_1_sigma"] <= 0.78, out  # σ_d honest here (68 ± 10 %)
    assert out["lr_paired"] > 300, out
    # the two directions share their error: 0.9 is far below what is measured (0.97–0.99) and
    # far above independent errors (0)
    assert out["lr_error_corr"] >= 0.9, out
    # measured 0.08–0.17: 0.35 leaves twice the largest, and is still under half of 0.8
    assert out["lr_rms_z"] <= 0.35, out


@pytest.fixture(scope="module")
def phone_rows() -> list[dict]:
    if not phone.DATA.exists():
        pytest.skip("shared/data not beside the clone")
    return [phone.evaluate(w, t) for _, w, t in phone.pairs()]


def test_real_phone_pairs(phone_rows: list[dict]) -> None:
    rows = phone_rows
    assert len(rows) == 16
    n100 = sum(r["matches"] >= 100 for r in rows)
    # acceptance ≥ 100 matches on ≥ 80 % of the pairs; measured with the default MatchConfig
    # (the misfit floor in input-noise units, also after blur equalisation; the pairs' floors
    # are ≥ 5, so the compression-limited 23 × 23 fit applies) 233–713, ≥ 100 on 16 of 16,
    # since the search refills the windows that fail it (features/search_budget.py: the pairs
    # pass 14–32 % of their first 2000); 97–302 and 15 of 16 before (79–252 with the 15 × 15
    # fit; 0–22 per pair when the floor was skipped after equalisation)
    assert n100 >= 0.8 * len(rows), [r["matches"] for r in rows]
    # the rows line up to within the third party's calibration: measured median |e| 0.2–2.0 px
    assert all(r["median_abs_e_px"] < 3.0 for r in rows), [r["median_abs_e_px"] for r in rows]
    z = np.array([r["rms_z"] for r in rows])
    # left→right vs right→left RMS z, acceptance 0.8–1.25 per pair. Measured 0.65–1.06 (median
    # 0.85) on 71–273 paired matches per pair (0.45–1.00, median 0.82, on 36–119 before the
    # search refilled; 0.47–0.92, median 0.65, with the 15 × 15 fit).
    # (Before the pairing used y' + e instead of y' − e: only the matches with |e| < 0.5 px
    # paired on pairs whose rows are 1.5–2 px off, mostly wrong ones, and RMS z read 2–3
    # there.) The upper bound holds on every pair
    assert np.all(z <= 1.25), z
    assert np.all(z >= 0.4), z
    # pooled over every paired match (README): measured 0.82 over 2831 paired matches, inside
    # the acceptance's 0.8–1.25 although 6 pairs read below 0.8 on their own; ±0.03 is the
    # spread between the landed matcher versions, so a change that moves it further is seen
    pooled = phone.pooled_rms_z(rows)
    assert 0.79 <= pooled <= 0.85, pooled


# LR and RL fit the same pixels, so the misfit both see is common and cancels in d_LR − d_RL:
# on Middlebury JPEG q85 the same statistic reads 0.58–0.83 while only 26–50 % of the matches
# are within σ_d of the ground truth (σ_d too small, not too large); on the clean pairs it reads
# 1.0–1.27; on the ISP renders, where σ_d is honest, 0.08–0.17
# (test_lr_rl_statistic_reads_low_for_honest_sigma: the two directions' errors correlate
# 0.97–0.99). Below 0.8 on phone pairs is therefore not an over-stated σ_d; the statistic cannot
# show honesty on ISP-processed pairs, and the acceptance's lower bound is not met (6 of 16
# pairs below 0.8: 0.65–0.79; 7 of 16 before the search refilled, 13 of 16 with the 15 × 15 fit)
@pytest.mark.xfail(strict=True, reason="RMS z 0.65–1.06 per pair: common ISP misfit cancels")
def test_real_phone_pairs_consistency_lower_bound(phone_rows: list[dict]) -> None:
    z = np.array([r["rms_z"] for r in phone_rows])
    assert np.all(z >= 0.8), z
