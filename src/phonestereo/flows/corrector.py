"""The learned correction of a fix store's observations under a flow configuration (thesis
§3.6, Fig. 4-2): the field or Figure 3-31's lookups, the heating term, the radial residual fix
and σ with its common-mode and extrapolation parts. Constructed by the application phase
(``evaluate``, ``depth``, the bench); :class:`~phonestereo.flows.config.FlowConfig` says how.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from scipy.stats import chi2

from phonestereo.fixes.distortion import RadialResidualFix
from phonestereo.fixes.radial_residual import pool_radial, refer_to_pooled_radial
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.roi_disparity import reference_rectification, tele_center_px
from phonestereo.learning.extent import LearnedExtent
from phonestereo.learning.field import FieldConfig, FieldLookup
from phonestereo.learning.heating_term import HeatingTerm
from phonestereo.learning.lookup import DictionaryLookup
from phonestereo.learning.observation import (
    Correction,
    as_observation_array,
    corrections_px,
    typical_correction_px,
    typical_row_error_px,
)
from phonestereo.learning.wt_lever import capture_lever_variance, lever_noise

ALL_BUCKETS = "all"


def _within_variance(samples: Sequence[tuple[float, int]]) -> float:
    """A robust pooled variance from sample variances on few degrees of freedom:
    (s², k) pairs → median of s² / (median(χ²_k) / k), px² (0 without samples).

    The plain median of s² is biased low when k is small (median(χ²_1) = 0.455), which left
    part of the faces' own noise in the capture scatter.

    >>> round(_within_variance([(0.455, 1), (0.693, 2), (0.789, 3)]), 2)  # each at its median
    1.0
    """
    if not samples:
        return 0.0
    s2, k = np.asarray(samples, dtype=np.float64).T
    return float(np.median(s2 / (chi2.median(k) / k)))


def _narrow(obs: np.ndarray) -> bool:
    """True when the learned disparities span too little (< 25 % of their level, e.g. faces at
    one distance) for a gain over disparity: the field then fits none instead of noise."""
    if obs.size < 3:
        return True
    lo, hi = np.percentile(obs["d_measured_px"], [5, 95])
    return bool(hi - lo < 0.25 * abs(float(np.median(obs["d_measured_px"]))))


class Corrector:
    """The learned correction of a store's observations under a :class:`FlowConfig`.

    Wraps :class:`~phonestereo.learning.field.FieldLookup` or
    :class:`~phonestereo.learning.lookup.DictionaryLookup`; with orientation buckets off all
    observations share one bucket. ``calibration_temperature_c`` (the calibration's
    conditions, °C, when known) lets the heating term refuse a slope the module could not
    have drifted by since then
    (:data:`~phonestereo.learning.heating_term.MAX_CALIBRATION_CORRECTION_REL`).
    ``tele_center_x_px`` (the tele's principal point in the reference rectified frame, px)
    weights the field's faces by their W-T scale's lever arm
    (:mod:`~phonestereo.learning.wt_lever`). :meth:`for_calibration` fills both.
    """

    def __init__(
        self, observations: Any, config: FlowConfig, principal_point_px: Any = None,
        radial_fits: Sequence[RadialResidualFix | None] = (),
        calibration_temperature_c: float | None = None,
        tele_center_x_px: float | None = None,
    ) -> None:
        #: The learning captures' residual radial distortion pooled (``radial_residual``), or None.
        self.radial = pool_radial(radial_fits) if config.radial_residual else None
        obs = refer_to_pooled_radial(as_observation_array(observations).copy(), self.radial)
        if not config.orientation_buckets and obs.size:
            obs["orientation"] = ALL_BUCKETS
        self.heating = HeatingTerm(False, "off (heating_by_temperature)")
        self.heating_time = HeatingTerm(False, "off (heating_by_temperature)", index="time_s")
        if config.heating_by_temperature and config.learned_correction:
            self.heating = HeatingTerm.fit(
                obs, calibration_temperature_c=calibration_temperature_c)
            obs = self.heating.normalise(obs)  # referred to one temperature
            if not self.heating.ok:  # no temperatures: the drift still to come is a σ
                self.heating_time = HeatingTerm.fit(obs, index="time_s",
                                                    tau_s=config.warmup_s / 2.6)
        self.observations = obs
        self.config = config
        self.tele_center_x_px = tele_center_x_px
        pp: tuple[float, float] | None = None
        if principal_point_px is not None:
            pp = (float(principal_point_px[0]), float(principal_point_px[1]))
        self._lookup: Any
        if config.lookup == "field":
            fcfg = FieldConfig(max_degree=config.field_max_degree, min_degree_gain=0)
            self._lookup = FieldLookup(obs, pp, fcfg, narrow_gain=_narrow(obs),
                                       tele_center_x_px=tele_center_x_px)
        else:
            self._lookup = DictionaryLookup(obs, pp)
        self.capture_sigma_px = self._capture_scatter()
        self.extents = (
            {str(b): self._extent(str(b)) for b in np.unique(obs["orientation"])}
            if obs.size
            else {}
        )

    @classmethod
    def for_calibration(
        cls, observations: Any, config: FlowConfig, calibration: Any,
        radial_fits: Sequence[RadialResidualFix | None] = (),
    ) -> Corrector:
        """The correction of ``observations`` learned under ``calibration`` (a
        :class:`~phonestereo.io.calibration.Calibration`): its temperature and the tele's
        principal point in the reference rectified frame (``config.mode``) passed on."""
        ref = reference_rectification(calibration.rig, config.mode)
        return cls(observations, config, radial_fits=radial_fits,
                   calibration_temperature_c=calibration.conditions.temperature_c,
                   tele_center_x_px=float(tele_center_px(ref, calibration.rig)[0]))

    def _capture_scatter(self) -> float:
        """Capture-to-capture scatter of the learned observations about the correction, px.

        The per-capture mean residual (observations of one capture share its focus state,
        W-T fit and heating) robustly spread over captures: how far a *new* capture may sit
        from the learned correction, beyond the correction's own fit uncertainty. A face
        capture's mean also carries its faces' own scatter (ruler and landmarks) over their
        number n, which a new capture does not: the pooled within-capture variance / n is
        taken out of the spread's square (over the 28 bench sets 0.014–0.126 px → 0–0.105 px,
        zero on 14 of them; docs/module-random.md, session 13). A capture of n faces gives its
        variance on n − 1 degrees of freedom, whose median is only 0.45 (1 dof) to 0.84 (4 dof)
        of the true variance, so each is divided by its χ² median per dof before the median is
        taken (:func:`_within_variance`); the bench's face captures hold 2–5 faces. A capture's
        mean also carries its W-T scale error times its faces' mean lever arm
        (:meth:`_lever_variance`), which a chart at the tele's centre does not: that is taken
        out too (random-3095: σ 0.33 → 0.29 %, within σ 94 → 89 %; docs/module-random.md,
        session 25).
        """
        obs = self.observations
        if obs.size == 0:
            return 0.0
        means, within, counts, lever_var = [], [], [], []
        for b in np.unique(obs["orientation"]):
            ob = obs[obs["orientation"] == b]
            q = np.column_stack([ob["x_px"], ob["y_px"], ob["d_measured_px"]])
            c = self._raw_correct(q, str(b))
            r = (ob["d_expected_px"] - ob["d_measured_px"]) - c.value_px
            lev = self._lever_variance(ob)
            for k, cid in enumerate(np.unique(ob["capture_id"])):
                rc = r[ob["capture_id"] == cid]
                rc = rc[np.isfinite(rc)]
                if rc.size:
                    means.append(float(np.mean(rc)))
                    counts.append(rc.size)
                    lever_var.append(float(lev[k]))
                    if rc.size > 1:
                        within.append((float(np.var(rc, ddof=1)), rc.size - 1))
        if len(means) < 4:
            return 0.0
        m = np.asarray(means)
        between = (1.4826 * float(np.median(np.abs(m - np.median(m))))) ** 2
        noise = _within_variance(within) * float(np.mean(1.0 / np.asarray(counts)))
        noise += float(np.mean(lever_var))
        return float(np.sqrt(max(between - noise, 0.0)))

    def _lever_variance(self, ob: np.ndarray) -> np.ndarray:
        """The variance each capture's mean correction owes its W-T scale error (G,) px², in
        ``np.unique`` order of the capture ids of one bucket's observations ``ob``
        (:func:`~phonestereo.learning.wt_lever.capture_lever_variance`, τ as the field's
        weights take it); zeros without the tele's centre."""
        groups = np.unique(ob["capture_id"], return_inverse=True)[1].ravel()
        n_g = int(groups.max()) + 1 if groups.size else 0
        if self.tele_center_x_px is None or not ob.size:
            return np.zeros(n_g)
        lever = ob["x_px"] - ob["d_measured_px"] - float(self.tele_center_x_px)
        tau = lever_noise(corrections_px(ob), lever, groups, ob["sigma_px"])[0]
        return capture_lever_variance(lever, groups, tau)

    def _extent(self, bucket: str) -> LearnedExtent:
        """The learned extent of a bucket, with residuals about this correction."""
        ob = self.observations[self.observations["orientation"] == bucket]
        q = np.column_stack([ob["x_px"], ob["y_px"], ob["d_measured_px"]])
        r = (ob["d_expected_px"] - ob["d_measured_px"]) - self._raw_correct(q, bucket).value_px
        drift = [t.gain_sigma for t in (self.heating, self.heating_time)
                 if np.isfinite(t.gain_sigma)]
        return LearnedExtent.from_observations(
            ob, np.nan_to_num(r), focal_rel_sigma=self.config.focal_rel_sigma,
            drift_gain_sigma=max(drift) if drift else float("nan"),
            lever_var_px2=self._lever_variance(ob),
        )

    def _raw_correct(self, query: Any, bucket: str) -> Correction:
        if self.config.lookup == "field":
            c: Correction = self._lookup.correct(query, bucket)
        else:
            c = self._lookup.correct(query, bucket, self.config.lookup)
        return c

    def bucket(self, orientation: str) -> str:
        """The bucket a capture of ``orientation`` is corrected in."""
        return orientation if self.config.orientation_buckets else ALL_BUCKETS

    def count(self, orientation: str) -> int:
        """Observations in the capture's bucket."""
        if self.observations.size == 0:
            return 0
        return int(np.sum(self.observations["orientation"] == self.bucket(orientation)))

    def typical_px(self, orientation: str) -> float:
        """The bucket's :func:`~phonestereo.learning.observation.typical_correction_px`."""
        ob = self.observations
        return typical_correction_px(ob[ob["orientation"] == self.bucket(orientation)]
                                     if ob.size else ob)

    def row_error_px(self, orientation: str, at: Any = None) -> float:
        """The bucket's :func:`~phonestereo.learning.observation.typical_row_error_px` at the
        reference rectified wide pixel ``at`` (x, y) (NaN when its observations did not record
        e)."""
        ob = self.observations
        return typical_row_error_px(ob[ob["orientation"] == self.bucket(orientation)]
                                    if ob.size else ob, at)

    def correct(
        self, query: Any, orientation: str, temperature_c: float | None = None,
        time_s: float | None = None,
    ) -> Correction:
        """Corrections (N,) for (x, y, d_measured) queries (N, 3), reference rectified pixels,
        of a capture at ``temperature_c`` (°C, None = not reported) and ``time_s``."""
        return self.correct_parts(query, orientation, temperature_c, time_s)[0]

    def heating_corrected(self, temperature_c: float | None) -> bool:
        """True when a capture at this temperature gets the learned heating term (so the
        warm-up gate need not wait its drift out)."""
        return self.heating.ok and temperature_c is not None and bool(np.isfinite(temperature_c))

    def correct_parts(
        self, query: Any, orientation: str, temperature_c: float | None = None,
        time_s: float | None = None,
    ) -> tuple[Correction, dict[str, np.ndarray]]:
        """:meth:`correct` and its σ parts (px, each (N,)): ``fit`` (the correction's own
        statistical error), ``capture`` (a new capture's own offset: the capture-to-capture
        scatter), ``systematic`` (common-mode scale: the learned captures' relative spread and
        the focal prior, :class:`~phonestereo.learning.extent.LearnedExtent`),
        ``extrapolation`` (beyond the learned disparities and sensor positions) and ``heating``
        (the learned heating term's σ at this temperature; a capture without a temperature
        under a learned term carries the learned temperatures' whole drift; without
        temperatures, the drift the learning captures showed over time, extrapolated to
        ``time_s``, :class:`~phonestereo.learning.heating_term.HeatingTerm`)."""
        bucket = self.bucket(orientation)
        query = np.array(query, dtype=np.float64, copy=True)
        heat_v, heat_s = np.zeros(len(query)), np.zeros(len(query))
        if self.heating.ok:
            if temperature_c is not None and self.heating_corrected(temperature_c):
                v, sd = self.heating.offset_px(np.full(len(query), float(temperature_c)))
                heat_v, heat_s = v, sd
            else:
                lo, hi = self.heating.range_c
                heat_s = np.full(len(query), abs(self.heating.slope_px_per_c) * (hi - lo))
            if query.ndim == 2 and query.shape[1] == 3:
                query[:, 2] += heat_v  # the field lives at the reference temperature
        elif self.heating_time.ok and time_s is not None:
            heat_s = self.heating_time.offset_px(np.full(len(query), float(time_s)))[1]
        c = self._raw_correct(query, bucket)
        if not c.ok:
            return c, {}
        c = Correction(c.value_px + heat_v, c.sigma_px, c.n_used, c.strategy, c.reason)
        fit = c.sigma_px
        if self.config.lookup == "field":  # the mean's error; one face's scatter is not ours
            fit = self._lookup.fits[bucket].field.predict(query, scatter=False).sigma_px
        n = len(fit)
        ext = self.extents.get(bucket)
        sys_px, ext_px = (
            ext.extra_sigma_px(query, c.value_px) if ext is not None else (np.zeros(n),) * 2
        )
        parts = {"fit": fit, "capture": np.full(n, self.capture_sigma_px),
                 "systematic": sys_px, "extrapolation": ext_px}
        if self.heating.ok or self.heating_time.ok:
            parts["heating"] = heat_s
        sigma = np.sqrt(sum(v**2 for v in parts.values()))
        return Correction(c.value_px, sigma, c.n_used, c.strategy, c.reason), parts


__all__ = ["ALL_BUCKETS", "Corrector"]
