"""Compare the lookup strategies as thesis Figure 3-31 does, plus the smooth field
(docs/architecture.md).

Corrections learned from one set of observations (faces, §3.6) are applied to a verification
set whose expected disparity is known independently (chart corners at measured depths): per
strategy, the error of the correction against the verification set's own
``d_expected − d_measured`` and the relative depth error left after correcting,
``|d_expected / (d_measured + correction) − 1|`` (= |Z_corrected − Z| / Z, eq. 4), beside
"none" (no correction, Figure 3-31 top left). Each bucket of the verification set is served
only from the same learned bucket (§3.4).

Examples
--------
>>> from phonestereo.learning.observation import Observation
>>> learn = [Observation(x, 750.0, 9.0 - 0.3, 9.0, 2.0, "landscape", "", 0.0, None, f"f{i}")
...          for i, x in enumerate(range(100, 2000, 100))]
>>> check = [Observation(1000.0, 700.0, 4.5 - 0.3, 4.5, 4.0, "landscape", "", 0.0, None, "v1")]
>>> table = compare_strategies(learn, check)
>>> round(table.row("none").median_rel_depth, 3), round(table.row("mean").median_rel_depth, 3)
(0.071, 0.0)
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from phonestereo.learning.field import FieldConfig, FieldLookup
from phonestereo.learning.lookup import STRATEGIES, DictionaryLookup, LookupConfig
from phonestereo.learning.observation import Correction, as_observation_array, corrections_px

#: Rows of the comparison, in order.
ROWS = ("none", *STRATEGIES, "field")


@dataclass(frozen=True)
class StrategyRow:
    """How one strategy did on the verification set (errors in px; depth errors relative).

    ``coverage_2sigma`` is the fraction of points whose |error| ≤ 2 σ (σ calibration);
    ``n`` counts served points (a bucket without learned observations is not served).
    """

    strategy: str
    n: int
    median_abs_px: float
    p90_abs_px: float
    rms_px: float
    median_rel_depth: float
    p90_rel_depth: float
    coverage_2sigma: float
    median_sigma_px: float


@dataclass(frozen=True)
class StrategyTable:
    """The comparison table: one :class:`StrategyRow` per entry of :data:`ROWS`."""

    rows: tuple[StrategyRow, ...]
    n_train: int
    n_test: int
    field_degrees: dict[str, tuple[int, int]]

    def row(self, strategy: str) -> StrategyRow:
        """The row of one strategy."""
        return next(r for r in self.rows if r.strategy == strategy)

    def best_dictionary(self, metric: str = "rms_px") -> StrategyRow:
        """The Figure 3-31 strategy with the lowest ``metric``."""
        return min((self.row(s) for s in STRATEGIES), key=lambda r: getattr(r, metric))

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return asdict(self)

    def to_markdown(self) -> str:
        """The table as Markdown (errors in px, depth errors in %)."""
        head = (
            "| strategy | n | median abs px | p90 abs px | rms px | median rel depth % | "
            "p90 rel depth % | |err| ≤ 2σ | median σ px |\n|" + "---|" * 9
        )
        lines = [
            f"| {r.strategy} | {r.n} | {r.median_abs_px:.3f} | {r.p90_abs_px:.3f} | "
            f"{r.rms_px:.3f} | {100 * r.median_rel_depth:.2f} | {100 * r.p90_rel_depth:.2f} | "
            f"{r.coverage_2sigma:.2f} | {r.median_sigma_px:.3f} |"
            for r in self.rows
        ]
        return "\n".join([head, *lines])


def _row(name: str, c_hat: np.ndarray, sigma: np.ndarray, test: np.ndarray) -> StrategyRow:
    ok = np.isfinite(c_hat)
    truth = corrections_px(test)[ok]
    err = np.abs(c_hat[ok] - truth)
    d_exp, d_meas = test["d_expected_px"][ok], test["d_measured_px"][ok]
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.abs(d_exp / (d_meas + c_hat[ok]) - 1.0)
    rel = np.where(np.isfinite(rel), rel, np.inf)  # corrected to d ≤ 0: no depth at all
    nan = float("nan")

    def q(a: np.ndarray, p: float) -> float:
        return float(np.percentile(a, p)) if a.size else nan

    s = sigma[ok]
    return StrategyRow(
        strategy=name,
        n=int(ok.sum()),
        median_abs_px=q(err, 50),
        p90_abs_px=q(err, 90),
        rms_px=float(np.sqrt(np.mean(err**2))) if err.size else nan,
        median_rel_depth=q(rel, 50),
        p90_rel_depth=q(rel, 90),
        coverage_2sigma=float(np.mean(err <= 2 * s)) if np.isfinite(s).any() else nan,
        median_sigma_px=q(s[np.isfinite(s)], 50),
    )


def compare_strategies(
    train_obs: Any,
    test_obs: Any,
    principal_point_px: tuple[float, float] | None = None,
    lookup_config: LookupConfig | None = None,
    field_config: FieldConfig | None = None,
) -> StrategyTable:
    """Every Figure 3-31 strategy and the smooth field, learned on one set, judged on another.

    Parameters
    ----------
    train_obs : structured ndarray or sequence of Observation
        The learning set (e.g. faces).
    test_obs : structured ndarray or sequence of Observation
        The verification set: points whose expected disparity is known independently; their
        ``d_expected − d_measured`` is the correction each strategy should have produced.
    principal_point_px : (float, float) or None
        The wide principal point (for ``centre`` and the field's polynomials).
    lookup_config, field_config
        Settings of the dictionary strategies and of the field.

    Returns
    -------
    StrategyTable
    """
    train = as_observation_array(train_obs)
    test = as_observation_array(test_obs)
    lut = DictionaryLookup(train, principal_point_px, lookup_config)
    fields = FieldLookup(train, lut.principal_point_px, field_config)
    n = len(test)
    out: dict[str, tuple[np.ndarray, np.ndarray]] = {
        name: (np.full(n, np.nan), np.full(n, np.nan)) for name in ROWS
    }
    out["none"] = (np.zeros(n), np.full(n, np.nan))  # no correction, no σ
    for o in np.unique(test["orientation"]):
        sel = test["orientation"] == o
        q = np.stack([test["x_px"][sel], test["y_px"][sel], test["d_measured_px"][sel]], axis=1)
        served: dict[str, Correction] = {s: lut.correct(q, str(o), s) for s in STRATEGIES}
        served["field"] = fields.correct(q, str(o))
        for name, corr in served.items():
            out[name][0][sel] = corr.value_px
            out[name][1][sel] = corr.sigma_px
    degrees = {
        o: (f.field.degree_offset, f.field.degree_gain)
        for o, f in fields.fits.items()
        if f.field is not None
    }
    rows = tuple(_row(name, *out[name], test) for name in ROWS)
    return StrategyTable(rows, len(train), n, degrees)
