"""The ROI measurement's parameters (:func:`~phonestereo.flows.roi_disparity.measure_roi`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

from phonestereo.features.matching import MatchConfig


@dataclass(frozen=True)
class RoiConfig:
    """Parameters of the ROI measurement.

    The rectification mode and whether the W-T scale is applied are not fields here: they are
    the flow's switches (:attr:`FlowConfig.canonical`, :attr:`FlowConfig.wt_scale`), passed
    to :func:`measure_roi` explicitly, so one configuration cannot say two things.
    """

    #: ROI expansion factor per side (Fig. 4-2), ≥ 1.
    expand: float = 1.6
    #: Nearest depth searched (sets the largest disparity).
    z_min_m: float = 0.4
    #: The smallest disparity searched, px: −2, a little beyond infinity, for a calibration whose
    #: disparity is off by up to 2 px. The application flow lowers it to reach −correction − 1
    #: where a learned correction is positive (a far point reads −correction: random-3004's +7.5
    #: px put its charts from 3.2 m beyond −2 px, :func:`reaching`), so the default is only what
    #: an unlearned ROI needs.
    far_disparity_px: int = -2
    #: ``majority_bin_px``, ``majority_tol_px``, ``majority_tol_rel``: Histogram bin of the majority
    #: vote and the band kept about it (max of px, relative).
    majority_bin_px: float = 0.5
    #: See ``majority_bin_px`` above.
    majority_tol_px: float = 0.75
    #: See ``majority_bin_px`` above.
    majority_tol_rel: float = 0.04
    #: Fewest matches on the surface for a measurement.
    min_matches: int = 12
    #: With fewer on the surface after blur equalisation, the unblurred pair is tried too.
    enough_matches: int = 60
    #: Grid step of the window's rectification maps (exact on the grid, splines between).
    map_step_px: int = 16
    #: ``coarse_min_zncc``, ``fine_range_px``: float, int. The coarse whole-box correlation must
    #: reach this ZNCC; the fine search is then ±``fine_range_px`` around it (repetitive texture
    #: stays unambiguous).
    coarse_min_zncc: float = 0.5
    equalise_blur: bool = True
    coarse_rows: int = 8
    #: ``coarse_expand``, ``max_ambiguity``: The coarse box is the ROI expanded this much; a second
    #: correlation peak (> 2 px away, a separate local maximum) above ``max_ambiguity`` × the first
    #: makes the measurement fail as ambiguous.
    coarse_expand: float = 3.0
    #: See ``coarse_expand`` above.
    max_ambiguity: float = 0.97
    #: The first coarse peak must beat the second tile by tile: the paired t of the tiles' ZNCC
    #: differences (:func:`~phonestereo.flows.coarse.peak_contrast`) must reach this, else the
    #: measurement fails as ambiguous (a periodic texture's alias).
    min_peak_t: float = 2.0
    #: The first coarse peak must also beat, tile by tile, every further peak within this fraction
    #: of its ZNCC (a periodic texture's aliases: random-3014's truth read 0.87 of an alias 109 px
    #: away and t = −0.2 against it, while its measured charts beat theirs at t ≥ 2.2; on the 33
    #: bench sets it gates 2 more of 594 charts); 1 tests the second peak only.
    alias_ratio: float = 0.85
    #: When the W-T scale the coarse box's tiles show moves its edges by more than this against its
    #: centre, the tele window is corrected for that scale before the coarse and fine steps (only
    #: with the W-T scale fix on; :func:`~phonestereo.flows.coarse_gate.coarse_peak`).
    coarse_max_scale_drift_px: float = 4.0
    #: The fine search is ±``fine_range_px`` around the coarse peak (repetitive texture stays
    #: unambiguous; see ``coarse_min_zncc``).
    fine_range_px: int = 3
    #: The surface's matches must form one band about the plane: when the fuller side beyond it (up
    #: to 3 majority tolerances) holds this many times the band's matches, the measurement fails
    #: (two disparities, no single one).
    max_band_split: float = 0.5
    # Wide and tele have different optics: a window never fits to the noise level (the
    # Middlebury-tuned residual-to-noise test would reject every match on a high-contrast
    # chart), so only the contrast-relative residual test is kept; σ_d still includes misfit.
    # After the coarse step the search is ±3 px: no slant fit and no left-right check are
    # needed, and 450 keypoints are plenty for the disparity plane. Measured on four benches
    # against 1200 keypoints with both: median 0.37-0.74 % → 0.37-0.58 %, p90 1.10-2.10 % →
    # 0.89-1.52 %, ~130 ms → ~53 ms per capture.
    match: MatchConfig = field(
        default_factory=lambda: MatchConfig(
            max_keypoints=450,
            max_residual_ratio=1e9,
            max_normalized_residual=0.35,
            slant=False,
            lr_check=False,
        )
    )


def reaching(cfg: RoiConfig, correction_px: float) -> RoiConfig:
    """``cfg`` with the searched disparities reaching a learned correction's far points: the
    measured disparity of a far point is −correction, so ``far_disparity_px`` becomes at most
    −⌈correction⌉ − 1 (a pixel beyond infinity: the correction is known to a few tenths). A
    correction below 1 px, or negative, leaves it (the near end, from ``z_min_m``, has room to
    spare); random-1010 (+0.5 px) lost 3 charts whose coarse ZNCC sits at the 0.5 threshold
    when its search was widened by 1 px for nothing.

    >>> [reaching(RoiConfig(), c).far_disparity_px for c in (7.5, 2.1, 0.5, -3.0, float("nan"))]
    [-9, -4, -2, -2, -2]
    """
    if not math.isfinite(correction_px):
        return cfg
    far = min(cfg.far_disparity_px, -math.ceil(correction_px) - 1)
    return replace(cfg, far_disparity_px=far) if far != cfg.far_disparity_px else cfg


#: Margin the coarse step's ±``coarse_rows`` keep about a known row error, px: the row error of
#: one capture scatters by ±1 px about its set's and a heating drift still to come moves it by a
#: few more (:func:`centred_rows`).
ROW_MARGIN_PX = 3


def centred_rows(cfg: RoiConfig, e_px: float) -> int:
    """The whole-pixel row offset to search about for a known row error ``e_px`` (a learned
    one, or a capture's W-T measurement): 0 while rows ±``coarse_rows`` about 0 hold it with
    :data:`ROW_MARGIN_PX` to spare (searches and numbers unchanged), else ``round(e_px)``.
    Over 73 bench sets the coarse e reached −8 px (random-3037), random-3056's 11–12 px.

    >>> [centred_rows(RoiConfig(), e) for e in (0.0, 4.9, -5.2, 11.6, float("nan"))]
    [0, 0, -5, 12, 0]
    """
    if not math.isfinite(e_px) or abs(e_px) <= cfg.coarse_rows - ROW_MARGIN_PX:
        return 0
    return round(float(e_px))
