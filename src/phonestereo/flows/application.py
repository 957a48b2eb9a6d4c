"""The application phase (thesis §4.1, Fig. 4-2): depth of an ROI with its σ.

Blocks, in order, each named as the thesis names it (§4.1.3) and each recorded in the result:

1. **gates** — heated, fixed focus, orientation known (:mod:`~phonestereo.flows.gates`);
2. **focus fix** — the refocus stack's scale/offset correction when one is given (Fig. 4-1);
3. **features in the ROI matched into the tele → majority disparity → ROI expansion →
   majority again → W-T scale in the ROI** (:func:`~phonestereo.flows.roi_disparity.measure_roi`);
4. **fix disparity** — the learned correction at each ROI point (x, y, d), keyed by the
   orientation bucket, and the learned gate (enough observations);
5. **majority depth** — Z over the ROI grid (the rectified ray of each ROI pixel at its
   corrected disparity, depth along the wide's optical axis), the median, and σ from the
   matching bound (the plane fit over Cramér–Rao-weighted matches), the W-T scale's σ and the
   correction's σ with its systematic and extrapolation parts
   (:mod:`~phonestereo.learning.extent`); a depth whose σ/Z exceeds
   ``FlowConfig.max_relative_sigma`` is gated ``extrapolation`` with the reason;
6. **wide breathing** — the depth scaled by the wide's focal length at its working focus (the
   reported focus position, else the measured depth) over the calibrated one (§3.5,
   :mod:`~phonestereo.fixes.breathing`), when the calibration gives the wide's physical focal
   length and focus distance: the learned correction cannot see this scale (the IPD ruler
   reads in the same pixels).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from phonestereo.fixes.breathing import correct_depth, focus_sigma_rel
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.corrector import Corrector
from phonestereo.flows.focus_stack import FocusCorrection
from phonestereo.flows.gates import Gate, capture_gates, first_failed, learned_gate
from phonestereo.flows.roi_config import centred_rows, reaching
from phonestereo.flows.roi_disparity import measure_roi, reference_rectification
from phonestereo.io import Calibration, CaptureEntry
from phonestereo.learning.learn import capture_orientation
from phonestereo.rectification import Rectification


@dataclass(frozen=True)
class ApplicationInputs:
    """One capture to measure."""

    calibration: Calibration
    #: Its manifest entry (time, gravity, focus mode, ROI).
    entry: CaptureEntry
    #: ``image_wide``, ``image_tele``: ndarray. Decoded images.
    image_wide: Any
    #: See ``image_wide`` above.
    image_tele: Any
    #: The learned correction (None: no store → the learned gate fails unless the learned correction
    #: is switched off).
    corrector: Corrector | None = None
    #: (x, y, w, h) or None. Raw wide pixels; default the entry's ROI.
    roi: tuple[int, int, int, int] | None = None
    #: The refocus stack's correction for this attempt (Fig. 4-1).
    focus: FocusCorrection | None = None
    #: The calibration's reference rectification, when the caller keeps it across captures (default:
    #: built here, ~15 ms).
    reference: Rectification | None = None


@dataclass(frozen=True)
class DepthResult:
    """The application phase's answer for one capture.

    ``ok`` False: ``gate`` names the gate (or ``"measure"`` / ``"correction"``) and ``reason``
    says why; ``depth_m`` is then NaN — never a silent number.
    """

    capture_id: str
    ok: bool
    depth_m: float
    sigma_m: float
    gate: str = ""
    reason: str = ""
    disparity_px: float = float("nan")
    disparity_fixed_px: float = float("nan")
    correction_px: float = float("nan")
    depth_uncorrected_m: float = float("nan")
    stages: dict[str, Any] = field(default_factory=dict)
    gates: tuple[Gate, ...] = ()
    seconds: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""

        def num(v: float) -> float | None:
            return None if not np.isfinite(v) else round(float(v), 6)

        return {
            "capture_id": self.capture_id, "ok": self.ok, "depth_m": num(self.depth_m),
            "sigma_m": num(self.sigma_m), "gate": self.gate, "reason": self.reason,
            "disparity_px": num(self.disparity_px),
            "disparity_fixed_px": num(self.disparity_fixed_px),
            "correction_px": num(self.correction_px),
            "depth_uncorrected_m": num(self.depth_uncorrected_m),
            "gates": [g.to_dict() for g in self.gates], "stages": self.stages,
            "seconds": round(self.seconds, 4),
        }


def _gated(cid: str, gate: str, reason: str, gates: list[Gate], **kw: Any) -> DepthResult:
    nan = float("nan")
    return DepthResult(cid, False, nan, nan, gate, reason, gates=tuple(gates), **kw)


def run(config: FlowConfig, inputs: ApplicationInputs) -> DepthResult:
    """Run the application phase on one capture (Fig. 4-2); see the module docstring."""
    t0 = time.perf_counter()
    entry = inputs.entry
    # A capture whose temperature indexes the learned heating term is corrected, not gated.
    heated = inputs.corrector is not None and config.learned_correction and (
        inputs.corrector.heating_corrected(entry.temperature_c))
    gates = capture_gates(entry, warmup_s=config.warmup_s, heating=config.heating_gate,
                          heating_corrected=heated)
    bad = first_failed(gates)
    if bad is not None:
        return _gated(entry.id, bad.name, bad.reason, gates, seconds=time.perf_counter() - t0)
    orientation = capture_orientation(entry)
    if config.learned_correction:
        n = 0 if inputs.corrector is None else inputs.corrector.count(orientation)
        g = learned_gate(n, config.min_observations, orientation)
        gates.append(g)
        if not g.passed:
            return _gated(entry.id, g.name, g.reason, gates, seconds=time.perf_counter() - t0)
    roi = inputs.roi or entry.roi
    if roi is None:
        return _gated(entry.id, "roi", "no ROI given (--roi x,y,w,h or the manifest's roi)", gates)
    stages: dict[str, Any] = {}
    rig = inputs.calibration.rig
    if config.focus_calibration and inputs.focus is not None:
        rig = inputs.focus.apply(rig)
        stages["focus_fix"] = inputs.focus.to_dict()
    ref = inputs.reference
    if ref is None or ref.mode != config.mode:
        ref = reference_rectification(inputs.calibration.rig, config.mode)
    box = (int(roi[0]), int(roi[1]), int(roi[2]), int(roi[3]))
    radial = inputs.corrector.radial if inputs.corrector is not None else None
    if radial is not None:  # §3.2, learned (fixes/radial_residual.py)
        stages["radial_residual"] = radial.to_dict()
    roi_cfg, rows = config.roi, 0
    if config.learned_correction and inputs.corrector is not None:
        # A far point reads d = −correction: a positive one takes it beyond the searched
        # −2 px (random-3004: +7.5 px, every chart from 3.2 m gated "beyond infinity").
        roi_cfg = reaching(roi_cfg, inputs.corrector.typical_px(orientation))
        # The rows are searched about the learned row error: random-3056's were off by 12 px,
        # and about e = 0 its far chessboards settled on an alias 30–37 px off at e ≈ 3.
        centre = ref.points_wide(np.array([[box[0] + 0.5 * box[2], box[1] + 0.5 * box[3]]]))[0]
        rows = centred_rows(roi_cfg, inputs.corrector.row_error_px(orientation, centre))
    m = measure_roi(
        rig,
        inputs.image_wide,
        inputs.image_tele,
        box,
        roi_cfg,
        ref,
        mode=config.mode,
        wt_scale=config.wt_scale,
        radial=radial,
        row_offset_px=rows,
    )
    stages["measure"] = {"counts": m.counts, "ok": m.ok, "reason": m.reason}
    if m.wt is not None:
        stages["wt_scale"] = m.wt.to_dict()
    if not m.ok or m.plane is None:
        return _gated(
            entry.id, "measure", m.reason, gates, stages=stages, seconds=time.perf_counter() - t0
        )
    grid = m.roi_grid
    d_grid, sd_grid = m.plane.predict(grid)
    stages["majority_disparity_px"] = round(m.majority_px, 5)
    z_raw = ref.backproject(grid, d_grid)[:, 2]
    corr_v = np.zeros(len(d_grid))
    corr_s = np.zeros(len(d_grid))
    parts: dict[str, Any] = {}
    if config.learned_correction and inputs.corrector is not None:
        c, parts = inputs.corrector.correct_parts(
            np.column_stack([grid, d_grid]), orientation, entry.temperature_c, entry.time_s
        )
        if not c.ok or not np.isfinite(c.value_px).all():
            return _gated(entry.id, "correction", c.reason or "correction unavailable", gates,
                          stages=stages, seconds=time.perf_counter() - t0)
        corr_v, corr_s = c.value_px, c.sigma_px
        stages["correction"] = {
            "strategy": c.strategy, "median_px": round(float(np.median(corr_v)), 5),
            "sigma_px": round(float(np.median(corr_s)), 5), "n_used": int(np.median(c.n_used)),
        }
        if heated and entry.temperature_c is not None:  # (heated implies a temperature)
            heat = inputs.corrector.heating
            stages["correction"]["heating"] = {
                **heat.to_dict(),
                "offset_px": round(float(heat.offset_px(float(entry.temperature_c))[0]), 5),
            }
    d_fix = d_grid + corr_v
    z = ref.backproject(grid, d_fix)[:, 2]
    k = int(np.argsort(z)[len(z) // 2])  # the median grid point
    depth = float(np.median(z))
    sigma_wt = 0.0
    if m.wt is not None and m.wt.ok:
        x_t = grid[k, 0] - d_grid[k]
        sigma_wt = float(m.wt.sigma_scale * abs(x_t - m.wt.center_px[0]))
    sigma_d = float(np.sqrt(sd_grid[k] ** 2 + sigma_wt**2 + corr_s[k] ** 2))
    sigma_z = depth * sigma_d / max(float(d_fix[k]), 1e-9)
    sigma_focus = 0.0  # the wide's reported focus, as disparity
    cond = inputs.calibration.conditions
    if config.wide_breathing and cond.wide_focal_length_mm and cond.focus_distance_m:
        scale = correct_depth(depth, cond.wide_focal_length_mm, cond.focus_distance_m,
                              entry.focus_position) / depth
        depth, sigma_z, z_raw = depth * scale, sigma_z * scale, z_raw * scale
        if entry.focus_position is not None and entry.focus_position >= 0:  # the report's σ
            rel = focus_sigma_rel(cond.wide_focal_length_mm, entry.focus_position,
                                  config.wide_focus_sigma_dioptre)
            sigma_focus = rel * float(d_fix[k])
            sigma_d = float(np.hypot(sigma_d, sigma_focus))
            sigma_z = float(np.hypot(sigma_z, rel * depth))
        stages["wide_breathing"] = {
            "scale": round(scale, 6), "focal_length_mm": cond.wide_focal_length_mm,
            "calibration_focus_m": cond.focus_distance_m,
            "focus": "reported" if entry.focus_position is not None else "measured depth",
        }
    stages["sigma_px"] = {
        "matching": round(float(sd_grid[k]), 5), "wt_scale": round(sigma_wt, 5),
        "correction": round(float(corr_s[k]), 5), "wide_focus": round(sigma_focus, 5),
        "total": round(sigma_d, 5),
        **{f"correction_{n}": round(float(v[k]), 5) for n, v in parts.items()},
    }
    if not sigma_z <= config.max_relative_sigma * depth:
        ext = inputs.corrector.extents.get(inputs.corrector.bucket(orientation)) if (
            inputs.corrector is not None) else None
        learned = "" if ext is None else (
            f"; learned disparities {ext.d_lo_px:.1f}–{ext.d_hi_px:.1f} px")
        return _gated(
            entry.id, "extrapolation",
            f"depth {depth:.3f} m would carry "
            + (f"σ {sigma_z:.3f} m" if np.isfinite(sigma_z) else "an unbounded σ")
            + f" (> {config.max_relative_sigma:.0%} of it): the capture lies beyond what was "
            f"learned (disparity {float(d_grid[k]):.1f} px"
            f"{learned}); learn from faces at this distance and sensor position",
            gates, stages=stages, seconds=time.perf_counter() - t0,
        )
    return DepthResult(
        entry.id, True, depth, sigma_z, "", "",
        float(np.median(d_grid)), float(np.median(d_fix)), float(np.median(corr_v)),
        float(np.median(z_raw)), stages, tuple(gates), time.perf_counter() - t0,
    )


__all__ = ["ApplicationInputs", "DepthResult", "run"]
