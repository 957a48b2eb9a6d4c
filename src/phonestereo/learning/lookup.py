"""Dictionary lookups of learned disparity corrections: the strategies of thesis Figure 3-31.

The thesis learns offsets ``d_expected − d_measured`` from faces (§3.6) and applies them to
verification-chart corners in five ways (Figure 3-31): the closest learned landmark
(``"nearest"``), the mean of all offsets (``"mean"``), the largest (``"max"``) or smallest
(``"min"``) offset, and the offset at the image centre (``"centre"``). Closest was best; the
centre offset was "promising with a much reduced need for faces". Here each returns a
:class:`~phonestereo.learning.observation.Correction` with σ, and every lookup is keyed by the
orientation bucket (§3.4, docs/architecture.md): a fix learned in one bucket is never applied in
another.

σ per strategy (pixels):

- ``nearest``: the k nearest learned points in normalised (x, y, d) (a cKDTree), inverse-
  distance-weighted mean; σ is their weighted spread (or the point's own σ when k = 1).
- ``mean``: σ = s/√n ⊕ s (uncertainty of the mean ⊕ the scatter a constant cannot explain).
- ``max``, ``min``: σ = the RMS of the learned offsets about the chosen constant.
- ``centre``: the mean of the k observations nearest the principal point; σ = their
  spread/√k ⊕ the RMS of all offsets about it.

Examples
--------
>>> from phonestereo.learning.observation import Observation
>>> obs = [Observation(x, 750.0, 9.0 - c, 9.0, 2.0, "landscape", "", 0.0, None, "f1")
...        for x, c in [(500.0, 0.2), (1000.0, 0.3), (1500.0, 0.4)]]
>>> lut = DictionaryLookup(obs, principal_point_px=(1000.0, 750.0),
...                        config=LookupConfig(k_nearest=1))
>>> lut.correct([[1480.0, 760.0, 8.6]], "landscape", "nearest").value_px.round(3).tolist()
[0.4]
>>> lut.correct([[0.0, 0.0, 9.0]], "landscape", "centre").value_px.round(3).tolist()
[0.3]
>>> print(lut.correct([[0.0, 0.0, 9.0]], "portrait", "mean").reason[:50])
no observations learned in orientation bucket 'por
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from phonestereo.errors import InputError, ShapeError
from phonestereo.learning.observation import Correction, as_observation_array, corrections_px

#: The dictionary strategies of Figure 3-31.
STRATEGIES = ("nearest", "mean", "max", "min", "centre")


@dataclass(frozen=True)
class LookupConfig:
    """How the dictionary strategies look up."""

    #: Learned points averaged by ``nearest`` (1 = the thesis's closest landmark).
    k_nearest: int = 4
    #: Learned points nearest the principal point averaged by ``centre``.
    k_centre: int = 4
    #: Sensor distance that counts as one unit in the (x, y, d) metric; None = the larger standard
    #: deviation of the learned x and y.
    xy_scale_px: float | None = None
    #: Disparity difference that counts as one unit; None = the learned disparities' std.
    d_scale_px: float | None = None

    def __post_init__(self) -> None:
        if self.k_nearest < 1 or self.k_centre < 1:
            raise InputError("k_nearest and k_centre must be ≥ 1")
        for name in ("xy_scale_px", "d_scale_px"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise InputError(f"{name} must be a positive number of pixels or None, got {v}")


def as_queries(query: Any) -> np.ndarray:
    """Query points as a float64 (N, 3) array of (x_px, y_px, d_measured_px)."""
    q = np.asarray(query, dtype=np.float64)
    if q.ndim == 1 and q.shape[0] == 3:
        q = q[None, :]
    if q.ndim != 2 or q.shape[1] != 3:
        raise ShapeError(f"query must have shape (N, 3) = (x_px, y_px, d_px), got {q.shape}")
    if not np.all(np.isfinite(q)):
        raise ShapeError("query points must be finite")
    return q


def _scale(v: np.ndarray) -> float:
    s = float(np.std(v)) if v.size else 0.0
    return s if s > 1e-9 else 1.0


class _Bucket:
    """The learned observations of one orientation bucket, prepared for every strategy."""

    def __init__(self, obs: np.ndarray, pp: tuple[float, float], cfg: LookupConfig) -> None:
        self.pts = np.stack([obs["x_px"], obs["y_px"], obs["d_measured_px"]], axis=1)
        self.c = corrections_px(obs)
        self.sigma = np.asarray(obs["sigma_px"], dtype=np.float64)
        self.n = int(self.c.size)
        xy = cfg.xy_scale_px or max(_scale(self.pts[:, 0]), _scale(self.pts[:, 1]))
        self.norm = np.array([xy, xy, cfg.d_scale_px or _scale(self.pts[:, 2])])
        self.tree = cKDTree(self.pts / self.norm)
        self.xy_tree = cKDTree(self.pts[:, :2] / xy)
        self.pp = np.asarray(pp, dtype=np.float64) / xy
        self.std = float(np.std(self.c, ddof=1)) if self.n > 1 else float(self.sigma[0])
        self.cfg = cfg

    def rms_about(self, v: float) -> float:
        return float(np.sqrt(np.mean((self.c - v) ** 2)))

    def nearest(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        k = min(self.cfg.k_nearest, self.n)
        dist, idx = self.tree.query(q / self.norm, k=k)
        dist, idx = dist.reshape(len(q), k), idx.reshape(len(q), k)
        w = 1.0 / (dist + 1e-3)  # inverse distance; 1e-3 normalised units caps exact hits
        w /= w.sum(axis=1, keepdims=True)
        c = self.c[idx]
        value = (w * c).sum(axis=1)
        if k == 1:
            own = self.sigma[idx[:, 0]]
            sigma = np.where(np.isfinite(own), own, self.std)
        else:
            n_eff = 1.0 / (w**2).sum(axis=1)
            var = (w * (c - value[:, None]) ** 2).sum(axis=1) * n_eff / np.maximum(n_eff - 1, 1e-9)
            sigma = np.sqrt(var)
        return value, sigma, np.full(len(q), k)

    def constant(self, strategy: str) -> tuple[float, float, int]:
        if strategy == "mean":
            v = float(np.mean(self.c))
            return v, float(np.hypot(self.std / np.sqrt(self.n), self.std)), self.n
        if strategy in ("max", "min"):
            v = float(np.max(self.c) if strategy == "max" else np.min(self.c))
            return v, self.rms_about(v), 1
        k = min(self.cfg.k_centre, self.n)  # centre
        _, idx = self.xy_tree.query(self.pp, k=k)
        c = self.c[np.atleast_1d(idx)]
        v = float(np.mean(c))
        spread = float(np.std(c, ddof=1)) if k > 1 else self.std
        return v, float(np.hypot(spread / np.sqrt(k), self.rms_about(v))), k


class DictionaryLookup:
    """The Figure 3-31 strategies over learned observations, keyed by orientation bucket.

    Parameters
    ----------
    observations : structured ndarray (N,) or sequence of Observation
        Learned observations (e.g. ``FixStore.observations(focus_group=...)``).
    principal_point_px : (float, float) or None
        The wide camera's principal point (cx, cy) for ``centre``; None = the centre of the
        learned positions' bounding box.
    config : LookupConfig
    """

    def __init__(
        self,
        observations: Any,
        principal_point_px: tuple[float, float] | None = None,
        config: LookupConfig | None = None,
    ) -> None:
        obs = as_observation_array(observations)
        self.config = config or LookupConfig()
        if principal_point_px is None and obs.size:
            principal_point_px = (
                float(obs["x_px"].min() + obs["x_px"].max()) / 2,
                float(obs["y_px"].min() + obs["y_px"].max()) / 2,
            )
        self.principal_point_px = principal_point_px
        self._buckets = {
            str(o): _Bucket(obs[obs["orientation"] == o], principal_point_px or (0, 0), self.config)
            for o in np.unique(obs["orientation"])
        }

    @property
    def orientations(self) -> tuple[str, ...]:
        """The orientation buckets with learned observations."""
        return tuple(sorted(self._buckets))

    def count(self, orientation: str) -> int:
        """Learned observations in a bucket (0 when none)."""
        b = self._buckets.get(orientation)
        return 0 if b is None else b.n

    def correct(self, query: Any, orientation: str, strategy: str = "nearest") -> Correction:
        """Corrections for query points of one orientation bucket.

        Parameters
        ----------
        query : array_like, shape (N, 3)
            (x_px, y_px, d_measured_px) in the rectified wide image.
        orientation : str
            Bucket of the capture being corrected.
        strategy : {"nearest", "mean", "max", "min", "centre"}

        Returns
        -------
        Correction
            value_px, sigma_px, n_used of shape (N,); with a reason and NaN when the bucket
            holds no observations.
        """
        if strategy not in STRATEGIES:
            raise InputError(f"unknown lookup strategy {strategy!r}; choose one of {STRATEGIES}")
        q = as_queries(query)
        b = self._buckets.get(orientation)
        if b is None:
            return Correction.unavailable(
                len(q),
                strategy,
                f"no observations learned in orientation bucket '{orientation}' (learned: "
                f"{list(self.orientations)}); learn in this orientation first (§3.4)",
            )
        if strategy == "nearest":
            return Correction(*b.nearest(q), strategy=strategy)
        v, s, n = b.constant(strategy)
        m = len(q)
        return Correction(np.full(m, v), np.full(m, s), np.full(m, n), strategy)
