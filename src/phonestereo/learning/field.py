"""A smooth correction field over the sensor and disparity (beyond thesis §3.6;
docs/architecture.md).

Instead of looking up the nearest learned offset, fit

    c(x, y, d) = offset(x, y) + gain(x, y) · d̃,      d̃ = (d − d_ref) / d_scale

with ``offset`` and ``gain`` 2-D polynomials in normalised sensor coordinates
u = (x − cx)/s, v = (y − cy)/s of total degree 0..3 (gain may be absent). The fit is robust
(:func:`scipy.optimize.least_squares` with ``loss="soft_l1"``): a face whose IPD is far from
the assumed one is down-weighted, not followed. The two degrees are chosen by k-fold
cross-validation (folds grouped by capture when there are enough captures, since the
observations of one capture share its errors), keeping the simplest model within one standard
error of the best score. σ at a query is the fit covariance propagated to it ⊕ the robust
residual scatter.

Examples
--------
>>> import numpy as np
>>> from phonestereo.learning.observation import Observation
>>> rng = np.random.default_rng(0)     # faces at 1–3 m, f·B = 18 px·m; the offset tilts in x
>>> obs = []
>>> for i, (x, y, z) in enumerate(rng.uniform([0, 0, 1], [2000, 1500, 3], (60, 3))):
...     c = 0.3 + 1e-4 * (x - 1000) + rng.normal(0, 0.01)
...     obs.append(Observation(x, y, 18 / z - c, 18 / z, z, "landscape", "", 0.0, None,
...                            f"c{i % 10}"))
>>> fit = fit_field(obs, principal_point_px=(1000.0, 750.0))
>>> fit.ok, fit.field.degree_offset, fit.field.degree_gain     # a tilt, no gain
(True, 1, -1)
>>> corr = fit.field.predict([[1500.0, 750.0, 9.0]])      # truth 0.35 px
>>> round(float(corr.value_px[0]), 2), bool(corr.sigma_px[0] < 0.02)
(0.35, True)
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from scipy.optimize import least_squares

from phonestereo.errors import InputError
from phonestereo.learning.lookup import as_queries
from phonestereo.learning.observation import Correction, as_observation_array, corrections_px
from phonestereo.learning.wt_lever import lever_weights

_MAD = 1.4826  # MAD → σ for a normal distribution


@dataclass(frozen=True)
class FieldConfig:
    """How the smooth field is fitted."""

    #: Highest total degree tried for offset and gain (0..3).
    max_degree: int = 3
    #: Cross-validation folds (≥ 2).
    folds: int = 5
    #: Robust loss of ``least_squares`` ("soft_l1", "huber", "cauchy", "linear").
    loss: str = "soft_l1"
    #: Residual (px) where the loss turns robust; None = 1.5 × the robust residual scatter.
    f_scale_px: float | None = None
    #: Seed of the fold assignment.
    seed: int = 0
    #: Lowest gain degree the model choice may pick (-1: no gain term allowed; 0: always a constant
    #: gain, the physics of a baseline or focal-length error, §3.6 — the learned disparities rarely
    #: span enough for cross-validation to prove it, yet it decides the extrapolation beyond them).
    min_degree_gain: int = -1
    #: Highest gain degree tried (-1: offsets only, for disparities learned at one distance).
    max_gain_degree: int = 3

    def __post_init__(self) -> None:
        if not -1 <= self.min_degree_gain <= self.max_degree:
            raise InputError(f"min_degree_gain must be -1..max_degree, got {self.min_degree_gain}")
        if not 0 <= self.max_degree <= 3:
            raise InputError(f"max_degree must be 0..3, got {self.max_degree}")
        if self.folds < 2:
            raise InputError(f"folds must be ≥ 2, got {self.folds}")
        if self.loss not in ("soft_l1", "huber", "cauchy", "linear", "arctan"):
            raise InputError(f"unknown loss {self.loss!r}; use soft_l1, huber, cauchy or linear")


@dataclass(frozen=True)
class CVScore:
    """Cross-validation of one model.

    ``score_px`` is the RMS held-out residual (each clipped at 3 σ so that outliers do not
    decide); ``excess_px2`` the model's mean squared held-out residual minus the best model's,
    ``se_excess_px2`` the standard error of that paired difference (over captures).
    """

    degree_offset: int
    degree_gain: int
    n_params: int
    score_px: float
    excess_px2: float
    se_excess_px2: float


@dataclass(frozen=True)
class _Frame:
    """Normalisation of (x, y, d) shared by fit and prediction."""

    cx: float
    cy: float
    s: float
    d_ref: float
    d_scale: float

    def design(self, q: np.ndarray, deg_o: int, deg_g: int) -> np.ndarray:
        u, v = (q[:, 0] - self.cx) / self.s, (q[:, 1] - self.cy) / self.s
        dd = (q[:, 2] - self.d_ref) / self.d_scale
        mono = [u**i * v**j for t in range(4) for i in range(t, -1, -1) for j in [t - i]]
        n_terms = [1, 3, 6, 10]
        cols = mono[: n_terms[deg_o]]
        if deg_g >= 0:
            cols += [dd * m for m in mono[: n_terms[deg_g]]]
        return np.stack(cols, axis=1)


def _n_params(deg_o: int, deg_g: int) -> int:
    return (deg_o + 1) * (deg_o + 2) // 2 + (0 if deg_g < 0 else (deg_g + 1) * (deg_g + 2) // 2)


def _weights(r: np.ndarray, loss: str, f_scale: float) -> np.ndarray:
    """ρ'(z), z = (r / f)²: the IRLS weight of each residual under ``least_squares``'s loss."""
    z = (r / f_scale) ** 2
    if loss == "soft_l1":
        return 1 / np.sqrt(1 + z)
    if loss == "huber":
        return 1 / np.sqrt(np.maximum(z, 1))
    if loss == "cauchy":
        return 1 / (1 + z)
    if loss == "arctan":
        return 1 / (1 + z**2)
    return np.ones_like(r)


def _irls(A: np.ndarray, c: np.ndarray, loss: str, f_scale: float) -> np.ndarray:
    """The same robust fit by iteratively reweighted normal equations (P ≤ 20 unknowns): the
    cross-validation runs ~100 fits, where least_squares' per-iteration SVD dominates."""
    w = np.ones_like(c)
    coef = np.zeros(A.shape[1])
    for _ in range(100):
        Aw = A * w[:, None]
        new = np.linalg.lstsq(Aw.T @ A, Aw.T @ c, rcond=None)[0]
        done = np.max(np.abs(new - coef)) <= 1e-10 * (1 + np.max(np.abs(new)))
        coef = new
        if done or loss == "linear":
            break
        w = _weights(A @ coef - c, loss, f_scale)
    return coef


def _robust_fit(
    A: np.ndarray, c: np.ndarray, loss: str, f_scale: float
) -> tuple[np.ndarray, np.ndarray]:
    """The final robust fit (``least_squares``, started from IRLS); returns (coefficients,
    IRLS weights at the solution)."""
    x0 = _irls(A, c, loss, f_scale)
    if loss == "linear":
        return x0, np.ones_like(c)
    res = least_squares(
        lambda t: A @ t - c, x0, jac=lambda t: A, loss=loss, f_scale=f_scale, method="trf"
    )
    return res.x, _weights(A @ res.x - c, loss, f_scale)


@dataclass(frozen=True)
class SmoothField:
    """A fitted correction field (see the module docstring for the model)."""

    #: ``degree_offset``, ``degree_gain``: Chosen polynomial degrees (gain −1 = no gain term).
    degree_offset: int
    #: See ``degree_offset`` above.
    degree_gain: int
    #: ndarray, shape (P,). Coefficients (offset terms, then gain terms).
    coef: np.ndarray
    #: ndarray, shape (P, P). Their covariance, px².
    cov: np.ndarray
    #: Robust scatter of the residuals (1.4826 · MAD), px.
    scatter_px: float
    #: ``n_used``, ``n_outliers``: Observations fitted; those with |residual| > 3 scatter.
    n_used: int
    #: See ``n_used`` above.
    n_outliers: int
    #: tuple of CVScore. Every model tried, in order of complexity.
    cv: tuple[CVScore, ...]
    frame: _Frame

    def predict(self, query: Any, *, scatter: bool = True) -> Correction:
        """Correction at (x_px, y_px, d_measured_px) points, shape (N, 3), with σ: the fit's
        ⊕ (``scatter``) one observation's robust scatter."""
        q = as_queries(query)
        A = self.frame.design(q, self.degree_offset, self.degree_gain)
        var_fit = np.einsum("ij,jk,ik->i", A, self.cov, A)
        sigma = np.sqrt(np.maximum(var_fit, 0) + (self.scatter_px**2 if scatter else 0.0))
        return Correction(A @ self.coef, sigma, np.full(len(q), self.n_used), "field")

    def offset_gain(self, xy: Any) -> tuple[np.ndarray, np.ndarray]:
        """The field as c = offset_px + gain · d at sensor points (N, 2): (offset_px, gain)."""
        p = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        f = self.frame
        c0 = self.predict(np.c_[p, np.full(len(p), f.d_ref)]).value_px
        c1 = self.predict(np.c_[p, np.full(len(p), f.d_ref + f.d_scale)]).value_px
        gain = (c1 - c0) / f.d_scale
        return c0 - gain * f.d_ref, gain


@dataclass(frozen=True)
class FieldFit:
    """Result of :func:`fit_field`: the field, or None with the reason."""

    field: SmoothField | None
    reason: str = ""

    @property
    def ok(self) -> bool:
        return self.field is not None


def _groups(obs: np.ndarray) -> np.ndarray:
    """Capture index per observation (observations of one capture share its errors)."""
    return np.unique(obs["capture_id"], return_inverse=True)[1].ravel()


def _folds(groups: np.ndarray, n: int, k: int, seed: int) -> np.ndarray:
    """Fold index per observation: whole captures when there are ≥ k of them, else at random."""
    rng = np.random.default_rng(seed)
    n_groups = int(groups.max()) + 1
    if n_groups >= k:
        return rng.permutation(np.arange(n_groups) % k)[groups]
    return rng.permutation(np.arange(n) % k)


def _cross_validate(
    design: Callable[[int, int], np.ndarray],
    c: np.ndarray,
    groups: np.ndarray,
    cfg: FieldConfig,
    f: float,
) -> list[CVScore]:
    """Held-out clipped squared residuals of every feasible model (``design(deg_o, deg_g)``:
    its weighted design matrix over the observations, ``c`` the weighted corrections); the
    one-standard-error comparison is paired (same points, per capture), so shared noise
    cancels."""
    fold = _folds(groups, len(c), cfg.folds, cfg.seed)
    k = int(fold.max()) + 1
    n_train = min(int((fold != i).sum()) for i in range(k))
    clip2 = (3.0 * f / 1.5) ** 2
    models, sq = [], []
    for deg_o in range(cfg.max_degree + 1):
        for deg_g in range(-1, min(cfg.max_degree, cfg.max_gain_degree) + 1):
            p = _n_params(deg_o, deg_g)
            if 3 * p > n_train:
                continue
            A = design(deg_o, deg_g)
            r2 = np.empty_like(c)
            for i in range(k):
                tr, te = fold != i, fold == i
                coef = _irls(A[tr], c[tr], cfg.loss, f)
                r2[te] = np.minimum((A[te] @ coef - c[te]) ** 2, clip2)
            models.append((deg_o, deg_g, p))
            sq.append(r2)
    if not sq:
        return []
    r2_all = np.array(sq)
    best = int(np.argmin(r2_all.mean(axis=1)))
    g = groups if int(groups.max()) + 1 >= 2 * k else np.arange(len(c))
    n_g = int(g.max()) + 1
    out = []
    for (deg_o, deg_g, p), r2 in zip(models, r2_all, strict=True):
        diff = np.bincount(g, r2 - r2_all[best], n_g) / np.maximum(np.bincount(g, None, n_g), 1)
        se = float(np.std(diff, ddof=1) / np.sqrt(n_g)) if n_g > 1 else 0.0
        excess = float(np.mean(r2 - r2_all[best]))
        out.append(CVScore(deg_o, deg_g, p, float(np.sqrt(r2.mean())), excess, se))
    return sorted(out, key=lambda s: (s.n_params, s.degree_offset))


def fit_field(
    observations: Any,
    principal_point_px: tuple[float, float] | None = None,
    config: FieldConfig | None = None,
    *,
    tele_center_x_px: float | None = None,
) -> FieldFit:
    """Fit the smooth correction field to learned observations (one orientation bucket).

    Parameters
    ----------
    observations : structured ndarray (N,) or sequence of Observation
        The learned observations of one bucket.
    principal_point_px : (float, float) or None
        Centre of the sensor polynomials; None = the centre of the learned positions.
    config : FieldConfig
    tele_center_x_px : float, optional
        x of the tele's principal point in the observations' rectified frame, px: the fit is
        then weighted by the W-T scale's lever arm (:mod:`~phonestereo.learning.wt_lever`);
        None fits every observation alike.

    Returns
    -------
    FieldFit
        ``field`` with the chosen degrees, CV scores and σ; or None with a reason when there
        are no observations. ``scatter_px`` is then the weighted residuals' (one observation
        of median weight).
    """
    cfg = config or FieldConfig()
    obs = as_observation_array(observations)
    if obs.size == 0:
        return FieldFit(None, "no observations to fit")
    q = np.stack([obs["x_px"], obs["y_px"], obs["d_measured_px"]], axis=1)
    c = corrections_px(obs)
    lo, hi = q[:, :2].min(axis=0), q[:, :2].max(axis=0)
    cx, cy = principal_point_px or tuple((lo + hi) / 2)
    s = max(float(np.max(np.abs(q[:, :2] - [cx, cy]))), 1.0)
    d_scale = float(np.std(q[:, 2]))
    frame = _Frame(cx, cy, s, float(np.mean(q[:, 2])), d_scale if d_scale > 1e-6 else 1.0)
    groups = _groups(obs)
    w = np.ones(len(c))
    if tele_center_x_px is not None:  # x_t = x_w − d: the lever of the capture's W-T scale
        lever = q[:, 0] - q[:, 2] - float(tele_center_x_px)
        w = lever_weights(c, lever, groups, obs["sigma_px"])
    c = c * w

    def design(deg_o: int, deg_g: int) -> np.ndarray:
        return frame.design(q, deg_o, deg_g) * w[:, None]

    f = cfg.f_scale_px
    if f is None:
        resid = c - np.median(c)  # robust scale about the median, or about the richest model
        if 3 * _n_params(cfg.max_degree, cfg.max_degree) <= len(c):
            A = design(cfg.max_degree, cfg.max_degree)
            resid = c - A @ np.linalg.lstsq(A, c, rcond=None)[0]
        # floor 1 mpx: finer corrections are meaningless and a zero scale stalls the solver
        f = 1.5 * max(_MAD * float(np.median(np.abs(resid - np.median(resid)))), 1e-3)
    enough = len(obs) >= 2 * cfg.folds
    cv = _cross_validate(design, c, groups, cfg, f) if enough else []
    if cv:  # the simplest model within one (paired) standard error of the best
        allowed = [t for t in cv if t.degree_gain >= cfg.min_degree_gain]
        chosen = next((t for t in allowed if t.excess_px2 <= t.se_excess_px2), allowed[0])
        deg_o, deg_g = chosen.degree_offset, chosen.degree_gain
    else:
        deg_o, deg_g = 0, min(cfg.min_degree_gain, 0) if len(c) >= 3 else -1
    A = design(deg_o, deg_g)
    coef, rw = _robust_fit(A, c, cfg.loss, f)
    r = c - A @ coef
    scatter = _MAD * float(np.median(np.abs(r - np.median(r))))
    if len(c) == 1:
        sig = float(obs["sigma_px"][0])
        scatter = sig if np.isfinite(sig) else float("nan")
    cov = np.linalg.pinv(A.T @ (rw[:, None] * A)) * scatter**2
    return FieldFit(
        SmoothField(
            degree_offset=deg_o,
            degree_gain=deg_g,
            coef=coef,
            cov=cov,
            scatter_px=scatter,
            n_used=len(c),
            n_outliers=int((np.abs(r) > 3 * scatter).sum()),
            cv=tuple(cv),
            frame=frame,
        )
    )


class FieldLookup:
    """One smooth field per orientation bucket, with the interface of ``DictionaryLookup``."""

    def __init__(
        self,
        observations: Any,
        principal_point_px: tuple[float, float] | None = None,
        config: FieldConfig | None = None,
        *,
        narrow_gain: bool = False,
        tele_center_x_px: float | None = None,
    ) -> None:
        obs = as_observation_array(observations)
        cfg = config or FieldConfig()
        if narrow_gain:  # too narrow a disparity span to fit a gain: offsets only
            cfg = replace(cfg, min_degree_gain=-1, max_gain_degree=-1)
        self.fits = {
            str(o): fit_field(obs[obs["orientation"] == o], principal_point_px, cfg,
                              tele_center_x_px=tele_center_x_px)
            for o in np.unique(obs["orientation"])
        }

    def correct(self, query: Any, orientation: str) -> Correction:
        """Field corrections for (N, 3) query points of one bucket (NaN + reason if none)."""
        q = as_queries(query)
        fit = self.fits.get(orientation)
        if fit is None or fit.field is None:
            why = fit.reason if fit is not None else "no observations learned"
            return Correction.unavailable(
                len(q), "field", f"{why} in orientation bucket '{orientation}' (§3.4)"
            )
        return fit.field.predict(q)
