"""The documentation of the :class:`~phonestereo.flows.config.FlowConfig` knobs (the "flow"
section of :data:`phonestereo.flows.config_knobs.KNOBS`): unit, meaning, why the default."""

from __future__ import annotations

#: field → (unit, meaning, why the default).
FLOW_KNOBS: dict[str, tuple[str, str, str]] = {
    "warmup_s": (
        "s",
        "Heated gate: a capture taken sooner than this after the camera "
        "started is not learned or measured (§3.1).",
        "Tuned to the simulator presets' heating τ = 70 s: 180 s ≈ 2.6 τ, when "
        "92 % of the warm-up drift has happened (thesis: ~3 min). Use ≈ 2.6 × "
        "your phone's τ.",
    ),
    "heating_gate": (
        "bool",
        "Apply the heated gate (§3.1).",
        "On: cold captures carry the warm-up drift into the learned field.",
    ),
    "focus_calibration": (
        "bool",
        "Correct each refocus stack's focus breathing from its attempts (Fig. 4-1, §3.5.3).",
        "Off: on handheld stacks the hand's motion dominates the "
        "same-camera scale; on the bench it made the flow worse "
        "(median 0.44/0.61/0.74 % → 0.51/0.86/0.91 %). For tripod stacks.",
    ),
    "wt_scale": (
        "bool",
        "Fit and apply the wide-tele scale in the ROI / over the face captures' tele view "
        "(§3.5.1): the focus breathing of this capture.",
        "On: without it each capture's breathing is an error of its own.",
    ),
    "canonical": (
        "bool",
        "Canonical rectification (§3.3); off = tele-to-wide (ablation).",
        "On: the thesis's best mode; the store's pixels live in it.",
    ),
    "orientation_buckets": (
        "bool",
        "Learn and apply a separate correction per orientation (§3.4).",
        "On: gravity sags the module differently per orientation.",
    ),
    "learned_correction": (
        "bool",
        "Apply the correction learned from faces (§3.6).",
        "On: it is the point of the learning phase.",
    ),
    "lookup": (
        "name",
        "How the learned correction is looked up: 'field' (smooth "
        "polynomial over the sensor) or Figure 3-31's nearest/mean/max/min/centre.",
        "'field': lowest error on the bench, uses every observation.",
    ),
    "min_observations": (
        "count",
        "Learned gate: fewest observations in the capture's "
        "orientation bucket to apply a correction.",
        "10: below that the field's fit is not trusted.",
    ),
    "field_max_degree": (
        "0..3",
        "Highest polynomial degree over the sensor the smooth "
        "field may choose (it picks the lowest that fits).",
        "3: enough for the distortion residue the bench shows.",
    ),
    "focal_rel_sigma": (
        "relative",
        "σ of the common scale a store cannot see in its own scatter: a systematic "
        "(common-mode) part of the learned correction's σ (learning/extent.py).",
        "0.1 %: the IPD ruler through the factory wide model and the landmark detector's IPD "
        "bias. With it the 29 bench sets' mean errors over their ρ have an rms of 1.02 (0.25 % "
        "made it 0.75), with the faces on the pooled radial fit (docs/module-random.md, "
        "session 14); 1.08 with the modules learned warm and ρ averaged over the learning's "
        "distance layers (session 16). A reported wide focus's σ is per capture: "
        "wide_focus_sigma_dioptre.",
    ),
    "max_relative_sigma": (
        "relative",
        "Extrapolation gate: a depth whose σ/Z exceeds this lies beyond what was learned "
        "and is gated with the reason instead of answered.",
        "5 %: an order above the learned flow's error inside its range, so only captures "
        "far outside the learned disparities are gated.",
    ),
    "heating_by_temperature": (
        "bool",
        "When the face captures report the module temperature, learn the "
        "disparity offset per °C from the set's own face captures (capture-level "
        "fit with disparity and sensor position), refer the learned observations "
        "to their median temperature, and add the term with its σ to each capture "
        "that reports a temperature; those captures skip the warm-up gate. "
        "Without temperatures, a significant drift of the learned offsets over "
        "the learning captures' time adds the drift still to come (τ = "
        "warmup_s / 2.6) to σ.",
        "On: drift and temperature follow the same warm-up curve, and the face "
        "captures are taken while the module still warms (random-1006, ×2.36, "
        "6 px drift: the learned correction took the remaining drift as a gain "
        "over disparity, full flow −1.3 % at 0.8 m to −3.4 % at 3.6 m).",
    ),
    "wide_breathing": (
        "bool",
        "Scale each measured depth by the wide's focal length at its working focus (the "
        "measured depth) over the calibrated one, thin lens (§3.5, fixes/breathing.py). Needs "
        "the calibration's conditions.focus_distance_m and wide_focal_length_mm; else a no-op.",
        "On: the learned correction cannot see this scale (the IPD ruler reads in the same "
        "pixels); the random periscopes read +0.3–1.3 % long without it (random-1005, 5.85 mm "
        "wide calibrated at 0.6 m: +1.26 % mean → +0.58 %).",
    ),
    "wide_focus_sigma_dioptre": (
        "D",
        "σ of the wide's reported focus position (the manifest's focus_position). With "
        "wide_breathing on, a depth scaled by the focal length at the reported focus carries "
        "f·σ_D/(1 − f·D) of relative σ (a 5.8 mm wide: 0.17 % at 0.3 D).",
        "0.3 D: a report the thesis found unreliable (§3.5; Camera2's APPROXIMATE focus "
        "calibration promises dioptres, not repeatability), the virtual module's report noise. "
        "Without it the per-capture σ covered the scatter between two captures of one chart "
        "only at rms z 2.1 over the 29 bench sets; with it 0.99 (docs/module-random.md, "
        "session 14). Set it from your phone: the spread of the reported focus over repeated "
        "autofocus on one target.",
    ),
    "radial_residual": (
        "bool",
        "Take the rectified pair's residual radial distortion out of every disparity (thesis "
        "§3.2's non-disparity-axis fix, fixes/radial_residual.py): P(r) about the wide's "
        "principal point (the wide's factory misfit; session 19), fitted to each face "
        "capture's whole-view matches' e and pooled over "
        "the learning captures, corrects the faces and the ROI's matches (before its W-T "
        "scale) alike (session 14: each face on its own capture's fit scattered).",
        "On: the factory's even-order lens model leaves this residual on an odd lens. With the "
        "face chart's grid as the ruler (learn --face-pitch-mm) the 20 random modules' "
        "medians fall by 30 % (0.55 → 0.38 % on average, p90 ≤ 2.5 % on 20 of 20); alone, "
        "with the IPD ruler, it uncovers that ruler's bias (random-1015 0.37 → 0.79 %). "
        "docs/module-random.md, session 11.",
    ),
    "face_wt_keypoints": (
        "count",
        "Keypoints of the face captures' W-T scale fit, which runs over the whole view the "
        "tele shares with the wide (flows/learning.py).",
        "1500: the tele's view is ~3× a verification ROI; the 450 of an ROI left some captures "
        "of a ×3.5 periscope below the 12 matches a fit needs. The cost is the box's remap, "
        "not the keypoints (±10 ms between 450 and 1500).",
    ),
}

__all__ = ["FLOW_KNOBS"]
