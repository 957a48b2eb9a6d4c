"""Configuration and result of the sparse matcher (:func:`.matching.match_rectified`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError
from phonestereo.features.keypoints import DETECTORS

F64 = NDArray[np.float64]


@dataclass(frozen=True)
class MatchConfig:
    """Parameters of :func:`match_rectified` (defaults tuned on Middlebury and rendered pairs)."""

    #: {"dog", "sift"}.
    detector: str = "dog"
    #: Keypoints searched (strongest first, spread over 8 × 8 px cells). DoG: while fewer than half
    #: of them pass the NCC search tests, the next candidates are searched in place of those that
    #: failed, up to 4 × as many (:mod:`~.search_budget`).
    max_keypoints: int = 2000
    #: ``dog_sigma``, ``dog_k``, ``contrast``, ``edge_ratio``: DoG scales (px), minimum |DoG| in
    #: units of its noise σ, Lowe's edge ratio.
    dog_sigma: float = 1.0
    #: See ``dog_sigma`` above.
    dog_k: float = 1.6
    #: See ``dog_sigma`` above.
    contrast: float = 5.0
    #: See ``dog_sigma`` above.
    edge_ratio: float = 10.0
    #: ``radius``, ``sigma_w``: int, float. Window half size (px) and Gaussian weight σ (px) of the
    #: sub-pixel fit; the NCC search uses the same window.
    radius: int = 7
    #: See ``radius`` above.
    sigma_w: float = 3.0
    #: Rows searched either side of the epipolar row, px.
    row_tolerance: int = 3
    #: ``min_score``, ``uniqueness``, ``min_curvature``: NCC peak ≥ min_score; second-best peak
    #: elsewhere in the band < uniqueness × peak; −∂²NCC/∂x² (and ∂y²) at the peak ≥ min_curvature
    #: (per px²).
    min_score: float = 0.8
    #: See ``min_score`` above.
    uniqueness: float = 0.9
    #: See ``min_score`` above.
    min_curvature: float = 0.01
    #: ``lr_check``, ``lr_tolerance``: bool, int. Left–right consistency and its tolerance, px.
    lr_check: bool = True
    #: See ``lr_check`` above.
    lr_tolerance: int = 1
    #: ``slant``, ``max_slant``: bool, float. Fit the disparity gradient in the window, and its
    #: bound (px/px).
    slant: bool = True
    #: See ``slant`` above.
    max_slant: float = 0.5
    #: ``max_iter``, ``tol``: int, float. Gauss–Newton iterations and convergence threshold, px.
    max_iter: int = 10
    #: See ``max_iter`` above.
    tol: float = 1e-3
    #: |sub-pixel − parabola start| allowed in d and e, px.
    max_shift: float = 0.7
    #: Residual σ / window σ (≈ √(1 − ZNCC²)) allowed after the fit, times √ of the pair's
    #: normalised misfit floor (``typical_normalized``), or the pair's own upper tail when larger
    #: (``normalized_tail``).
    max_normalized_residual: float = 0.2
    #: Residual σ / noise σ_r allowed (the window must fit to a few times the noise), times √ of the
    #: pair's misfit floor (``typical_misfit``).
    max_residual_ratio: float = 4.0
    #: Largest σ_d kept, px.
    max_sigma_d: float = 0.25
    #: ``e_floor_px``, ``e_k_mad``: Row-error filter: |e − affine fit| ≤ max(floor, k·σ_MAD).
    e_floor_px: float = 0.5
    #: See ``e_floor_px`` above.
    e_k_mad: float = 5.0
    #: ``hist_bin_px``, ``hist_min_count``: float, int. Histogram filter.
    hist_bin_px: float = 1.0
    #: See ``hist_bin_px`` above.
    hist_min_count: int = 3
    #: ``support_k``, ``support_tol_px``, ``min_support``: int, float, int. Neighbour-support filter
    #: (min_support = 0 disables it).
    support_k: int = 8
    #: See ``support_k`` above.
    support_tol_px: float = 1.0
    #: See ``support_k`` above.
    min_support: int = 1
    #: Per-pixel image noise σ, DN. None: estimated from each image (median of a Laplacian,
    #: :func:`~phonestereo.features.crlb.noise_sigma`) and capped by the typical residual of the
    #: window fits, √median(s² / (1 + a²)), since fine texture inflates the former.
    noise_sigma: float | None = None
    #: σ_d from max(noise, residual misfit) (True) or from the noise alone (pure CRLB).
    residual_sigma: bool = True
    #: Measure the pair's relative blur on the NCC matches and blur the sharper image by it before
    #: the sub-pixel fit (:mod:`~phonestereo.features.blur`); the noise σ of the blurred image is
    #: computed from the kernel.
    equalise_blur: bool = True
    #: The pair is equalised only when its blur difference adds at least this many noise variances
    #: to a window's residual (``BlurEstimate.misfit_ratio``); unblurred pairs measure ≤ 0.35, one
    #: image blurred by σ = 0.5 px 3.7–8.8 (Middlebury, motorcycle).
    min_blur_misfit: float = 1.0
    #: Measure the pair's own misfit (:mod:`~phonestereo.features.misfit`) and test the residuals
    #: against it: a window is dropped when it fits much worse than the pair's typical window, not
    #: worse than sensor noise alone would allow. JPEG, sharpening and denoising lower the image's
    #: noise estimate and add misfit: without the floor the residual tests removed 55–100 % of the
    #: windows (Adirondack JPEG q85: 14 matches of 883 clean; with it 728).
    misfit_floor: bool = True
    #: Scale the residual part of σ_d², σ_e² by the residual's pooled autocorrelation (the sandwich
    #: with C(δ) instead of a white σ²; :func:`~.misfit.correlation_factor`). Off: on JPEG and ISP
    #: renders the factor is 0.9–1.4 and changes no figure (within σ 0.65–0.69 either way), while on
    #: pairs with a relative blur it reads the deterministic, even misfit as correlated noise and
    #: over-states σ (within σ 0.83–0.87 instead of 0.60–0.64).
    correlated_misfit: bool = False
    #: The median window residual (in noise variances σ_L² + a²σ_R²) that a pair without ISP
    #: processing already shows and that does not raise the floor: clean real pairs measure 2.0
    #: (Adirondack, Piano) and 5.7 (motorcycle, GT-consistent left); JPEG q95 / q85 / q70 12 / 52 /
    #: 132 (Adirondack). The floor is max(1, median / 6). It is measured in units of the pair's
    #: *input* noise model, before blur equalisation, and applies after it too: the equalisation
    #: lowers the computed noise of the blurred image, not the misfit a clean pair shows, so in the
    #: blurred image's units a clean but blurred pair would read a floor (motorcycle, one image
    #: blurred 0.7–1 px: median error 1.2–1.4×), while in the input's units it reads ≤ 1 and nothing
    #: changes; a phone pair's ISP misfit raises it either way (phone_wide_ultra: ≥ 100 matches on
    #: 15 of 16 pairs, 0–22 per pair when the floor was skipped after equalisation; the sharpened
    #: motorcycle keeps 511 of 565 instead of 397). The clean motorcycle pair reads 14 (a misfit
    #: that grows with the windows' contrast: its surfaces, and the image–GT offset, not an ISP), so
    #: its floor is 2.3 and it keeps 605 matches at 0.0727 px instead of 457 at 0.0642 (418 at 0.063
    #: before the floor): the 456 windows that a floor of 1 keeps still read 0.0642 px, the 149 it
    #: adds 0.0987 (their σ_d 0.035 against 0.026 px says so). ``typical_misfit`` = 14 gives those
    #: figures back but the degraded pairs lose their matches (Adirondack JPEG q95 / q85 / q70 68 /
    #: 53 / 53 %, denoised 30 %; Piano q85 51 %), as does a floor from the intercept of the
    #: residual's regression on the window contrast (motorcycle q85 / q70 51 / 54 %: JPEG's error
    #: grows with contrast too).
    typical_misfit: float = 6.0
    #: The same for the normalised residual s² / window variance: clean 0.014 (Adirondack), 0.029
    #: (motorcycle); JPEG q85 0.073, q70 0.10. The normalised test's bound is raised by max(1,
    #: median / 0.02): at 0.03 the motorcycle's figures stay as before, but JPEG q85 keeps only
    #: 56–67 % of the matches.
    typical_normalized: float = 0.02
    #: With ``misfit_floor``, the normalised test's bound is also raised to the upper tail of the
    #: pair's own converged windows, median + k·σ_MAD of s² / window variance
    #: (:func:`~.misfit.misfit_tail`), where that is larger. k = 2: on the clean pairs the tail
    #: stays at or near the bound (Adirondack 883 matches, 0.0188 px, as without it; Piano 663 /
    #: 0.0673 and motorcycle 605 / 0.0727 instead of 641 / 0.0670 and 565 / 0.0725), while denoised
    #: and JPEG pairs, whose ratio spreads because texture is lost on one side (Adirondack denoised:
    #: 10th–90th percentile 0.005–0.19), keep the windows whose disparity is as good as the rest
    #: (Adirondack denoised 311 → 415 matches at 0.0370 → 0.0343 px, Piano JPEG q85 443 → 517). k =
    #: 3 keeps ~5 % more on the degraded pairs but moves the motorcycle's clean median by +3 %.
    normalized_tail: float = 2.0
    #: When both images still carry their demosaicer's colour-filter-array phase (each on its sensor
    #: grid: :func:`~.cfa.cfa_phase_contrast` ≥ ``min_cfa``), filter both by [1, 2, 1] / 4 along x
    #: and y before the sub-pixel fit (:func:`~.cfa.suppress_cfa`): the grid-locked interpolation
    #: error otherwise pulls d toward even disparities (−0.03 to −0.04 px at d = 16.3 on ISP
    #: renders, within σ 0.37–0.55). Images resampled off the sensor grid (rectification at a scale,
    #: Middlebury) measure ≤ 0.03 and are not touched.
    cfa_filter: bool = True
    #: Phase contrast of both images above which ``cfa_filter`` acts: demosaiced images measure
    #: 0.5–1.0 (ISP renders, re-mosaiced Middlebury), others 0.01–0.03.
    min_cfa: float = 0.2
    #: A pair whose misfit floor (``typical_misfit``) reads at least this is compression- limited,
    #: and its sub-pixel fit is redone with the wide window below. 5: JPEG q85 / q70 read 8.7 / 22
    #: (Adirondack), 6.0 / 12.8 (Piano), 10 / 19 (motorcycle) and the phone pairs above it, while
    #: the clean pairs read 1–2.3, JPEG q95 1.9–3.6 and the denoised right images 1.7–4.4 (their
    #: misfit is lost texture, which a larger window does not average away). There the quantisation
    #: error, not the sensor noise, is the window's residual: it is spread over the 8 × 8 blocks'
    #: high frequencies, so σ_d falls with the window's area and with damping the frequencies the
    #: quantiser coarsened. Adirondack q85 / q70 0.0410 / 0.0613 → 0.0262 / 0.0371 px median error,
    #: Piano q70 0.1205 → 0.0912; phone_wide_ultra 79–252 → 97–302 matches per pair, LR/RL RMS z
    #: 0.47–0.92 → 0.45–1.00. Its cost: the motorcycle's depth edges, q85 / q70 0.0857 / 0.0925 →
    #: 0.1009 / 0.1087 px (within the issue's 1.5 × clean).
    wide_floor: float = 5.0
    #: ``wide_radius``, ``wide_sigma_w``: int, float. The compression-limited fit's window half size
    #: and Gaussian weight σ, px (23 × 23, σ_w 5; the NCC search keeps ``radius``). 19 × 19 (σ_w 4)
    #: reads 0.0453 px on Adirondack q70, over the 0.0388 limit; 29 × 29 (σ_w 6.5) 0.0414 without
    #: the prefilter.
    wide_radius: int = 11
    #: See ``wide_radius`` above.
    wide_sigma_w: float = 5.0
    #: Gaussian σ applied to both images before the compression-limited fit, px (a symmetric blur
    #: does not move d; the noise model is scaled by its Σk², so the floor keeps its meaning). 0.5:
    #: Adirondack q70 0.0434 → 0.0370 px at 23 × 23; 1.0 leaves few windows whose residual fits the
    #: (then tiny) computed noise.
    wide_prefilter_px: float = 0.5
    #: In the compression-limited fit, σ_d uses the residual's pooled autocorrelation
    #: (``correlated_misfit``) whatever that knob says: the quantiser's error is correlated over its
    #: 8 × 8 blocks and the prefilter, and a white σ over 23 × 23 pixels counts them as independent.
    #: Adirondack q85 / q70 within σ of the GT 0.44 / 0.40 → 0.52 / 0.50 (the 15 × 15 fit read 0.50
    #: / 0.44). Not when the pair was blur-equalised: that is the reason ``correlated_misfit`` is
    #: off by default (a blur difference's even misfit read as correlated noise, σ over-stated); the
    #: phone pairs are (their tele is sharper), and with the factor their σ_d doubled (0.033 → 0.067
    #: px median) and the LR/RL RMS z fell to 0.21–0.51, so they keep the white σ and their figures
    #: (an open question: the LR/RL statistic cannot tell whether their σ_d is honest, see
    #: tests/_support/match_phone.py).
    wide_correlated: bool = True

    @classmethod
    def fast(cls, **overrides: Any) -> MatchConfig:
        """The speed preset: 400 keypoints, translation-only fit, no left–right search, ±2 rows.

        The left–right search costs as much as the forward one and, after the uniqueness
        test, removes ~1 % of the matches on Middlebury; the slant matters on strongly slanted
        surfaces (Piano: 0.065 → 0.072 px median error).
        """
        preset: dict[str, Any] = {
            "max_keypoints": 400,
            "slant": False,
            "lr_check": False,
            "row_tolerance": 2,
        }
        return cls(**{**preset, **overrides})

    def __post_init__(self) -> None:
        if self.detector not in DETECTORS:
            raise InputError(f"detector must be one of {DETECTORS}, got '{self.detector}'")
        if int(self.radius) != self.radius or not 2 <= self.radius <= 32:
            raise InputError(f"radius must be an integer 2..32 px, got {self.radius}")
        if self.row_tolerance < 0 or int(self.row_tolerance) != self.row_tolerance:
            raise InputError(f"row_tolerance must be an integer >= 0, got {self.row_tolerance}")
        if self.noise_sigma is not None and not self.noise_sigma > 0:
            raise InputError(f"noise_sigma must be > 0 DN or None, got {self.noise_sigma}")
        if int(self.wide_radius) != self.wide_radius or not 2 <= self.wide_radius <= 32:
            raise InputError(f"wide_radius must be an integer 2..32 px, got {self.wide_radius}")
        if not self.wide_sigma_w > 0 or self.wide_prefilter_px < 0:
            raise InputError("wide_sigma_w must be > 0 and wide_prefilter_px >= 0")
        if not 0 < self.sigma_w or self.max_keypoints < 1:
            raise InputError("sigma_w must be > 0 and max_keypoints >= 1")


@dataclass(frozen=True, eq=False)
class MatchResult:
    """Sub-pixel matches of a rectified pair and what every stage did."""

    #: ndarray, shape (N, 2). Left (wide) pixels (x, y) of the matches (window centres,
    #: integer-valued).
    xy: F64
    #: ``d``, ``e``: ndarray, shape (N,). Disparity x_left − x_right and non-disparity error y_left
    #: − y_right, px.
    d: F64
    #: See ``d`` above.
    e: F64
    #: ``sigma_d``, ``sigma_e``: ndarray, shape (N,). 1-σ uncertainty of d and e (Cramér–Rao from
    #: gradients and noise, raised to the fit's residual misfit), px.
    sigma_d: F64
    #: See ``sigma_d`` above.
    sigma_e: F64
    #: ndarray, shape (N,). NCC of the integer search peak.
    score: F64
    #: ndarray, shape (N,). Weighted NCC of the window after the sub-pixel fit.
    zncc: F64
    #: dict of str to int. Survivors after each stage, in order (``keypoints`` … ``matches``).
    counts: dict[str, int] = field(default_factory=dict)
    #: Per-pixel noise σ of the left and right images used, DN (after blur equalisation).
    noise_sigma: tuple[float, float] = (float("nan"), float("nan"))
    #: (x, y, w, h) searched, left pixels.
    roi: tuple[int, int, int, int] = (0, 0, 0, 0)
    #: Wall time of the call.
    seconds: float = 0.0
    #: Empty when there are matches, else why there are none (a data problem, not an error).
    reason: str = ""
    #: Gaussian σ added to the left and right image to equalise their blur, px (one is 0).
    blur_added: tuple[float, float] = (0.0, 0.0)
    #: Both images carried a CFA phase and were filtered before the sub-pixel fit
    #: (``MatchConfig.cfa_filter``).
    cfa_filtered: bool = False
    #: Window half size of the sub-pixel fit, px: ``MatchConfig.radius``, or ``wide_radius`` when
    #: the pair's misfit floor said it is compression-limited (0 when nothing was fitted).
    radius: int = 0
    #: Keypoints searched beyond ``max_keypoints`` in place of windows that failed the NCC
    #: search (:mod:`~.search_budget`; counted in ``counts["keypoints"]``).
    refilled: int = 0

    def __post_init__(self) -> None:
        for name in ("xy", "d", "e", "sigma_d", "sigma_e", "score", "zncc"):
            arr = np.array(getattr(self, name), dtype=np.float64)  # own copy, read-only
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)
        object.__setattr__(self, "counts", dict(self.counts))

    def __len__(self) -> int:
        return len(self.d)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"matches": [{"x", "y", "d", "e", "sigma_d", "sigma_e", "score"}], …}``."""
        rows = np.column_stack([self.xy, self.d, self.e, self.sigma_d, self.sigma_e, self.score])
        keys = ("x", "y", "d", "e", "sigma_d", "sigma_e", "score")
        return {
            "matches": [
                {k: round(float(v), 5) for k, v in zip(keys, row, strict=True)} for row in rows
            ],
            "seconds": round(self.seconds, 4),
            "counts": dict(self.counts),
            "noise_sigma": [round(s, 4) for s in self.noise_sigma],
            "blur_added": [round(s, 3) for s in self.blur_added],
            "cfa_filtered": self.cfa_filtered,
            "radius": self.radius,
            "refilled": self.refilled,
            "roi": list(self.roi),
            "reason": self.reason,
        }
