"""What a module can see: scenario distances and focus planned per module (issue #18 item 2).

The thesis bench puts the face chart at 1–3 m and the verification chart at 0.8–4 m with manual
focus at 1.5 m, which fits a ×2–×3 tele. A longer tele sees less: a ×5 tele's field at 1 m is
a fifth of the wide's, so a face does not fit in it and the verification chart's circle pairs
(the W-T scale) fall outside it. :func:`fit_distances` keeps a scenario's distances where they
already fit and otherwise re-spaces them over the range that fits; :func:`fit_focus` keeps the
scenario's manual focus when the tele's blur stays within the thesis module's and otherwise
focuses each stack on its chart (the user taps the chart; the thesis bench then focuses its
face stacks on theirs too, one focus regime for learning and application). Each change, and what
the module cannot cover, is a note in the plan (``Plan.notes``, ``ground_truth.json``,
``simulate``).

The limits, from the module alone:

- **faces, near**: one whole face cell of the chart fits in the tele's field
  (cell / (2·tan half-field), rows and columns);
- **faces, far**: the wide still resolves a face, pupil distance ≥ :data:`MIN_WIDE_IPD_PX`
  pixels (the thesis bench's faces at 3 m are 31.5 px on ``folded-x3``);
- **verification, near**: the chart's circle pairs (the W-T scale; within the central 8 × 6
  squares) with a :data:`CIRCLE_MARGIN` margin, off the tele's axis by half the baseline, fit
  in its field;
- **verification, far**: the ROI (with the same margin) lies on the chart in the wide;
- **focus**: the tele's blur disc over the planned distances stays ≤ :data:`BLUR_BUDGET_PX`
  (``folded-x3``'s tele, focused at 1.5 m, blurs 11.9 px at 0.8 m).

Examples
--------
>>> from phonestereo.sim.module import load_module
>>> cov = module_coverage(load_module("periscope-x5"))
>>> [round(v, 2) for v in cov.face_range_m], [round(v, 2) for v in cov.verification_range_m]
([1.63, 3.15], [0.87, 6.52])
>>> fit_distances((1.0, 2.0, 3.0), cov.face_range_m)
(1.65, 2.325, 3.0)
>>> fit_distances((1.0, 2.0, 3.0), module_coverage(load_module("folded-x3")).face_range_m)
(1.0, 2.0, 3.0)
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from phonestereo.charts.faces import FaceChart
from phonestereo.charts.verification import VerificationChart
from phonestereo.sim import effects as fx
from phonestereo.sim.module import ModuleSpec
from phonestereo.sim.optics import coc_diameter_m

#: Smallest pupil distance in the wide for a usable face (folded-x3 at 3 m: 31.5 px).
MIN_WIDE_IPD_PX = 30.0
#: Margin on the circle pairs (tele) and the ROI (wide) for hand shake and tilt.
CIRCLE_MARGIN = 1.15
#: Largest tele blur-disc diameter over a scenario's distances with one manual focus, pixels.
BLUR_BUDGET_PX = 13.0
#: Distances are rounded to this step (metres) when re-spaced.
STEP_M = 0.05
#: "Heated": at most this fraction of the warm-up drift is still to come at a scenario's heated
#: start. The presets (τ = 70 s) start at 300 s with e^(−300/70) = 1.4 % to come; a module that
#: warms with τ = 118 s would still have 7.9 % to come at 300 s, which the faces, taken near to
#: far, learn as a gain (docs/module-random.md, sessions 13 and 15).
HEATED_DRIFT_LEFT = 0.015


@dataclass(frozen=True)
class Coverage:
    """Where one module sees the charts: distance ranges (near, far) in metres."""

    tele_half_field_rad: tuple[float, float]
    face_range_m: tuple[float, float]
    verification_range_m: tuple[float, float]


def module_coverage(
    module: ModuleSpec, roi_px: tuple[int, int] = (200, 150), ipd_m: float = 0.063
) -> Coverage:
    """The face and verification distance ranges of a module (module docstring)."""
    tele, wide = module.tele, module.wide
    half = tuple(float(np.arctan(n / 2 / tele.focal_px_infinity)) for n in tele.size)
    hx, hy = (float(np.tan(a)) for a in half)
    cell = FaceChart().cell_m
    face_near = cell / (2 * min(hx, hy))
    face_far = wide.focal_px_infinity * ipd_m / MIN_WIDE_IPD_PX
    chart = VerificationChart()
    uv = np.concatenate([pair.centers_uv for pair in chart.circle_pairs])
    radius = max(pair.radius_m for pair in chart.circle_pairs)
    circles = (np.abs(uv - np.array(chart.size_m) / 2).max(axis=0) + radius) * CIRCLE_MARGIN
    b = np.abs(fx.tele_center_m(module)[:2]) / 2
    ver_near = float(max((circles[0] + b[0]) / hx, (circles[1] + b[1]) / hy))
    size = np.array(chart.size_m)
    ver_far = float(np.min(size * wide.focal_px_infinity / (CIRCLE_MARGIN * np.array(roi_px))))
    return Coverage((half[0], half[1]), (face_near, face_far), (ver_near, ver_far))


def fit_distances(distances: tuple[float, ...], range_m: tuple[float, float]) -> tuple[float, ...]:
    """The distances unchanged if all lie in ``range_m``, else as many re-spaced over the part
    of their span inside it (rounded up/down to :data:`STEP_M`; one distance if it is empty)."""
    lo, hi = range_m
    if all(lo <= d <= hi for d in distances):
        return tuple(distances)
    a = np.ceil(max(min(distances), lo) / STEP_M - 1e-9) * STEP_M
    b = np.floor(min(max(distances), hi) / STEP_M + 1e-9) * STEP_M
    if b < a:
        return (round(float(a), 3),)
    new = np.round(np.linspace(a, b, len(distances)), 3)
    return tuple(dict.fromkeys(float(v) for v in new))


def tele_blur_px(module: ModuleSpec, focus_m: float, depth_m: object) -> np.ndarray:
    """The tele's blur-disc diameter (pixels) at ``depth_m`` when focused at ``focus_m``."""
    t = module.tele
    coc = coc_diameter_m(t.focal_length_m, t.f_number, focus_m, np.asarray(depth_m, float))
    return np.asarray(coc, dtype=np.float64) / t.pixel_pitch_m


def fit_focus(
    module: ModuleSpec, distances: tuple[float, ...], focus_m: float
) -> tuple[float, bool]:
    """One manual focus for ``distances``, or per-stack focus: ``(focus_m, per_distance)``.

    The scenario's ``focus_m`` is kept when the tele's blur disc stays within
    :data:`BLUR_BUDGET_PX` at every distance; else the dioptric middle of the distances (the
    focus with the least worst blur) when it does; else ``per_distance`` is True: each stack is
    focused on its chart (the user taps the chart).
    """
    if np.max(tele_blur_px(module, focus_m, distances)) <= BLUR_BUDGET_PX:
        return focus_m, False
    middle = round(2.0 / (1.0 / min(distances) + 1.0 / max(distances)), 3)
    if np.max(tele_blur_px(module, middle, distances)) <= BLUR_BUDGET_PX:
        return middle, False
    return focus_m, True


def _span(d: tuple[float, ...]) -> str:
    return f"{min(d):g}-{max(d):g} m" if len(d) > 1 else f"{d[0]:g} m"


def plan_notes(
    what: str,
    module: ModuleSpec,
    asked: tuple[float, ...],
    planned: tuple[float, ...],
    range_m: tuple[float, float],
    focus_m: float,
    per_distance: bool,
    asked_focus_m: float,
) -> list[str]:
    """Notes for one chart kind: what was re-planned and what the module cannot cover."""
    notes, (lo, hi) = [], range_m
    if planned != tuple(asked):
        notes.append(f"{what} planned at {_span(planned)} instead of {_span(asked)}: "
                     f"{module.name} sees it from {lo:.2f} m to {hi:.2f} m")
    if lo > hi:
        notes.append(f"cannot cover {what}: it needs >= {lo:.2f} m for the tele and <= "
                     f"{hi:.2f} m for the wide; planned at {_span(planned)} anyway")
    else:
        if min(asked) < lo:
            notes.append(f"cannot cover {what} nearer than {lo:.2f} m (the tele's field)")
        if max(asked) > hi:
            notes.append(f"cannot cover {what} farther than {hi:.2f} m (the wide's resolution)")
    if focus_m != asked_focus_m:
        notes.append(
            f"{what}: manual focus at {focus_m:g} m instead of {asked_focus_m:g} m "
            f"(the tele's blur within {BLUR_BUDGET_PX:g} px)"
        )
    if per_distance:
        worst = float(np.max(tele_blur_px(module, focus_m, planned)))
        notes.append(f"{what}: one manual focus at {focus_m:g} m would blur the tele by up to "
                     f"{worst:.0f} px (> {BLUR_BUDGET_PX:g}); each stack is focused on its "
                     "chart instead")
    return notes


__all__ = [
    "BLUR_BUDGET_PX",
    "CIRCLE_MARGIN",
    "MIN_WIDE_IPD_PX",
    "STEP_M",
    "Coverage",
    "fit_config",
    "fit_distances",
    "fit_focus",
    "module_coverage",
    "plan_notes",
    "tele_blur_px",
]


def heated_start_s(module: ModuleSpec, start_s: float, notes: list[str]) -> float:
    """A scenario's heated start (s) for this module: ``start_s`` or later, when at most
    :data:`HEATED_DRIFT_LEFT` of its warm-up is still to come (τ·ln(1/that), 4.2 τ); a later
    start is a note in ``notes``. A user learns on a warm phone: how long that takes is the
    module's own warm-up (``phonestereo analyze heating`` measures it)."""
    if not module.effects.heating:
        return start_s
    tau = module.heating.tau_s
    heated = float(np.ceil(tau * np.log(1.0 / HEATED_DRIFT_LEFT)))
    if heated <= start_s:
        return start_s
    notes.append(f"heated start {heated:.0f} s, not {start_s:.0f} s: the module warms with "
                 f"τ = {tau:.0f} s ({HEATED_DRIFT_LEFT:.1%} of its drift still to come)")
    return heated


def fit_config(config: Any, module: ModuleSpec, what: str, notes: list[str]) -> Any:
    """A learning or verification config (``distances_m``, ``focus_m``,
    ``focus_per_distance``) fitted to the module: distances (:func:`fit_distances`) and focus
    (:func:`fit_focus`); the notes of :func:`plan_notes` are appended to ``notes``."""
    cov = module_coverage(module, getattr(config, "roi_px", (200, 150)))
    range_m = cov.face_range_m if what == "faces" else cov.verification_range_m
    planned = fit_distances(tuple(config.distances_m), range_m)
    if config.focus_per_distance:  # asked for: no one manual focus to choose
        focus_m, per_distance, chosen = config.focus_m, True, False
    else:
        focus_m, per_distance = fit_focus(module, planned, config.focus_m)
        chosen = per_distance
    notes += plan_notes(what, module, tuple(config.distances_m), planned, range_m, focus_m,
                        chosen, config.focus_m)
    return replace(config, distances_m=planned, focus_m=focus_m, focus_per_distance=per_distance)
