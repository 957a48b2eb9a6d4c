"""The heating term of a learned correction, indexed by the module temperature (thesis §3.1,
fix option 1 and chapter 5; issue 18 item 4).

A warming module's principal points drift, so the disparity offset a face capture teaches
depends on how warm the module was. The learning captures of a set are taken one after the
other while the module is still warming (the warm-up gate only guarantees most of the drift
has happened), and usually in distance order, so a correction that ignores it learns the
remaining drift as a *gain* over disparity and extrapolates it — a common-mode error that no
statistical σ of the fit shows. Drift and reported temperature follow the same warm-up curve
(both are driven by the same heat), so the offset is linear in the temperature.

:class:`HeatingTerm` learns that slope from the set's own face captures: a capture-level
least-squares fit (captures are the independent units; their observations share one heating
state) of the mean correction c_i on

    c_i = a + g·d_i + k·(T_i − T_ref) + b_x·x̃_i + b_y·ỹ_i,

d_i the capture's mean measured disparity, T_i its reported temperature, x̃, ỹ its mean
sensor position (scaled), T_ref the median learned temperature. The learned observations are
then referred to T_ref (:meth:`HeatingTerm.normalise`) before the correction is fitted, and a
capture at temperature T gets k·(T − T_ref) added with σ_k·|T − T_ref|
(:meth:`HeatingTerm.offset_px`) — when k is significant (|k| > :data:`APPLY_SIGNIFICANCE` σ_k,
3σ: the captures share their layer's errors, so 2σ slopes are often false, and a false
correction moves every capture while a real slope left out only widens σ): a
slope the captures cannot tell from zero would only add its noise to every capture. Without
temperatures (or too few captures, no spread of temperature, no significant slope) the term is
absent and says why; the same fit against the capture time then
gives, when its slope is significant, a σ for the drift still to come (not a correction: the
warm-up curve's τ is unknown, see :attr:`HeatingTerm.index`).

Either way the fit also says how well the captures tell the **gain** g from a drift
(:attr:`HeatingTerm.gain_sigma`: the fits without and with the drift term averaged by their
evidence, so a drift the captures cannot tell from zero widens it by its weight only; session
20). Faces learned near to
far while the module still warms make time and disparity collinear: the drift cannot be
separated from a gain, the field learns it as one, and only this σ shows it (random-1009: the
learned gain read +1.95 %, +1.08 % with the faces' distances interleaved in time; the
captures' gain 1.96 ± 0.27 % alone, 1.16 ± 0.51 % with a linear drift in time, so σ_g =
0.51 % ⊕ 0.80 %; docs/module-random.md, session 13).

Examples
--------
>>> import numpy as np
>>> from phonestereo.learning.observation import Observation
>>> rng = np.random.default_rng(1)
>>> obs = []                             # 12 captures warming from 30 to 31.1 °C, k = 0.3 px/°C
>>> for i in range(12):
...     temp, d = 30.0 + 0.1 * i, 18 / (1 + i // 4)
...     for x in (800.0, 1000.0, 1200.0):
...         c = 0.5 + 0.3 * (temp - 30.0) + rng.normal(0, 0.005)
...         obs.append(Observation(x, 750.0, d - c, d, 1 + i // 4, "landscape", "", 300.0 + i,
...                                temp, f"c{i}"))
>>> term = HeatingTerm.fit(obs)
>>> term.ok, bool(abs(term.slope_px_per_c - 0.3) < 3 * term.slope_sigma < 0.05)
(True, True)
>>> value, sigma = term.offset_px(31.55)              # 1 °C above the learned median
>>> round(float(value), 1), bool(sigma > 0)
(0.3, True)
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.learning.observation import as_observation_array, corrections_px

#: Fewest face captures with a reported temperature for a heating term.
MIN_CAPTURES = 6
#: Smallest spread of the learned temperatures (°C) that can show a slope.
MIN_SPAN_C = 0.05
#: Smallest spread of the learned capture times (s) for the time-indexed σ.
MIN_SPAN_S = 20.0
#: A slope counts (a temperature correction, or a time σ) when it is this many of its σ from
#: zero; below, the term is absent (random-1010: −0.19 ± 0.39 px/°C applied as a correction
#: moved the full flow from 0.69 / 1.01 % to 0.97 / 1.76 %; its true heating drift is 0.03 px).
SIGNIFICANCE = 2.0
#: A temperature slope is *applied* as a correction only from this many of its σ (between
#: SIGNIFICANCE and this, the term is absent and the time-indexed σ carries the drift). σ_k is
#: the capture-level fit's, which takes the captures as independent, yet they share their
#: distance layer's errors and are taken in one order, layer after layer and placement after
#: placement, as the module warms: what they share passes for a slope more often than 2σ says.
#: A correction applied on a false slope moves every later capture by k·(T − T_ref), often ~1 %
#: at 4 m, while a real slope left out only widens σ. Over the 27 random bench sets (20 warm, 7
#: learned cold), three slopes passed 2σ: random-1006 learned cold, −0.64 ± 0.13 px/°C (5.1σ;
#: without it 2.03 % instead of 0.39 %), and two warm sets whose learned temperatures span
#: 0.09–0.16 °C, random-1011 −3.9 ± 1.4 px/°C (2.7σ; 0.76 % with it, 0.25 % without) and
#: random-1002 +0.57 ± 0.23 (2.4σ; 0.24 / 0.54 % with it, 0.20 / 0.34 % without)
#: (docs/module-random.md, session 17).
APPLY_SIGNIFICANCE = 3.0
#: A temperature slope is not applied when the correction it implies at the calibration's own
#: temperature, c̄ − k·(T_ref − T_cal) (the drift linear in temperature since the factory taken
#: back out), exceeds this fraction of the learned faces' expected disparity: at T_cal the
#: factory calibration holds but for the non-thermal effects, and those together make the
#: thesis's whole naive error, ~30 % (§1). random-3072, warm (0.11 °C over the set), read
#: −6.2 ± 1.4 px/°C, 4.4σ across its captures — 54 px of drift since its calibration 8.7 °C
#: cooler, for a learned correction of −1.7 px; applied, every depth read +1.0 % (0 % within σ),
#: without it 0.44 % (94 %): its placements, taken in the same order in every distance layer as
#: the module warmed, carry errors that pass for a slope (docs/module-random.md, session 23).
MAX_CALIBRATION_CORRECTION_REL = 0.3


@dataclass(frozen=True)
class HeatingTerm:
    """A learned disparity offset per °C of module temperature (module docstring)."""

    #: False: no term (``reason`` says why); :meth:`offset_px` then gives 0 ± 0.
    ok: bool
    reason: str
    #: ``slope_px_per_c``, ``slope_sigma``: k and its 1σ, px/°C (reference rectified pixels; px/s
    #: for a time-indexed term).
    slope_px_per_c: float = 0.0
    #: See ``slope_px_per_c`` above.
    slope_sigma: float = 0.0
    #: T_ref, the median learned temperature, °C (t_ref, s, for a time-indexed term).
    reference_c: float = float("nan")
    #: Learned temperatures, min–max, °C (times, s, for a time-indexed term).
    range_c: tuple[float, float] = (float("nan"), float("nan"))
    #: Captures in the fit.
    n_captures: int = 0
    #: {"temperature_c", "time_s"}. What the term is indexed by. With ``"time_s"`` (the captures
    #: report no temperature) the slope is px per second and the term is **not** a correction: the
    #: drift follows an exponential of unknown τ that a line through the learning captures would
    #: overshoot, so :meth:`offset_px` gives 0 and, when the slope is significant
    #: (:data:`SIGNIFICANCE`), σ = |k|·τ·(1 − e^(−|t − t_ref|/τ)): the drift still to come between
    #: t_ref and t on a warm-up curve of time constant τ (``tau_s``) that drifts at k at t_ref.
    index: str = "temperature_c"
    #: τ of the time-indexed σ, s (the flows pass the one the warm-up gate assumes,
    #: ``FlowConfig.warmup_s`` / 2.6).
    tau_s: float = 70.0
    #: σ of the gain over disparity (px per px of d) that the captures can tell when their
    #: times or temperatures move with their distances (module docstring): with an applied
    #: temperature term (the drift taken out of the observations), its σ in the fit with the
    #: drift; otherwise the fits with and without a drift averaged by their evidence
    #: (:func:`_averaged_gain_sigma`: a drift the captures cannot tell from zero widens the
    #: gain's σ by its weight, a clear one by all of it and its shift). NaN when the fit could
    #: not be made. Set whether or not the drift itself is significant.
    gain_sigma: float = float("nan")

    @classmethod
    def fit(
        cls, observations: Any, *, min_captures: int = MIN_CAPTURES, index: str = "temperature_c",
        tau_s: float = 70.0, calibration_temperature_c: float | None = None,
    ) -> HeatingTerm:
        """Fit the term to learned observations (one bucket or all; module docstring), by
        ``index`` "temperature_c" (a correction) or "time_s" (a σ only, see ``index``). With the
        calibration's temperature (°C) a slope must also be plausible from there
        (:data:`MAX_CALIBRATION_CORRECTION_REL`)."""
        obs = as_observation_array(observations)
        if obs.size == 0:
            return cls(False, "no observations", index=index)
        temp = np.asarray(obs[index], dtype=np.float64)
        keep = np.isfinite(temp)
        if not keep.any():
            return cls(False, "the captures report no module temperature", index=index)
        obs, temp = obs[keep], temp[keep]
        c = corrections_px(obs)
        cid = np.unique(obs["capture_id"], return_inverse=True)[1].ravel()
        g = int(cid.max()) + 1
        if g < min_captures:
            return cls(False, f"{g} face captures report a {index}; need >= {min_captures}",
                       n_captures=g, index=index)
        n = np.bincount(cid, minlength=g).astype(np.float64)

        def mean(v: np.ndarray) -> np.ndarray:
            return np.bincount(cid, np.asarray(v, dtype=np.float64), g) / n

        t_i, c_i, d_i = mean(temp), mean(c), mean(obs["d_measured_px"])
        x_i, y_i = mean(obs["x_px"]), mean(obs["y_px"])
        lo, hi = float(t_i.min()), float(t_i.max())
        span = MIN_SPAN_C if index == "temperature_c" else MIN_SPAN_S
        if hi - lo < span:
            return cls(False, f"the learned {index} span {hi - lo:.3f} < {span}",
                       range_c=(lo, hi), n_captures=g, index=index)
        ref = float(np.median(t_i))
        scale = max(float(np.ptp(np.r_[x_i, y_i])), 1.0)
        cols = [np.ones(g), d_i - d_i.mean(), t_i - ref]
        if g >= min_captures + 2:  # sensor position, when the captures can afford it
            cols += [(v - v.mean()) / scale for v in (x_i, y_i) if np.ptp(v) > 1.0]
        x = np.column_stack(cols)
        use = np.ones(g, dtype=bool)
        for _ in range(2):  # one robust pass: drop captures beyond 3 robust σ, refit
            beta, sd, res = _ols(x[use], c_i[use])
            if beta is None:
                return cls(False, f"the captures' disparities, {index} and positions are "
                           "collinear: the heating slope cannot be told", range_c=(lo, hi),
                           n_captures=g, index=index)
            full = c_i - x @ beta
            mad = 1.4826 * float(np.median(np.abs(res - np.median(res))))
            new = np.abs(full) <= max(3 * mad, 1e-9) if mad > 0 else use
            if new.sum() < x.shape[1] + 2 or np.array_equal(new, use):
                break
            use = new
        k, k_sigma = float(beta[2]), float(sd[2])
        need = APPLY_SIGNIFICANCE if index == "temperature_c" else SIGNIFICANCE
        significant = abs(k) > need * k_sigma
        applied = significant and index == "temperature_c"
        why = (f"no significant drift over the learning captures' {index}: "
               f"{k:.3g} ± {k_sigma:.2g} px per unit (needs {need:g}σ)")
        if applied and calibration_temperature_c is not None and np.isfinite(
                calibration_temperature_c):
            c_cal = float(np.median(c_i[use])) - k * (ref - float(calibration_temperature_c))
            bound = MAX_CALIBRATION_CORRECTION_REL * float(np.median(mean(obs["d_expected_px"])))
            if abs(c_cal) > bound:
                applied = significant = False
                why = (f"the drift over the learning captures' temperatures, {k:.3g} ± "
                       f"{k_sigma:.2g} px/°C, is not the heating: from the calibration's "
                       f"{calibration_temperature_c:.3g} °C it would leave a correction of "
                       f"{c_cal:.3g} px there, beyond {bound:.3g} px "
                       f"({MAX_CALIBRATION_CORRECTION_REL:.0%} of the faces' disparity)")
        g_sigma = float(sd[1]) if applied else _averaged_gain_sigma(x[use], c_i[use])
        if not significant:
            return cls(False, why, k, k_sigma, ref, (lo, hi), int(use.sum()), index, tau_s,
                       g_sigma)
        return cls(True, "", k, k_sigma, ref, (lo, hi), int(use.sum()), index, tau_s, g_sigma)

    def offset_px(self, temperature_c: Any) -> tuple[np.ndarray, np.ndarray]:
        """(k·(T − T_ref), σ_k·|T − T_ref|) at temperatures (°C; NaN or no term → 0, 0); for
        a time-indexed term (0, |k|·τ·(1 − e^(−|t − t_ref|/τ))) at times (s)."""
        t = np.asarray(temperature_c, dtype=np.float64)
        if not self.ok:
            return np.zeros_like(t), np.zeros_like(t)
        dt = np.where(np.isfinite(t), t - self.reference_c, 0.0)
        if self.index != "temperature_c":
            tau = max(self.tau_s, 1e-9)
            return np.zeros_like(dt), abs(self.slope_px_per_c) * tau * -np.expm1(-np.abs(dt) / tau)
        return self.slope_px_per_c * dt, self.slope_sigma * np.abs(dt)

    def normalise(self, observations: Any) -> np.ndarray:
        """The observations referred to T_ref: d_measured + k·(T − T_ref), so that their
        corrections d_expected − d_measured lose the heating term (unknown T: unchanged)."""
        obs = as_observation_array(observations).copy()
        if self.ok and obs.size and self.index == "temperature_c":
            value, _ = self.offset_px(obs["temperature_c"])
            obs["d_measured_px"] = obs["d_measured_px"] + value
        return obs

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "ok": self.ok, "reason": self.reason, "index": self.index,
            "slope_px_per_c": round(self.slope_px_per_c, 6),
            "slope_sigma": round(self.slope_sigma, 6),
            "reference_c": None if not np.isfinite(self.reference_c) else round(
                self.reference_c, 4),
            "range_c": [None if not np.isfinite(v) else round(v, 4) for v in self.range_c],
            "n_captures": self.n_captures,
            "gain_sigma": None if not np.isfinite(self.gain_sigma) else round(self.gain_sigma, 6),
        }


def _averaged_gain_sigma(x: np.ndarray, y: np.ndarray) -> float:
    """σ of the gain a correction learned *without* a drift term (column 1 of ``x``, the drift
    column 2) owes to a drift the captures may carry, px/px: the two models — no drift, a
    linear drift — averaged by their evidence (BIC weights, Bayesian model averaging):
    σ² = w₀·σ₀² + w₁·(σ₁² + Δ²), σ₀, σ₁ the gain's σ in each fit and Δ² how far the drift moves
    it, ĝ₀ − ĝ₁, squared *less what noise alone gives it*: with no drift the nested fits' gains
    differ by noise of variance σ₁² − σ₀² (σ₁² already carries it), so the drift's own share
    is (ĝ₀ − ĝ₁)² − (σ₁² − σ₀²), at least 0 (session 23: over the 75 kept sets within σ 50–90 %
    on 12 of 20 acceptance seeds and 7 of 8 ``folded-x3`` instead of 11 and 6, the held out 30
    of 48 instead of 31, no capture further out). A drift the captures cannot tell from zero
    keeps a weight of about 1 / (1 + √n) (n captures), not 1: with every learned set warm the
    drift fit's collinear gain σ alone read the realised gain errors at 0.65–0.77 of it in rms
    (docs/module-random.md, session 20); a clear drift takes the whole weight and its shift."""
    full, sd1, res1 = _ols(x, y)
    alone, sd0, res0 = _ols(np.delete(x, 2, axis=1), y)
    if full is None or alone is None:
        return float(sd1[1]) if alone is None else float(sd0[1])
    n = len(y)
    rss1, rss0 = max(float(res1 @ res1), 1e-300), max(float(res0 @ res0), 1e-300)
    # BIC₀ − BIC₁ = n·ln(RSS₀ / RSS₁) − ln n (the drift is one parameter more)
    w1 = float(1.0 / (1.0 + np.exp(-0.5 * (n * np.log(rss0 / rss1) - np.log(n)))))
    shift2 = float(full[1] - alone[1]) ** 2 - max(float(sd1[1] ** 2 - sd0[1] ** 2), 0.0)
    return float(np.sqrt((1 - w1) * sd0[1] ** 2 + w1 * (sd1[1] ** 2 + max(shift2, 0.0))))


def _ols(x: np.ndarray, y: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray]:
    """(β, σ of each β, residuals) of y ≈ x·β; β None (σ inf) when x is (nearly)
    rank-deficient."""
    n, p = x.shape
    if n <= p or np.linalg.cond(x) > 1e8:
        return None, np.full(p, np.inf), np.zeros(n)
    beta, *_ = np.linalg.lstsq(x, y, rcond=None)
    res = y - x @ beta
    s2 = float(res @ res) / (n - p)
    cov = s2 * np.linalg.inv(x.T @ x)
    return beta, np.sqrt(np.maximum(np.diag(cov), 0.0)), res


__all__ = [
    "APPLY_SIGNIFICANCE", "MAX_CALIBRATION_CORRECTION_REL", "MIN_CAPTURES", "MIN_SPAN_C",
    "MIN_SPAN_S", "SIGNIFICANCE", "HeatingTerm",
]
