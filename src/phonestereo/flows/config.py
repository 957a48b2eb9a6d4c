"""Configuration of the Phase 0 flows (thesis chapter 4) and of the learned correction
(:class:`~phonestereo.flows.corrector.Corrector` applies it).

One :class:`FlowConfig` drives the learning and the application phase alike, so that what was
learned is applied under the same conventions. Every chapter-3 fix has a switch (the ablation
table of the bench switches them off one at a time).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

from phonestereo.errors import InputError
from phonestereo.flows.roi_disparity import RoiConfig
from phonestereo.learning.extent import FOCAL_REL_SIGMA
from phonestereo.learning.lookup import STRATEGIES

#: Lookup strategies: the smooth field (default, beyond the thesis) and Figure 3-31's.
LOOKUPS = ("field", *STRATEGIES)

#: The fixes that can be switched off, in the order of the ablation table.
FIXES = (
    "heating_gate",
    "focus_calibration",
    "wt_scale",
    "canonical",
    "orientation_buckets",
    "learned_correction",
    "wide_breathing",
    "radial_residual",
)


@dataclass(frozen=True)
class FlowConfig:
    """Switches and parameters of the learning and application flows."""

    #: Heated gate: seconds since the camera started (thesis: ~3 min, §3.1). The default 180 s is
    #: tuned to the simulator presets' heating time constant τ = 70 s: 180 s ≈ 2.6 τ, when 92 % of
    #: the warm-up drift has happened. A phone that heats more slowly needs about 2.6 × its own τ
    #: (set it with ``--config``; docs/flow-config.md).
    warmup_s: float = 180.0
    #: The fixes (all on by default; ``heating_gate`` … ``learned_correction`` here,
    #: ``wide_breathing`` below): the warm-up gate (§3.1).
    heating_gate: bool = True
    #: The refocus-stack focus calibration (Fig. 4-1, §3.5.3). The focus calibration is off by
    #: default: on handheld stacks the same-camera scale between attempts is dominated by the
    #: hand's motion, and on the thesis bench it made the full flow worse on all three sets
    #: measured (median 0.44/0.61/0.74 % without it, 0.51/0.86/0.91 % with it); it is meant for
    #: tripod stacks.
    focus_calibration: bool = False
    #: The W-T scale (§3.5.1).
    wt_scale: bool = True
    #: Canonical rectification (§3.3; off = ``tele-to-wide``).
    canonical: bool = True
    #: Orientation-keyed fixes (§3.4).
    orientation_buckets: bool = True
    #: The learned correction from faces (§3.6).
    learned_correction: bool = True
    #: One of :data:`LOOKUPS`.
    lookup: str = "field"
    #: The learned gate: fewest observations in the capture's bucket.
    min_observations: int = 10
    #: Highest polynomial degree over the sensor the smooth field may choose (0..3).
    field_max_degree: int = 3
    #: Relative σ of the wide's focal length at the working focus, a systematic part of the learned
    #: correction's σ (:mod:`~phonestereo.learning.extent`).
    focal_rel_sigma: float = FOCAL_REL_SIGMA
    #: The extrapolation gate: a depth whose σ/Z exceeds this (the capture lies beyond what was
    #: learned) is gated with the reason instead of answered.
    max_relative_sigma: float = 0.05
    #: When the face captures report the module temperature, learn the disparity offset per °C from
    #: them (:mod:`~phonestereo.learning.heating_term`), refer the learned observations to one
    #: temperature and add the term, with its σ, to every capture that reports one; such captures
    #: then skip the warm-up gate (their drift is corrected, not waited out). Without temperatures,
    #: a significant drift of the learned offsets over the learning captures' time puts the drift
    #: still to come into σ (τ = ``warmup_s`` / 2.6).
    heating_by_temperature: bool = True
    #: A fix (on by default, see ``heating_gate``): the wide's focus breathing between
    #: calibration and use (§3.5, :mod:`~phonestereo.fixes.breathing`; applied when the
    #: calibration gives the wide's physical focal length and its focus distance, else a no-op).
    wide_breathing: bool = True
    #: σ of a reported wide focus position, dioptres: with ``wide_breathing`` a depth scaled by
    #: the focal length at the *reported* focus carries f·σ_D/(1 − f·D) of relative σ
    #: (:func:`~phonestereo.fixes.breathing.focus_sigma_rel`; 0 = trust the report).
    wide_focus_sigma_dioptre: float = 0.3
    #: A fix (on by default, see ``heating_gate``): the residual radial distortion of the rectified
    #: pair (thesis §3.2's non-disparity-axis fix, :mod:`~phonestereo.fixes.radial_residual`),
    #: fitted to each face capture's whole-view matches and, pooled over the learning captures,
    #: taken out of the faces' and the ROI's disparities. On because a factory's even-order lens
    #: model leaves it on every odd lens; together with the face chart's grid as the ruler
    #: (``IpdMode.chart``) the 20 random modules' medians fall by 30 % (p90 ≤ 2.5 % on 20 of
    #: 20). Alone, with the IPD ruler, it uncovers that ruler's bias (random-1015 0.37 →
    #: 0.79 %; docs/module-random.md, sessions 11 and 14).
    radial_residual: bool = True
    #: Keypoints of the face captures' W-T scale fit, which runs over the whole view the tele shares
    #: with the wide (not the faces' box): the scale's lever is the view's height.
    face_wt_keypoints: int = 1500
    #: The ROI measurement's parameters. Its rectification mode and W-T switch are not in it: they
    #: are :attr:`mode` and :attr:`wt_scale` here, passed explicitly.
    roi: RoiConfig = field(default_factory=RoiConfig)

    def __post_init__(self) -> None:
        if self.lookup not in LOOKUPS:
            raise InputError(f"unknown lookup {self.lookup!r}; choose one of {list(LOOKUPS)}")
        if not self.warmup_s >= 0:
            raise InputError(f"warmup_s must be >= 0 seconds, got {self.warmup_s}")
        if not isinstance(self.roi, RoiConfig):
            raise InputError(f"roi must be a RoiConfig, got {type(self.roi).__name__}")
        if int(self.face_wt_keypoints) < 50:
            raise InputError(f"face_wt_keypoints must be >= 50, got {self.face_wt_keypoints}")
        if not 0 <= int(self.field_max_degree) <= 3 or self.min_observations < 0:
            raise InputError("field_max_degree must be 0..3 and min_observations >= 0")

    @property
    def mode(self) -> str:
        """Rectification mode the fixes imply."""
        return "canonical" if self.canonical else "tele-to-wide"

    def without(self, fix: str) -> FlowConfig:
        """A copy with one fix of :data:`FIXES` switched off."""
        return self.toggled(fix) if getattr(self, fix, None) else self

    def toggled(self, fix: str) -> FlowConfig:
        """A copy with one fix of :data:`FIXES` switched the other way (the ablation)."""
        if fix not in FIXES:
            raise InputError(f"unknown fix {fix!r}; choose one of {list(FIXES)}")
        changes: dict[str, Any] = {fix: not getattr(self, fix)}
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Every knob, nested as a ``--config`` file writes them, plus the derived ``mode``
        (recorded in every result JSON)."""
        return {**asdict(self), "mode": self.mode}

    def context_dict(self) -> dict[str, Any]:
        """The knobs that change what is *learned* (every knob but :data:`APPLY_ONLY`): the
        flow-config part of a fix store's context (:mod:`phonestereo.learning.provenance`)."""
        d = asdict(self)
        for k in APPLY_ONLY:
            d.pop(k)
        if not d["radial_residual"]:  # off learns what stores made before the knob learned
            d.pop("radial_residual")
        return d


#: Knobs used only when applying a store: changing them does not invalidate what was learned.
APPLY_ONLY = (
    "learned_correction",
    "lookup",
    "min_observations",
    "field_max_degree",
    "focal_rel_sigma",
    "max_relative_sigma",
    "wide_breathing",
    "wide_focus_sigma_dioptre",
)


__all__ = ["APPLY_ONLY", "FIXES", "LOOKUPS", "FlowConfig"]
