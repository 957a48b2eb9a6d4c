"""Learned disparity observations and the corrections derived from them (thesis §3.6).

A face (or any object of known size) at depth Z gives an *expected* disparity d = f·B/Z
(eq. 4 with Z from eq. 11); the disparity measured at its landmarks differs from it. One
:class:`Observation` is that pair at one sensor position, with the conditions it was learned
under (orientation bucket §3.4, focus group §3.5, time and temperature §3.1). The correction
to add to a measured disparity there is ``d_expected − d_measured``.

Many observations travel as one NumPy structured array (:func:`observations_to_array`), the
form the fix store returns and the lookups consume; :class:`Correction` is what a lookup gives
back for a set of query points.

Examples
--------
>>> ob = Observation(x_px=1000.0, y_px=750.0, d_measured_px=8.7, d_expected_px=9.0,
...                  depth_m=2.0, orientation="landscape", focus_group="g1", time_s=200.0,
...                  temperature_c=None, capture_id="f01")
>>> round(ob.correction_px, 3)    # 1500 px · 12 mm / 2 m = 9 px expected, 8.7 px measured
0.3
>>> arr = observations_to_array([ob])
>>> arr["orientation"][0], float(arr["temperature_c"][0])
('landscape', nan)
"""

from __future__ import annotations

import csv
import json
import math
import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from phonestereo.errors import InputError, ShapeError

#: Numeric columns of an observation array, in order (float64; NaN = unknown).
NUMERIC_FIELDS = (
    "x_px",
    "y_px",
    "d_measured_px",
    "d_expected_px",
    "depth_m",
    "time_s",
    "temperature_c",
    "sigma_px",
    "radial_px",
    "e_measured_px",
)
#: Text columns of an observation array.
TEXT_FIELDS = ("orientation", "focus_group", "capture_id", "source")
#: Every column, in the order of :class:`Observation`'s fields.
FIELDS = (
    "x_px",
    "y_px",
    "d_measured_px",
    "d_expected_px",
    "depth_m",
    "orientation",
    "focus_group",
    "time_s",
    "temperature_c",
    "capture_id",
    "source",
    "sigma_px",
    "radial_px",
    "e_measured_px",
)


def _finite(value: Any, name: str) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise InputError(f"observation field {name} must be finite, got {v}")
    return v


@dataclass(frozen=True)
class Observation:
    """One learned disparity observation (thesis §3.6, Figure 3-30)."""

    #: ``x_px``, ``y_px``: Sensor position in the rectified wide image, pixels ((0, 0) = centre of
    #: the top-left pixel).
    x_px: float
    #: See ``x_px`` above.
    y_px: float
    #: Disparity measured there after the earlier fixes, pixels.
    d_measured_px: float
    #: Disparity expected from the independent depth, f·B/Z (eq. 4), pixels.
    d_expected_px: float
    #: The independent depth Z (e.g. from the IPD, eq. 11), metres, > 0.
    depth_m: float
    #: Orientation bucket label (§3.4); a fix is applied only within its bucket.
    orientation: str
    #: str. Refocus stack the capture belongs to; ``""`` (or None) when none.
    focus_group: str | None
    #: Seconds since the camera app started (heating, §3.1).
    time_s: float
    #: Module temperature in °C when the module reports it.
    temperature_c: float | None
    #: The capture this observation was learned from (non-empty).
    capture_id: str
    #: What gave the expected disparity: ``"face-chart"``, ``"population"``, ``"iris"``, ...
    source: str = "face-chart"
    #: Standard deviation of the correction, pixels; NaN when unknown.
    sigma_px: float = field(default=math.nan)
    #: The residual radial distortion's x part (thesis §3.2) the learning took out of
    #: ``d_measured_px`` with its own capture's fit, pixels; NaN when none was taken out or it
    #: was not recorded (stores before schema 5). The learned correction re-refers it to the
    #: learning captures' pooled fit, the one the application takes out of a ROI
    #: (:class:`~phonestereo.flows.corrector.Corrector`).
    radial_px: float = field(default=math.nan)
    #: The row error e = y_wide − y_tele measured there, in the reference rectification, pixels;
    #: NaN when not recorded (stores before schema 6). The application centres its coarse row
    #: search on the learned captures' typical e (:func:`typical_row_error_px`).
    e_measured_px: float = field(default=math.nan)

    def __post_init__(self) -> None:
        for name in ("x_px", "y_px", "d_measured_px", "d_expected_px", "time_s"):
            object.__setattr__(self, name, _finite(getattr(self, name), name))
        z = _finite(self.depth_m, "depth_m")
        if z <= 0:
            raise InputError(f"observation depth_m must be > 0 metres, got {z}")
        object.__setattr__(self, "depth_m", z)
        if self.temperature_c is not None:
            object.__setattr__(self, "temperature_c", _finite(self.temperature_c, "temperature_c"))
        s = float(self.sigma_px)
        if not (math.isnan(s) or (math.isfinite(s) and s >= 0)):
            raise InputError(f"observation sigma_px must be ≥ 0 or NaN (unknown), got {s}")
        object.__setattr__(self, "sigma_px", s)
        rad = float(self.radial_px)
        if math.isinf(rad):
            raise InputError(f"observation radial_px must be finite or NaN (none), got {rad}")
        object.__setattr__(self, "radial_px", rad)
        e = float(self.e_measured_px)
        if math.isinf(e):
            raise InputError(f"observation e_measured_px must be finite or NaN (none), got {e}")
        object.__setattr__(self, "e_measured_px", e)
        if self.focus_group is None:
            object.__setattr__(self, "focus_group", "")
        for name in TEXT_FIELDS:
            value = getattr(self, name)
            if not isinstance(value, str):
                raise InputError(f"observation field {name} must be a string, got {value!r}")
        for name in ("orientation", "capture_id", "source"):
            if not getattr(self, name).strip():
                raise InputError(f"observation field {name} must be a non-empty label")

    @property
    def correction_px(self) -> float:
        """``d_expected_px − d_measured_px``: what to add to the measured disparity, pixels."""
        return self.d_expected_px - self.d_measured_px

    def as_row(self) -> tuple[Any, ...]:
        """The values in :data:`FIELDS` order (temperature None → NaN)."""
        t = math.nan if self.temperature_c is None else self.temperature_c
        return tuple(t if name == "temperature_c" else getattr(self, name) for name in FIELDS)


def observation_dtype(text_width: int = 32) -> np.dtype:
    """The structured dtype of an observation array (text fields ``U<text_width>``)."""
    w = max(1, int(text_width))
    return np.dtype(
        [(n, np.float64 if n in NUMERIC_FIELDS else f"U{w}") for n in FIELDS]  # type: ignore[misc]
    )


def _rows_to_array(rows: Sequence[Sequence[Any]]) -> np.ndarray:
    idx = [FIELDS.index(n) for n in TEXT_FIELDS]
    width = max((len(str(r[i])) for r in rows for i in idx), default=1)
    return np.array([tuple(r) for r in rows], dtype=observation_dtype(width))


def observations_to_array(observations: Iterable[Observation]) -> np.ndarray:
    """Stack observations into a structured array, shape (N,), fields :data:`FIELDS`.

    Unknown temperature and sigma are NaN; text fields are as wide as the longest value.
    """
    rows = []
    for ob in observations:
        if not isinstance(ob, Observation):
            raise InputError(f"expected Observation objects, got {type(ob).__name__}")
        rows.append(ob.as_row())
    return _rows_to_array(rows)


def array_to_observations(arr: np.ndarray) -> list[Observation]:
    """The inverse of :func:`observations_to_array` (NaN temperature → None)."""
    a = as_observation_array(arr)
    out = []
    for rec in a:
        kw: dict[str, Any] = {
            n: (str(rec[n]) if n in TEXT_FIELDS else float(rec[n])) for n in FIELDS
        }
        if math.isnan(kw["temperature_c"]):
            kw["temperature_c"] = None
        out.append(Observation(**kw))
    return out


def as_observation_array(obs: Any) -> np.ndarray:
    """Accept a structured observation array or a sequence of :class:`Observation`.

    Raises
    ------
    ShapeError
        If a structured array lacks a field of :data:`FIELDS` or is not 1-D.
    """
    if isinstance(obs, np.ndarray) and obs.dtype.names is not None:
        missing = [n for n in FIELDS if n not in obs.dtype.names]
        if missing or obs.ndim != 1:
            raise ShapeError(
                f"observation array must be 1-D with fields {FIELDS}; missing {missing}, "
                f"shape {obs.shape}; build it with observations_to_array()"
            )
        return obs
    return observations_to_array(list(obs))


def corrections_px(obs: np.ndarray) -> np.ndarray:
    """``d_expected − d_measured`` per observation, shape (N,), pixels."""
    return np.asarray(obs["d_expected_px"] - obs["d_measured_px"], dtype=np.float64)


def typical_correction_px(obs: Any) -> float:
    """The median finite ``d_expected − d_measured`` of observations (an array or a sequence of
    :class:`Observation`), px; 0 without any. A far point's measured disparity is about its
    negative (the flows widen their searches by it)."""
    arr = as_observation_array(obs)
    c = corrections_px(arr) if arr.size else np.zeros(0)
    c = c[np.isfinite(c)]
    return float(np.median(c)) if c.size else 0.0


def typical_row_error_px(obs: Any, at: Any = None) -> float:
    """The row error ``e_measured_px`` of observations (an array or a sequence of
    :class:`Observation`) at the rectified wide pixel ``at`` (x, y), px; NaN without any (not
    recorded). The flows centre their row searches on it.

    e varies across the view: an uncorrected W-T scale s tilts it by (1 − s) per pixel across
    the baseline and a roll along it (random-3056: e 3 px at the top of the tele's view, 15 px at
    its bottom). So with ``at`` and at least 6 observations spread over ≥ 50 px both ways, the
    plane e = a + b·x + c·y fitted to them (least squares, once more without the residuals
    beyond 3 robust σ) is read there; else their median.
    """
    arr = as_observation_array(obs)
    if not arr.size:
        return math.nan
    e = arr["e_measured_px"]
    ok = np.isfinite(e)
    if not ok.any():
        return math.nan
    xy = np.column_stack([arr["x_px"], arr["y_px"]])[ok]
    e = e[ok]
    if at is None or len(e) < 6 or np.ptp(xy, axis=0).min() < 50.0:
        return float(np.median(e))
    c = xy.mean(axis=0)
    a = np.column_stack([np.ones(len(e)), xy - c])
    keep = np.ones(len(e), bool)
    for _ in range(2):  # fit, then refit without the outliers (a mispaired face)
        beta = np.linalg.lstsq(a[keep], e[keep], rcond=None)[0]
        r = e - a @ beta
        keep = np.abs(r) <= max(3.0 * 1.4826 * float(np.median(np.abs(r[keep]))), 0.5)
    q = np.asarray(at, dtype=np.float64).reshape(2) - c
    return float(beta[0] + beta[1] * q[0] + beta[2] * q[1])


def _json_value(v: Any) -> Any:
    if isinstance(v, np.floating | float):
        return None if math.isnan(v) else float(v)
    return str(v)


def write_observations(
    path: str | os.PathLike[str], obs: np.ndarray, meta: dict[str, Any] | None = None
) -> Path:
    """Write an observation array to ``.csv`` (one row each, unknown values empty) or ``.json``
    (``meta`` keys, then ``observations`` as a list of objects, unknown values null).

    The file is written beside its destination and renamed into place, so a failure never
    leaves half a file.
    """
    dest = Path(path)
    kind = dest.suffix.lower()
    if kind not in (".csv", ".json"):
        raise InputError(f"observation file must end in .csv or .json, got '{dest}'")
    a = as_observation_array(obs)
    records = [{n: _json_value(rec[n]) for n in FIELDS} for rec in a]
    tmp = dest.with_name(f".{dest.name}.{os.getpid()}.tmp")
    try:
        with tmp.open("w", newline="", encoding="utf-8") as fh:
            if kind == ".csv":
                writer = csv.DictWriter(fh, fieldnames=FIELDS)
                writer.writeheader()
                writer.writerows(
                    {k: ("" if v is None else v) for k, v in r.items()} for r in records
                )
            else:
                json.dump({**(meta or {}), "observations": records}, fh, indent=1)
        os.replace(tmp, dest)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise InputError(
            f"cannot write '{dest}' ({exc.strerror or exc}); choose a writable path"
        ) from exc
    return dest


@dataclass(frozen=True)
class Correction:
    """Disparity corrections for N query points, with their uncertainty.

    Add ``value_px`` to the measured disparity. A query that cannot be served (no observations
    in its orientation bucket) has NaN value and sigma, ``n_used`` 0 and a ``reason``.
    """

    #: ndarray, shape (N,). Correction to add to the measured disparity, pixels.
    value_px: np.ndarray
    #: ndarray, shape (N,). Its standard deviation, pixels.
    sigma_px: np.ndarray
    #: ndarray of int, shape (N,). How many learned observations the value rests on.
    n_used: np.ndarray
    #: The lookup strategy that produced it ("nearest", "mean", "max", "min", "centre", "field").
    strategy: str
    #: Empty when served; otherwise why not.
    reason: str = ""

    def __post_init__(self) -> None:
        v = np.asarray(self.value_px, dtype=np.float64).copy()
        s = np.asarray(self.sigma_px, dtype=np.float64).copy()
        n = np.asarray(self.n_used, dtype=np.int64).copy()
        if not (v.ndim == 1 and v.shape == s.shape == n.shape):
            raise ShapeError(
                f"Correction arrays must share one shape (N,), got {v.shape}, {s.shape}, {n.shape}"
            )
        for a in (v, s, n):
            a.flags.writeable = False
        object.__setattr__(self, "value_px", v)
        object.__setattr__(self, "sigma_px", s)
        object.__setattr__(self, "n_used", n)

    @property
    def ok(self) -> bool:
        """True when every query was served."""
        return not self.reason

    @classmethod
    def unavailable(cls, n: int, strategy: str, reason: str) -> Correction:
        """N unserved queries (NaN) with the reason."""
        nan = np.full(n, np.nan)
        return cls(nan, nan, np.zeros(n, dtype=np.int64), strategy, reason)
