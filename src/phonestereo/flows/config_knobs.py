"""The documentation of every flow-configuration knob: unit, meaning, why the default.

One entry per field of :class:`~phonestereo.flows.config.FlowConfig`,
:class:`~phonestereo.flows.roi_disparity.RoiConfig` and
:class:`~phonestereo.features.match_config.MatchConfig` (the defaults themselves live only in
those dataclasses). :mod:`phonestereo.flows.config_file` turns these into the pydantic schema
of ``--config FLOW.json``; docs/flow-config.md is generated from the same table, and a test
fails when a field has no entry.
"""

from __future__ import annotations

from phonestereo.flows.flow_knobs import FLOW_KNOBS

#: section → field → (unit, meaning, why the default).
KNOBS: dict[str, dict[str, tuple[str, str, str]]] = {
    "flow": FLOW_KNOBS,
    "roi": {
        "expand": (
            "factor ≥ 1",
            "ROI expansion per side for the second majority vote (Fig. 4-2).",
            "1.6: more matches on the same surface, still local.",
        ),
        "z_min_m": (
            "m",
            "Nearest depth searched; sets the largest disparity.",
            "0.4 m: the closest a phone's tele focuses.",
        ),
        "far_disparity_px": (
            "px",
            "Smallest disparity searched; the application lowers it by a positive learned "
            "correction (a far point then reads −correction).",
            "−2 px: a little beyond infinity, for a calibration off by up to 2 px.",
        ),
        "majority_bin_px": (
            "px",
            "Histogram bin of the majority-disparity vote.",
            "0.5 px: finer than surfaces' separation, coarser than noise.",
        ),
        "majority_tol_px": (
            "px",
            "Band kept about the majority disparity, then about the surface's plane (absolute).",
            "0.75 px: the matches' spread; the plane follows a slanted surface.",
        ),
        "majority_tol_rel": (
            "fraction",
            "Band kept about the majority disparity (relative "
            "part; the larger of the two is used).",
            "4 %: large disparities (near objects) spread more.",
        ),
        "min_matches": (
            "count",
            "Fewest matches on the surface for a measurement.",
            "12: a 3-parameter plane with a robust margin.",
        ),
        "enough_matches": (
            "count",
            "With fewer on the surface after blur equalisation the unblurred pair is tried too.",
            "60: the plane is well fixed above.",
        ),
        "map_step_px": (
            "px",
            "Grid step of the window's rectification maps (exact on the grid, splines between).",
            "16 px: < 0.01 px map error, 250× fewer exact evaluations.",
        ),
        "coarse_min_zncc": (
            "ZNCC",
            "The coarse whole-box correlation must reach this.",
            "0.5: below it the ROI has no texture or is occluded.",
        ),
        "equalise_blur": (
            "bool",
            "After the coarse step, blur the sharper image to the other's blur (chosen on tiles "
            "aligned at the coarse disparity and row offset) before the sub-pixel fit.",
            "On: wide and tele differ in blur.",
        ),
        "coarse_rows": (
            "px",
            "Rows searched either side in the coarse correlation, about the learned row error "
            "when that is more than this less 3 px; a peak on the border moves the rows to it "
            "and searches again (up to 24 px from 0).",
            "8 px: the coarse e of 72 of 73 bench sets lies within ±7 px; wider rows admit a "
            "chessboard's aliases at other rows and cost the 2 MP application its margin. "
            "Larger errors (random-3056: 11–12 px after warm-up) are found by moving the rows, "
            "not by widening them.",
        ),
        "coarse_expand": (
            "factor",
            "The coarse box is the ROI expanded this much.",
            "3: repetitive texture needs context to be unambiguous.",
        ),
        "max_ambiguity": (
            "ratio",
            "A second coarse peak (> 2 px away) above this × the "
            "first fails the measurement as ambiguous.",
            "0.97: only near-equal peaks are ambiguous.",
        ),
        "min_peak_t": (
            "t",
            "The first coarse peak must beat the second tile by tile (4 × 4 tiles, paired t "
            "of their ZNCC differences) or the measurement fails as ambiguous.",
            "2 (one-sided p ≈ 0.03): random-1013's chessboard alias t 1.5 (read 0.37 m for "
            "2.40 m); true peaks: folded-x3 demo 3.8-5.5, periscope-x5 demo 2.3-2.8 (a threshold "
            "of 3 gated 4 of its 18 captures).",
        ),
        "alias_ratio": (
            "fraction",
            "The first coarse peak must also beat, tile by tile, every further peak within this "
            "fraction of its ZNCC.",
            "0.85: random-3014's truth read 0.87 of an alias (t = −0.2 against it), its measured "
            "charts beat theirs at t ≥ 2.2; on the 33 bench sets it gates 2 more of 594 charts.",
        ),
        "coarse_max_scale_drift_px": (
            "px",
            "When the W-T scale the coarse box's tiles show moves the box's edges by more than "
            "this against its centre, the tele window is corrected for it before the coarse "
            "and fine steps (W-T scale fix on only).",
            "4 px: random-1013 (3.7 %, 9.5 px; its box correlated 0.22-0.55, corrected "
            "0.95) and random-1000 (2 %, 5.6 px) are corrected; folded-x3 (1 %, 2.8 px) is "
            "not (correcting it cost 0.35 → 0.41 % median).",
        ),
        "fine_range_px": (
            "px",
            "The fine search is ± this around the coarse disparity.",
            "3 px: the coarse step is good to ~1 px.",
        ),
        "max_band_split": (
            "ratio",
            "Matches beside the surface's band (on its fuller side, within 3 majority "
            "tolerances) over those in it: at or above this the measurement fails as two "
            "disparities.",
            "0.5: one surface gives 0-0.23 (folded-x3, periscope-x5, random-1011, -1013); "
            "random-1001's periscope 0.95-1.03 (bands 1.4 px apart, read -13 % / +28 % at "
            "4 m), random-1000's 0.63-1.06.",
        ),
    },
    "match": {
        "detector": (
            "name",
            "Keypoint detector: 'dog' or 'sift'.",
            "'dog': faster, as accurate on the bench.",
        ),
        "max_keypoints": (
            "count",
            "Keypoints searched (strongest first, spread over 8×8 px cells); while fewer "
            "than half pass the search, the next candidates take the places of those that "
            "failed, up to 4× as many in all (features/search_budget.py).",
            "Flow: 450 (median 0.37-0.58 %, ~53 ms per capture vs "
            "~130 ms at 1200); matcher alone: 2000.",
        ),
        "dog_sigma": ("px", "DoG inner scale.", "1.0 px: the finest stable texture."),
        "dog_k": ("ratio", "DoG scale ratio.", "1.6: Lowe's approximation of the LoG."),
        "contrast": (
            "noise σ",
            "Minimum |DoG| in units of its noise σ.",
            "5: keeps keypoints well above noise.",
        ),
        "edge_ratio": (
            "ratio",
            "Lowe's edge ratio (edges are poorly localised along them).",
            "10: Lowe's value.",
        ),
        "radius": (
            "px",
            "Window half size of the NCC search and sub-pixel fit.",
            "7 px (15×15): best accuracy/robustness on Middlebury.",
        ),
        "sigma_w": (
            "px",
            "Gaussian weight σ of the sub-pixel window.",
            "3 px: centre-weighted, so the fit is local.",
        ),
        "row_tolerance": (
            "px",
            "Rows searched either side of the epipolar row.",
            "3 px: the rectification residue of a phone rig.",
        ),
        "min_score": ("NCC", "NCC peak must reach this.", "0.8: rejects wrong matches."),
        "uniqueness": (
            "ratio",
            "Second-best NCC peak elsewhere in the band must be below this × the peak.",
            "0.9: rejects repetitive-texture matches.",
        ),
        "min_curvature": (
            "1/px²",
            "−∂²NCC/∂x² (and ∂y²) at the peak must reach this.",
            "0.01: flat peaks are poorly localised.",
        ),
        "lr_check": (
            "bool",
            "Left-right consistency check.",
            "Matcher: on; flow: off (after the coarse step the ±3 px search is unambiguous).",
        ),
        "lr_tolerance": ("px", "Tolerance of the left-right check.", "1 px."),
        "slant": (
            "bool",
            "Fit the disparity gradient in the window.",
            "Matcher: on (Piano 0.065 vs 0.072 px); flow: off (planar ROI, faster).",
        ),
        "max_slant": ("px/px", "Bound of the fitted disparity gradient.", "0.5."),
        "max_iter": (
            "count",
            "Gauss-Newton iterations of the sub-pixel fit.",
            "10: converges in 3-5.",
        ),
        "tol": ("px", "Convergence threshold of the sub-pixel fit.", "1e-3 px."),
        "max_shift": (
            "px",
            "|sub-pixel − parabola start| allowed in d and e.",
            "0.7 px: a larger move means the fit left the peak.",
        ),
        "max_normalized_residual": (
            "ratio",
            "Residual σ / window σ (≈ √(1 − ZNCC²)) allowed after the fit.",
            "Matcher: 0.2; flow: 0.35 (wide and tele optics differ, windows never fit to noise).",
        ),
        "max_residual_ratio": (
            "ratio",
            "Residual σ / noise σ allowed.",
            "Matcher: 4; flow: off (1e9) for the same reason.",
        ),
        "max_sigma_d": ("px", "Largest σ_d kept.", "0.25 px: worse matches add nothing."),
        "e_floor_px": (
            "px",
            "Row-error filter floor: |e − affine fit| ≤ max(floor, k·σ_MAD).",
            "0.5 px.",
        ),
        "e_k_mad": ("σ_MAD", "Row-error filter multiple.", "5: only gross outliers."),
        "hist_bin_px": ("px", "Histogram filter bin.", "1 px."),
        "hist_min_count": ("count", "Histogram filter: fewest matches in a bin.", "3."),
        "support_k": ("count", "Neighbours of the support filter.", "8."),
        "support_tol_px": ("px", "Neighbour disparity tolerance of the support filter.", "1 px."),
        "min_support": ("count", "Neighbours that must agree (0 disables the filter).", "1."),
        "noise_sigma": (
            "DN or null",
            "Per-pixel image noise σ; null: estimated per image.",
            "null: phones differ.",
        ),
        "residual_sigma": (
            "bool",
            "σ_d from max(noise, residual misfit) (on) or from the noise alone (pure Cramér-Rao).",
            "On: honest σ on real optics.",
        ),
        "equalise_blur": (
            "bool",
            "Equalise the pair's blur before the sub-pixel fit.",
            "On: wide and tele differ in blur.",
        ),
        "min_blur_misfit": (
            "noise variances",
            "Equalise only when the blur difference adds at least this to a window's residual.",
            "1.0: unblurred pairs measure ≤ 0.35, 0.5 px blur 3.7-8.8.",
        ),
        "misfit_floor": (
            "bool",
            "Test window residuals against the pair's own typical misfit "
            "(features/misfit.py), not against sensor noise alone.",
            "On: JPEG, sharpening and denoising add misfit the noise estimate misses; "
            "without the floor Adirondack JPEG q85 kept 14 of 883 matches, with it 728.",
        ),
        "correlated_misfit": (
            "bool",
            "Scale the residual part of σ_d² by the residual's pooled autocorrelation.",
            "Off: on JPEG and ISP renders the factor is 0.9-1.4 and changes no figure; on "
            "pairs with a relative blur it over-states σ (within σ 0.83-0.87).",
        ),
        "typical_misfit": (
            "noise variances",
            "Median window residual a pair without ISP processing shows; the floor is "
            "max(1, median / this).",
            "6: clean real pairs measure 2.0 (Middlebury-Q) and 5.7 (motorcycle).",
        ),
        "typical_normalized": (
            "fraction of window variance",
            "The same for the normalised residual s² / window variance.",
            "0.02: clean 0.014 (Adirondack), 0.029 (motorcycle); JPEG q85 0.073.",
        ),
        "normalized_tail": (
            "σ_MAD",
            "The normalised residual's bound is also raised to median + this × σ_MAD of the "
            "pair's own windows where that is larger.",
            "2: clean pairs stay at 0.04 (Adirondack unchanged); denoised Adirondack keeps "
            "415 matches instead of 311, Piano JPEG q85 517 instead of 443.",
        ),
        "cfa_filter": (
            "bool",
            "Filter both images by [1, 2, 1] / 4 (x and y) before the sub-pixel fit when both "
            "still carry their demosaicer's CFA phase (features/cfa.py).",
            "On: two images on their sensor grids pull d toward even disparities (−0.03 to "
            "−0.04 px on ISP renders at d = 16.3, within σ 0.37-0.55; after it 0.69-0.74).",
        ),
        "min_cfa": (
            "fraction",
            "CFA phase contrast of both images (max/min − 1 of the high-pass energy over the "
            "2×2 phase classes) above which cfa_filter acts.",
            "0.2: demosaiced images measure 0.5-1.0; resampled or Middlebury images 0.01-0.03.",
        ),
        "wide_floor": (
            "misfit floor",
            "A pair whose misfit floor reads at least this is compression-limited: its "
            "sub-pixel fit is redone with the wide window on prefiltered images.",
            "5: JPEG q85/q70 read 6-22 and the phone pairs above 5, clean pairs 1-2.3, JPEG q95 "
            "1.9-3.6, denoised 1.7-4.4. Adirondack q85/q70 median 0.041/0.061 -> 0.026/0.037 px.",
        ),
        "wide_radius": (
            "px",
            "Window half size of the compression-limited fit (the NCC search keeps radius).",
            "11 (23 × 23): 9 reads 0.045 px on Adirondack q70, over the issue's 0.039.",
        ),
        "wide_sigma_w": (
            "px",
            "Gaussian weight σ of the compression-limited fit's window.",
            "5: the default's ratio radius / σ_w ≈ 2.3 kept.",
        ),
        "wide_prefilter_px": (
            "px",
            "Gaussian σ applied to both images before the compression-limited fit (the noise "
            "model is scaled by its Σk²).",
            "0.5: damps the frequencies the quantiser coarsened (Adirondack q70 0.043 -> 0.037 "
            "px); 1.0 leaves few windows.",
        ),
        "wide_correlated": (
            "bool",
            "In the compression-limited fit, σ_d from the residual's pooled autocorrelation "
            "(as correlated_misfit), whatever correlated_misfit says; not after blur "
            "equalisation.",
            "On: the quantiser's error is correlated over its blocks; Adirondack q85/q70 within "
            "σ 0.44/0.40 -> 0.52/0.50.",
        ),
    },
}

__all__ = ["KNOBS"]
