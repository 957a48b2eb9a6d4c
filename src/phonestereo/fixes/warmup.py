"""The warm-up gate (thesis §3.1 fix option 2, §4.1.1 "heated"): warm-up time or drift rate.

A capture passes once the camera app has run long enough (``time_s``), or once the measured
drift rate of a static scene is small (or the rate a fitted drift curve gives at its time,
:class:`~phonestereo.fixes.heating.DriftFit`). A capture without ``time_s`` falls back to the
drift-rate check on a measured rate; every reason names the check used.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from phonestereo.errors import InputError
from phonestereo.fixes.heating import DriftFit


@dataclass(frozen=True)
class GateResult:
    """Outcome of a gate: passed or not, and why (thesis §4.1.1)."""

    passed: bool
    reason: str


@dataclass(frozen=True)
class WarmupGate:
    """The "heated" gate (thesis §3.1 fix option 2, §4.1.1): warm-up time or drift rate.

    Examples
    --------
    >>> gate = WarmupGate(min_time_s=180.0)
    >>> gate.check({"time_s": 20.0}).passed, gate.check({"time_s": 240.0}).passed
    (False, True)
    """

    #: A capture passes once the camera app has run this long (the thesis uses 3 min = 180 s for its
    #: folded module). Default when neither criterion is given.
    min_time_s: float | None = None
    #: A capture passes when the measured drift rate of a static scene (|d mean| per second,
    #: :func:`drift_rate`) is at most this — or, with ``fit``, the fitted rate at its time.
    max_drift_rate_px_per_s: float | None = None
    #: A drift curve of this module; gives the rate at any time when none is measured.
    fit: DriftFit | None = None

    def __post_init__(self) -> None:
        if self.min_time_s is None and self.max_drift_rate_px_per_s is None:
            object.__setattr__(self, "min_time_s", 180.0)
        for name in ("min_time_s", "max_drift_rate_px_per_s"):
            v = getattr(self, name)
            if v is not None and (not math.isfinite(v) or v < 0):
                raise InputError(f"{name} must be a finite number >= 0, got {v}")

    def check(self, capture: Any, *, drift_rate_px_per_s: float | None = None) -> GateResult:
        """Gate one capture.

        ``capture``: a CaptureEntry, mapping or object with ``time_s`` (seconds since the
        camera app started, or None when unknown). ``drift_rate_px_per_s``: the measured drift
        rate of a static scene at this capture; without it (or NaN) the rate criterion uses
        ``fit``, and fails, saying so, if there is none. With ``time_s`` None the gate falls
        back to the drift-rate check on the measured rate (``fit`` needs a time); the reason
        always names the check used ("warm-up time check", "drift-rate check: no time_s").
        """
        has = "time_s" in capture if isinstance(capture, dict) else hasattr(capture, "time_s")
        if not has:
            raise InputError("the capture needs a finite 'time_s' (seconds since app start)")
        t = capture["time_s"] if isinstance(capture, dict) else capture.time_s
        if t is None:  # time unknown (e.g. a phone's EXIF has none): only the rate can decide
            return self._rate_only(drift_rate_px_per_s)
        if not math.isfinite(float(t)):
            raise InputError("the capture needs a finite 'time_s' (seconds since app start)")
        t = float(t)
        if self.min_time_s is not None and t < self.min_time_s:
            return GateResult(
                False,
                f"not warmed up: {t:.0f} s since start < {self.min_time_s:.0f} s "
                "(warm-up time check)",
            )
        if self.max_drift_rate_px_per_s is not None:
            rate, source = drift_rate_px_per_s, "measured"
            if rate is not None and not math.isfinite(rate):
                rate = None  # nothing measured (e.g. first capture): fall back on the fit
            if rate is None and self.fit is not None and self.fit.ok:
                rate, source = float(self.fit.rate(t)), "fitted"
            if rate is None:
                return GateResult(
                    False, "no drift rate: measure a static scene (drift_rate) or give a fit"
                )
            if abs(rate) > self.max_drift_rate_px_per_s:
                return GateResult(
                    False,
                    f"still drifting: {source} rate {abs(rate):.2g} px/s > "
                    f"{self.max_drift_rate_px_per_s:.2g} px/s at {t:.0f} s",
                )
        used = "warm-up time" if self.max_drift_rate_px_per_s is None else "drift-rate"
        if self.min_time_s is not None and self.max_drift_rate_px_per_s is not None:
            used = "warm-up time and drift-rate"
        return GateResult(True, f"warm at {t:.0f} s ({used} check)")

    def _rate_only(self, rate: float | None) -> GateResult:
        """The gate for a capture without ``time_s``: the drift-rate check, with the measured
        rate only (a fitted curve needs the time); gated, saying why, when it cannot run."""
        head = "no time_s (seconds since the camera app started), so the warm-up time check "
        if rate is None or not math.isfinite(rate):
            return GateResult(
                False,
                head + "cannot run, and the drift-rate check needs the measured drift rate of "
                "a static scene, which was not given: record time_s in the manifest, or "
                "measure the drift rate",
            )
        if self.max_drift_rate_px_per_s is None:
            return GateResult(
                False,
                head + "cannot run, and no max_drift_rate_px_per_s is set for the drift-rate "
                "check: set one, or record time_s",
            )
        if abs(rate) > self.max_drift_rate_px_per_s:
            return GateResult(
                False,
                f"still drifting: measured rate {abs(rate):.2g} px/s > "
                f"{self.max_drift_rate_px_per_s:.2g} px/s (drift-rate check: no time_s)",
            )
        return GateResult(
            True,
            f"measured drift rate {abs(rate):.2g} px/s <= {self.max_drift_rate_px_per_s:.2g} "
            "px/s (drift-rate check: no time_s)",
        )
