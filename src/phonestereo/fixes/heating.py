"""Heating (thesis §3.1): the warm-up drift curve, the warm-up gate and an offset correction.

A module that has just been switched on drifts: each camera's principal point moves by a
different amount, so a static scene's disparity "drops" and then saturates (thesis Figures 3-3
and 3-4). The drift follows the warm-up curve

    y(t) = c + A · (1 − e^(−t / τ)),

t the seconds since the camera app started, c the cold value, A the total drift and τ the time
constant (≈ 70 s on the thesis's folded module, saturated after ~3 min).

Thesis blocks implemented here:

- :func:`fit_drift_curve` — the drift-curve analysis of §3.1 (A, τ, saturation time);
- :class:`~phonestereo.fixes.warmup.WarmupGate` (in :mod:`phonestereo.fixes.warmup`) — fix
  option 2 of §3.1 and the "heated" gate of §4.1.1 / §4.1.3 ("Heated modules"): accept a capture
  only after a warm-up time, or once the measured drift rate of a static scene is small;
- :class:`HeatingCorrection` — fix option 1 of §3.1 / future work of chapter 5, beyond the
  thesis: a time- or temperature-indexed offset that maps a disparity to the warm state.

"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, fields
from typing import Any, Literal

import numpy as np
from numpy.typing import NDArray
from scipy.optimize import least_squares

from phonestereo.errors import InputError, ShapeError

F64 = NDArray[np.float64]
MIN_SAMPLES = 4
_N_TAU_GRID = 200


@dataclass(frozen=True)
class DriftFit:
    """The warm-up curve y(t) = offset + amplitude · (1 − e^(−t/τ)) fitted to a series."""

    #: False when the series cannot give τ; ``reason`` says why (or notes, e.g. unsaturated).
    ok: bool
    reason: str
    #: ``amplitude``, ``tau_s``, ``offset``: A (total drift cold → warm, unit of the values: px for
    #: disparity), τ (s), c (y at t = 0).
    amplitude: float
    #: See ``amplitude`` above.
    tau_s: float
    #: See ``amplitude`` above.
    offset: float
    #: RMS residual of the fit (unit of the values).
    sigma: float
    #: ``tau_sigma_s``, ``amplitude_sigma``: 1σ uncertainties from the fit's Jacobian.
    tau_sigma_s: float
    #: See ``tau_sigma_s`` above.
    amplitude_sigma: float
    #: ``saturation_fraction``, ``saturation_time_s``: Fraction f of the drift that counts as
    #: saturated (0.95) and the time it is reached, τ · ln(1 / (1 − f)) (3 τ for 95 %).
    saturation_fraction: float
    #: See ``saturation_fraction`` above.
    saturation_time_s: float
    #: Number of finite samples used.
    n: int

    def value(self, t_s: Any) -> F64:
        """y(t) of the fitted curve at ``t_s`` (seconds, any shape)."""
        t = np.asarray(t_s, dtype=np.float64)
        return np.asarray(self.offset + self.amplitude * -np.expm1(-t / self.tau_s))

    def rate(self, t_s: Any) -> F64:
        """dy/dt = (A / τ) · e^(−t/τ) at ``t_s``, unit of the values per second."""
        t = np.asarray(t_s, dtype=np.float64)
        return np.asarray(self.amplitude / self.tau_s * np.exp(-t / self.tau_s))

    def remaining(self, t_s: Any) -> F64:
        """Drift still to come after ``t_s``: A · e^(−t/τ) (unit of the values)."""
        t = np.asarray(t_s, dtype=np.float64)
        return np.asarray(self.amplitude * np.exp(-t / self.tau_s))

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> DriftFit:
        """Rebuild from :meth:`to_dict` (None → NaN)."""
        kw: dict[str, Any] = {k: float("nan") if v is None else v for k, v in data.items()}
        return cls(**{f.name: kw[f.name] for f in fields(cls)})

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly dict of every field (NaN, inf → None)."""
        d = asdict(self)
        return {
            k: None if isinstance(v, float) and not math.isfinite(v) else v for k, v in d.items()
        }


def _series(t_s: Any, values: Any) -> tuple[F64, F64]:
    t = np.asarray(t_s, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    if t.ndim != 1 or y.shape != t.shape:
        raise ShapeError(
            f"t_s and values must be 1-D arrays of the same length (one value per capture), got "
            f"shapes {t.shape} and {y.shape}; fit each component separately"
        )
    if np.any(~np.isfinite(t)) or np.any(t < 0):
        raise InputError("t_s must be finite seconds since the camera app started (>= 0)")
    keep = np.isfinite(y)
    return t[keep], y[keep]


def _linear(t: F64, y: F64, tau: float) -> tuple[float, float, float]:
    """Best (c, A) for a fixed τ by linear least squares, and the residual sum of squares."""
    g = -np.expm1(-t / tau)
    m = np.stack([np.ones_like(t), g], axis=1)
    coef, *_ = np.linalg.lstsq(m, y, rcond=None)
    r = m @ coef - y
    return float(coef[0]), float(coef[1]), float(r @ r)


def _failed(reason: str, n: int, fraction: float) -> DriftFit:
    nan = float("nan")
    return DriftFit(False, reason, nan, nan, nan, nan, nan, nan, fraction, nan, n)


def fit_drift_curve(t_s: Any, values: Any, *, saturation_fraction: float = 0.95) -> DriftFit:
    """Fit the warm-up curve y = c + A·(1 − e^(−t/τ)) to one component (thesis §3.1).

    Variable projection: for each τ on a log grid from 1/20 of the first sample spacing to
    5 × the series length, (c, A) are linear; the best grid τ starts
    :func:`scipy.optimize.least_squares` on (c, A, log τ).

    Parameters
    ----------
    t_s : array_like, shape (N,)
        Seconds since the camera app started (warm-up starts at t = 0).
    values : array_like, shape (N,)
        The drifting quantity (mean disparity or non-disparity error, pixels); NaN samples
        (captures where nothing was measured) are skipped.
    saturation_fraction : float
        Fraction of the drift that counts as saturated (0 < f < 1).

    Returns
    -------
    DriftFit
        ``ok=False`` with a reason when the data cannot give τ (fewer than 4 samples, τ at the
        edge of the search range, no drift above the noise); not an exception.

    Raises
    ------
    ShapeError, InputError
        Mismatched shapes, negative or non-finite times, a fraction outside (0, 1).

    Examples
    --------
    The thesis's folded module: 95 % of the drift is done after 3 τ ≈ 3.5 min.

    >>> t = np.arange(0.0, 601.0, 10.0)
    >>> fit = fit_drift_curve(t, 0.8 * (1 - np.exp(-t / 70.0)))
    >>> round(fit.saturation_time_s, 1), round(fit.saturation_time_s / 60, 1)
    (209.7, 3.5)
    """
    if not 0.0 < saturation_fraction < 1.0:
        raise InputError(f"saturation_fraction must be in (0, 1), got {saturation_fraction}")
    t, y = _series(t_s, values)
    n = len(t)
    if n < MIN_SAMPLES or len(np.unique(t)) < MIN_SAMPLES:
        why = f"needs >= {MIN_SAMPLES} samples at distinct times to fit (c, A, τ), got {n}"
        return _failed(why, n, saturation_fraction)
    span = float(t.max() - t.min())
    step = float(np.min(np.diff(np.unique(t))))
    lo, hi = max(step / 20.0, 1e-3), 5.0 * max(span, float(t.max()))
    grid = np.geomspace(lo, hi, _N_TAU_GRID)
    sse = np.array([_linear(t, y, float(tau))[2] for tau in grid])
    k = int(np.argmin(sse))
    c0, a0, _ = _linear(t, y, float(grid[k]))

    def resid(p: F64) -> F64:
        return np.asarray(p[0] + p[1] * -np.expm1(-t / np.exp(p[2])) - y)

    sol = least_squares(resid, [c0, a0, math.log(grid[k])], method="lm", x_scale="jac")
    c, a, log_tau = (float(v) for v in sol.x)
    tau = math.exp(log_tau)
    sigma = float(np.sqrt(np.sum(sol.fun**2) / max(n - 3, 1)))
    cov = np.linalg.pinv(sol.jac.T @ sol.jac) * sigma**2  # 1σ of (c, A, log τ)
    tau_sig, a_sig = tau * float(np.sqrt(max(cov[2, 2], 0.0))), float(np.sqrt(max(cov[1, 1], 0)))
    sat = tau * math.log(1.0 / (1.0 - saturation_fraction))
    sigma_n = float(np.sqrt(np.sum(sol.fun**2) / n))
    if k in (0, len(grid) - 1) or not sol.success or not np.isfinite(tau):
        why = (
            f"τ is not identifiable from this series (best τ at the edge of {lo:.3g}–{hi:.3g} s); "
            "capture from cold, often in the first minutes, for several τ"
        )
        return _failed(why, n, saturation_fraction)
    if abs(a) < 3.0 * max(sigma_n, 1e-12):
        return DriftFit(
            False, f"no drift above the noise (|A| = {abs(a):.3g} < 3σ = {3 * sigma_n:.3g})",
            a, tau, c, sigma, tau_sig, a_sig, saturation_fraction, sat, n,
        )
    note = ""
    if sat > float(t.max()):
        note = f"not saturated within the series (saturation at {sat:.0f} s > last {t.max():.0f} s)"
    return DriftFit(True, note, a, tau, c, sigma, tau_sig, a_sig, saturation_fraction, sat, n)


def drift_rate(t_s: Any, values: Any) -> float:
    """Measured drift rate of a static scene: slope of a line through (t_s, values), px/s.

    ``t_s``, ``values`` (N,): times (s) and a static scene's mean disparity (px) over a short
    recent window. NaN with fewer than 2 finite samples.

    Examples
    --------
    >>> drift_rate([0.0, 10.0, 20.0], [9.0, 8.99, 8.98])
    -0.001
    """
    t, y = _series(t_s, values)
    if len(t) < 2 or np.ptp(t) == 0:
        return float("nan")
    return round(float(np.polyfit(t, y, 1)[0]), 12)


@dataclass(frozen=True)
class HeatingCorrection:
    """Offset correction of the heating drift, indexed by time or by temperature (§3.1, ch. 5).

    ``apply(d, ...)`` returns d − (y(x) − y(x_ref)): the value the quantity would have in the
    reference state (default: warm, the saturated end of the curve, where the learned fixes of
    §3.6 are made).

    Build it with :meth:`from_fit` (time-indexed, from :func:`fit_drift_curve`) or
    :meth:`from_temperature` (a polynomial of the module temperature, thesis Figure 3-3).

    Examples
    --------
    >>> t = np.arange(0.0, 601.0, 10.0)
    >>> d = 9.0 - 2.9 * (1 - np.exp(-t / 70.0))
    >>> corr = HeatingCorrection.from_fit(fit_drift_curve(t, d))
    >>> round(float(corr.apply(d[0], time_s=0.0)), 3)     # cold 9.0 px → warm 6.1 px
    6.1
    """

    index: Literal["time_s", "temperature_c"]
    fit: DriftFit | None = None
    coefficients: tuple[float, ...] = ()
    reference: float = math.inf
    valid_range: tuple[float, float] = (0.0, math.inf)

    @classmethod
    def from_fit(cls, fit: DriftFit, reference_time_s: float = math.inf) -> HeatingCorrection:
        """Time-indexed correction from a drift curve; reference ``inf`` = warm."""
        if not fit.ok:
            raise InputError(f"cannot correct heating from a failed drift fit: {fit.reason}")
        return cls("time_s", fit, (), float(reference_time_s))

    @classmethod
    def from_temperature(
        cls,
        temperature_c: Any,
        values: Any,
        *,
        degree: int = 1,
        reference_temperature_c: float | None = None,
    ) -> HeatingCorrection:
        """Temperature-indexed correction: a polynomial fit of the values against temperature.

        ``temperature_c``, ``values`` (N,): reported module temperatures (°C) and the drifting
        quantity (px), NaN skipped. ``degree`` 1 when drift and temperature follow the same
        warm-up curve. ``reference_temperature_c``: default the highest seen (warm).
        """
        temp = np.asarray(temperature_c, dtype=np.float64)
        y = np.asarray(values, dtype=np.float64)
        if temp.ndim != 1 or temp.shape != y.shape:
            raise ShapeError(f"temperature_c and values must be (N,), got {temp.shape}, {y.shape}")
        keep = np.isfinite(temp) & np.isfinite(y)
        if np.unique(temp[keep]).size < degree + 2:
            raise InputError(
                f"a degree-{degree} temperature correction needs >= {degree + 2} distinct "
                f"temperatures; got {np.unique(temp[keep]).size} (does the module report them?)"
            )
        coef = np.polyfit(temp[keep], y[keep], degree)
        lo, hi = float(temp[keep].min()), float(temp[keep].max())
        ref = hi if reference_temperature_c is None else float(reference_temperature_c)
        return cls("temperature_c", None, tuple(float(c) for c in coef), ref, (lo, hi))

    def offset(self, *, time_s: Any = None, temperature_c: Any = None) -> F64:
        """y(x) − y(x_ref) at a time (s) or temperature (°C, clipped to the fitted range);
        :class:`InputError` if the index this correction needs is not given."""
        if self.index == "time_s":
            if time_s is None:
                raise InputError("this heating correction is time-indexed: give time_s")
            assert self.fit is not None
            t = np.asarray(time_s, dtype=np.float64)
            a, tau = self.fit.amplitude, self.fit.tau_s
            ref = 0.0 if math.isinf(self.reference) else math.exp(-self.reference / tau)
            return np.asarray(a * (ref - np.exp(-t / tau)))
        if temperature_c is None:
            raise InputError("this heating correction is temperature-indexed: give temperature_c")
        temp = np.clip(np.asarray(temperature_c, dtype=np.float64), *self.valid_range)
        ref = float(np.clip(self.reference, *self.valid_range))
        return np.asarray(np.polyval(self.coefficients, temp) - np.polyval(self.coefficients, ref))

    def apply(self, d: Any, *, time_s: Any = None, temperature_c: Any = None) -> F64:
        """Corrected values d − offset, same shape as ``d`` (broadcast with the index)."""
        off = self.offset(time_s=time_s, temperature_c=temperature_c)
        return np.asarray(np.asarray(d, dtype=np.float64) - off)

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly description."""
        return {
            "index": self.index,
            "fit": None if self.fit is None else self.fit.to_dict(),
            "coefficients": list(self.coefficients),
            "reference": None if math.isinf(self.reference) else self.reference,
            "valid_range": [v if math.isfinite(v) else None for v in self.valid_range],
        }
