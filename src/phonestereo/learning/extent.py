"""What a learned correction knows, and the σ it owes where it does not (issue 18).

The σ of a learned correction (:mod:`~phonestereo.learning.field`,
:mod:`~phonestereo.learning.lookup`) is the statistical error of its fit. Three more parts
are common to every capture it corrects, so a set's captures are all right or all wrong
together unless σ carries them:

- **systematic (common-mode) scale** ``rho``: the IPD ruler gives depth as f_wide·IPD/ipd_px,
  so the correction inherits every relative error of that scale — the spread of the learned
  captures' own relative offsets (their focus, pose and landmark biases differ), averaged over
  the *distance layers* they were learned at, not over the captures: captures at one distance
  share its focus state and see the same faces at one scale, so their offsets do not average
  out among themselves, while layers far apart in disparity (> ``LAYER_GAP``) do — and the wide's
  focal length at the working focus, which the IPD ruler cannot see (depth from IPD and from
  disparity scale alike with it; a phone wide of ~4 mm breathes ~0.4 % per dioptre of focus
  between the factory calibration and use, §3.5, which the wide-breathing fix takes out only
  as well as its focus input allows), and the ruler's own biases. σ_sys = rho · d;
- **extrapolation in disparity**: beyond the learned disparities the correction's gain is
  only as good as the capture-level regression of offset on disparity says (captures, not
  faces, are the independent units); σ_x = σ_gain · (distance outside the learned range).
  When the learning captures' times (or temperatures) move with their distances, a warm-up
  drift is indistinguishable from a gain: the gain's σ under a possible drift
  (``drift_gain_sigma``, :attr:`~phonestereo.learning.heating_term.HeatingTerm.gain_sigma`)
  then applies about the learned centre d̄ at every disparity, σ = σ_g,drift · |d − d̄|
  (the larger of the two is taken);
- **extrapolation over the sensor**: a query far from every learned sensor position carries
  the capture-to-capture scatter once more per unit of distance beyond ``reach``.

Examples
--------
>>> from phonestereo.learning.observation import Observation
>>> obs = [Observation(x, 750.0, d - 0.3, d, 18 / d, "landscape", "", 0.0, None, f"c{i}")
...        for i, (x, d) in enumerate([(900.0, 12.0), (1000.0, 12.1), (1100.0, 11.9),
...                                    (950.0, 12.05)])]
>>> ext = LearnedExtent.from_observations(obs)
>>> (round(ext.d_lo_px, 1), round(ext.d_hi_px, 1))
(11.6, 11.8)
>>> inside, far = ext.extra_sigma_px([[1000.0, 750.0, 11.7], [1000.0, 750.0, 4.5]])[1]
>>> bool(far > 10 * inside)       # one distance learned: the gain is unknown below it
True
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from phonestereo.learning.lookup import as_queries
from phonestereo.learning.observation import as_observation_array, corrections_px

#: Relative uncertainty of the common scale a store cannot see in its own scatter (see module
#: docstring): with it the 29 bench sets' common-mode errors (each set's mean error) over their
#: ρ have an rms of 1.02 (0.25 % made it 0.75, 0 1.13), once the faces carry the pooled radial
#: fit (docs/module-random.md, session 14; 0.25 % in session 13 matched the median ρ to the rms
#: common mode of the time, 0.36 %). Session 16 (modules learned warm, ρ averaged over distance
#: layers): 1.08, and 0.89 with the correction's fit σ beside ρ, so it stays. A reported wide
#: focus's own σ is per capture, not in it (``FlowConfig.wide_focus_sigma_dioptre``).
FOCAL_REL_SIGMA = 0.001

#: Relative gap in mean measured disparity that separates two distance layers of learning
#: captures (``rho`` averages over layers). The bench's face charts stand at 1–3 m in layers
#: whose captures lie within ±5 % of each other and ≥ 40 % apart; 20 % splits them and merges a
#: continuous spread (population faces) into few layers, which only makes ``rho`` larger.
LAYER_GAP = 0.2

_MAD = 1.4826


@dataclass(frozen=True)
class LearnedExtent:
    """The disparity range and sensor positions a correction was learned on, and its
    systematic σ parts (module docstring).
    """

    #: ``d_lo_px``, ``d_hi_px``: Learned (measured) disparities, 5th–95th percentile, px.
    d_lo_px: float
    #: See ``d_lo_px`` above.
    d_hi_px: float
    #: Relative common-mode σ (capture spread ⊕ focal), dimensionless.
    rho: float
    #: Its capture-spread part.
    rho_captures: float
    #: σ of the correction's slope over disparity from the capture-level regression, px/px (inf when
    #: the captures span too little disparity to tell).
    gain_sigma: float
    #: Capture-to-capture scatter of the per-capture mean offsets, px.
    capture_sigma_px: float
    #: Sensor distance from the nearest learned position that is still "learned", px.
    reach_px: float
    n_captures: int
    tree: Any
    #: σ of the gain with a drift over the learning captures' time or temperature in the fit,
    #: px/px (NaN: not known; module docstring).
    drift_gain_sigma: float = float("nan")
    #: d̄, the learned captures' mean measured disparity, px (where the offset is pinned).
    d_centre_px: float = float("nan")
    #: Distance layers the captures were learned at (:func:`distance_layers`).
    n_layers: int = 1

    @classmethod
    def from_observations(
        cls,
        observations: Any,
        residual_px: Any = None,
        *,
        focal_rel_sigma: float = FOCAL_REL_SIGMA,
        drift_gain_sigma: float = float("nan"),
        lever_var_px2: Any = None,
    ) -> LearnedExtent:
        """From learned observations (one bucket) and, when given, their residuals about the
        fitted correction (px; default: about their mean), the gain's σ with the drift in
        the fit (px/px, :class:`~phonestereo.learning.heating_term.HeatingTerm`) and the
        variance each capture's mean correction owes its W-T scale error (G,) px², in
        ``np.unique`` order of the capture ids
        (:func:`~phonestereo.learning.wt_lever.capture_lever_variance`): a chart at the tele's
        centre does not carry it, so the capture and common-mode spreads lose it."""
        obs = as_observation_array(observations)
        c = corrections_px(obs)
        r = c - np.mean(c) if residual_px is None else np.asarray(residual_px, dtype=np.float64)
        d = np.asarray(obs["d_measured_px"], dtype=np.float64)
        d_exp = np.asarray(obs["d_expected_px"], dtype=np.float64)
        cid = np.unique(obs["capture_id"], return_inverse=True)[1].ravel()
        g = int(cid.max()) + 1 if cid.size else 0
        n = np.maximum(np.bincount(cid, minlength=g), 1)
        mean_r = np.bincount(cid, r, g) / n
        mean_rel = np.bincount(cid, r / np.where(d_exp > 0, d_exp, np.nan), g) / n
        mean_c = np.bincount(cid, c, g) / n
        mean_d = np.bincount(cid, d, g) / n
        lev = np.zeros(g) if lever_var_px2 is None else np.asarray(lever_var_px2, np.float64)
        mean_dexp = np.bincount(cid, d_exp, g) / n
        with np.errstate(divide="ignore", invalid="ignore"):
            lev_rel = np.where(mean_dexp > 0, lev / mean_dexp**2, np.nan)
        cap = _less_noise(_robust_sd(mean_r), lev) if g >= 4 else 0.0
        rho_c = _less_noise(_robust_sd(mean_rel), lev_rel) if g >= 4 else 0.0
        gain_sigma = _slope_sigma(mean_d, mean_c)
        xy = np.column_stack([obs["x_px"], obs["y_px"]])
        span = np.ptp(xy, axis=0) if len(xy) else np.zeros(2)
        reach = max(0.25 * float(np.hypot(*span)), 150.0)
        lo, hi = np.percentile(d, [5, 95]) if d.size else (np.nan, np.nan)
        # Divided by √(layers), not √G: the captures of one distance share its focus and the
        # chart's faces, so their relative offsets do not average out among themselves (with
        # /√G the within-σ of folded-x3 seed 0 fell to 33 %; without any division the 29 bench
        # sets' mean errors read 0.71 of ρ in rms, with /√layers 1.08: docs/module-random.md,
        # session 16).
        layers = distance_layers(mean_d)
        rho = float(np.hypot(rho_c / np.sqrt(max(layers, 1)), focal_rel_sigma))
        return cls(
            float(lo), float(hi), rho, float(rho_c),
            gain_sigma, float(cap), reach, g, cKDTree(xy) if len(xy) else None,
            float(drift_gain_sigma), float(np.mean(mean_d)) if g else float("nan"), layers,
        )

    def outside_px(self, d: Any) -> np.ndarray:
        """How far disparities lie outside the learned range, px (0 inside)."""
        d = np.asarray(d, dtype=np.float64)
        return np.maximum(np.maximum(self.d_lo_px - d, d - self.d_hi_px), 0.0)

    def extra_sigma_px(self, query: Any, correction_px: Any = 0.0) -> tuple[np.ndarray, np.ndarray]:
        """(σ_sys, σ_extrapolation) at (x, y, d_measured) queries (N, 3) whose correction is
        ``correction_px`` (σ_sys scales the corrected disparity), px."""
        q = as_queries(query)
        sys = self.rho * np.abs(q[:, 2] + np.asarray(correction_px, dtype=np.float64))
        dd = self.outside_px(q[:, 2])
        with np.errstate(invalid="ignore"):
            ext = np.where(dd > 0, self.gain_sigma * dd, 0.0)
        if np.isfinite(self.drift_gain_sigma) and np.isfinite(self.d_centre_px):
            ext = np.maximum(ext, self.drift_gain_sigma * np.abs(q[:, 2] - self.d_centre_px))
        if self.tree is not None:
            dist, _ = self.tree.query(q[:, :2])
            ext = np.hypot(ext, self.capture_sigma_px * np.maximum(dist / self.reach_px - 1, 0))
        return sys, ext

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "d_lo_px": round(self.d_lo_px, 4), "d_hi_px": round(self.d_hi_px, 4),
            "rho": round(self.rho, 6), "rho_captures": round(self.rho_captures, 6),
            "gain_sigma": None if not np.isfinite(self.gain_sigma) else round(self.gain_sigma, 6),
            "capture_sigma_px": round(self.capture_sigma_px, 5), "n_captures": self.n_captures,
            "n_layers": self.n_layers,
            "drift_gain_sigma": None if not np.isfinite(self.drift_gain_sigma) else round(
                self.drift_gain_sigma, 6),
        }


def distance_layers(d_px: Any, gap: float = LAYER_GAP) -> int:
    """How many distance layers captures of mean measured disparities ``d_px`` (G,) px stand
    in: runs of the sorted disparities whose consecutive ratio stays within 1 + ``gap``.

    >>> distance_layers([30.1, 29.0, 15.2, 15.0, 14.6, 10.1, 9.8])
    3
    >>> distance_layers([])
    0
    """
    d = np.sort(np.asarray(d_px, dtype=np.float64).ravel())
    d = d[np.isfinite(d) & (d > 0)]
    if d.size == 0:
        return 0
    return int(1 + np.sum(d[1:] / d[:-1] > 1.0 + gap))


def _robust_sd(v: np.ndarray) -> float:
    v = v[np.isfinite(v)]
    if v.size < 2:
        return 0.0
    return float(_MAD * np.median(np.abs(v - np.median(v))))


def _less_noise(spread: float, noise_var: np.ndarray) -> float:
    """A spread less the typical (median) variance its values owe a known noise, floored at 0."""
    noise = noise_var[np.isfinite(noise_var)]
    if noise.size == 0 or not noise.any():
        return spread
    return float(np.sqrt(max(spread**2 - float(np.median(noise)), 0.0)))


def _slope_sigma(x: np.ndarray, y: np.ndarray) -> float:
    """Standard error of the slope of y on x over captures (inf when it cannot be told: fewer
    than 3 captures, or their disparities span less than 10 % of their mean)."""
    ok = np.isfinite(x) & np.isfinite(y)
    x, y = x[ok], y[ok]
    if x.size < 3:
        return float("inf")
    sxx = float(np.sum((x - x.mean()) ** 2))
    if np.ptp(x) < 0.1 * abs(float(np.mean(x))) or sxx <= 0:
        return float("inf")
    b = float(np.sum((x - x.mean()) * (y - y.mean())) / sxx)
    res = y - y.mean() - b * (x - x.mean())
    s2 = float(np.sum(res**2)) / (x.size - 2) if x.size > 2 else 0.0
    return float(np.sqrt(s2 / sxx))


__all__ = ["FOCAL_REL_SIGMA", "LAYER_GAP", "LearnedExtent", "distance_layers"]
