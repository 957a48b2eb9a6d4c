"""Translation analysis (thesis §3.3, Figure 3-10): e of two charts at two depths, before/after.

A tripod scene with two verification charts at different depths (a small ``near`` chart beside
the line of sight to a large ``far`` one, as ``phonestereo simulate dual-depth`` makes). Per
capture both charts are detected in both images (the near chart with its own layout first,
then masked out so the far chart's detection cannot latch onto it), corners matched by id and
rectified in every mode. If e did not depend on depth, the two charts' mean e would agree; the
rotation-only modes (``tele-to-wide``, ``undistort-both`` — "before") leave the non-baseline
translation t_y and the Z translation t_z in, so they disagree by ≈ f·t_y·(1/Z_near − 1/Z_far);
``canonical`` ("after", the fix of :mod:`phonestereo.fixes.translation`) puts the whole
baseline on x. Also reported: the translation measured from e (t_y/B, t_z/B,
:func:`~phonestereo.fixes.translation.fit_translation`) against the calibration's, and
canonical followed by the residual radial fix of §3.2 fitted on both charts.

When the set has a ``ground_truth.json`` (simulated), the true corners are rectified the same
way (what a perfect detector would give) and the true translation is reported.

Outputs in ``out_dir``: ``translation.json``, ``translation_dual_depth.png`` (d and e of every
corner over the image, before and after: Figure 3-10) and ``translation_e_by_depth.png``
(mean e per chart per mode).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import cv2
import numpy as np
from matplotlib.figure import Figure

from phonestereo.charts.verification import VerificationChart
from phonestereo.evaluation.analyses import AnalysisOutput, Progress
from phonestereo.evaluation.analyses._common import (
    VerificationSet,
    image_axes,
    measure_each,
    seconds_since,
    verification_analysis,
    write_output,
)
from phonestereo.evaluation.analyses._common import save_figure as _save
from phonestereo.evaluation.chart_ruler import corner_keys, match_detections, true_corners
from phonestereo.features.verification import ChartDetection, detect_verification_chart
from phonestereo.fixes.distortion import RadialResidualFix, principal_point_rect
from phonestereo.fixes.translation import (
    TranslationComponents,
    depth_agreement,
    fit_translation,
    predicted_nondisparity_px,
)
from phonestereo.geometry import Rig
from phonestereo.io import CaptureEntry, CaptureSet, read_gray
from phonestereo.rectification import MODES, Rectification

F64 = np.ndarray
#: The near chart of the ``dual-depth`` scenario (10 × 8 squares of 18 mm); far = the default.
NEAR_CHART = VerificationChart(squares=(10, 8), square_m=0.018)
CHARTS = ("near", "far")
BEFORE, AFTER = "undistort-both", "canonical"
FIXED = "canonical+radial"
MIN_CORNERS = 8  # fewest corners of a chart seen in both images
_MASK_GROW = 1.35  # the near chart's corner hull grown by this factor covers its white margin


def _mask_out(img: np.ndarray, det: ChartDetection) -> np.ndarray:
    """A copy of ``img`` with the detected chart (hull of its corners, grown) painted grey."""
    out = img.copy()
    hull = cv2.convexHull(det.points.astype(np.float32)).reshape(-1, 2)
    c = hull.mean(axis=0)
    poly = np.round((hull - c) * _MASK_GROW + c).astype(np.int32)
    cv2.fillConvexPoly(out, poly, float(np.median(img)))
    return out


def detect_two_charts(
    img: np.ndarray, near: VerificationChart = NEAR_CHART, far: VerificationChart | None = None
) -> tuple[ChartDetection, ChartDetection]:
    """Detect the near chart, mask it out, detect the far chart: (near, far) detections."""
    dn = detect_verification_chart(img, near)
    df = detect_verification_chart(_mask_out(img, dn) if dn.found else img, far)
    return dn, df


def _measure(cs: CaptureSet, cap: CaptureEntry) -> dict[str, Any]:
    """Matched raw corners of both charts in one capture, or a reason."""
    dets = [detect_two_charts(read_gray(p)) for p in cs.image_paths(cap.id)]
    out: dict[str, Any] = {"id": cap.id, "found": True, "reason": ""}
    for k, name in enumerate(CHARTS):
        dw, dt = dets[0][k], dets[1][k]
        bad = [f"{name} chart, {r}: {x.reason}" for r, x in (("wide", dw), ("tele", dt))]
        bad = [b for b, x in zip(bad, (dw, dt), strict=True) if not x.found]
        ids, qw, qt = match_detections(dw, dt) if not bad else (np.zeros((0, 2)), None, None)
        if not bad and len(ids) < MIN_CORNERS:
            bad = [f"{name} chart: only {len(ids)} corners seen in both images"]
        if bad:
            return {"id": cap.id, "found": False, "reason": bad[0]}
        out[name] = (ids, qw, qt)
    return out


def _truth_pairs(root: Path, m: dict[str, Any]) -> dict[str, Any] | None:
    pairs = {}
    for k, name in enumerate(CHARTS):
        kp = true_corners(root, m["id"], k)
        if kp is None:
            return None
        sel = np.isin(corner_keys(kp.ids), corner_keys(m[name][0]))
        pairs[name] = (kp.ids[sel], kp.wide_px[sel], kp.tele_px[sel])
    return pairs


def _per_mode(rect: Rectification, ms: list[dict[str, Any]]) -> dict[str, Any]:
    """Pooled d, e, rectified wide points and chart labels of every measured capture."""
    d, e, q, lab = [], [], [], []
    for m in ms:
        for name in CHARTS:
            _, qw, qt = m[name]
            dd, ee = rect.disparity(qw, qt)
            d.append(dd)
            e.append(ee)
            q.append(rect.points_wide(qw))
            lab += [name] * len(dd)
    return {"d": np.concatenate(d), "e": np.concatenate(e), "q": np.concatenate(q), "lab": lab}


def _mode_row(rect: Rectification, p: dict[str, Any]) -> dict[str, Any]:
    ag = depth_agreement(p["e"], p["lab"])
    v = p["q"][:, 1] - rect.wide_rect.cy
    tf = fit_translation(v, p["d"], p["e"], rect.f_px)
    labs = np.asarray(p["lab"])
    depth = {n: float(np.nanmedian(rect.depth(p["d"][labs == n]))) for n in CHARTS}
    return {"agreement": ag.to_dict(), "spread_px": ag.spread_px,
            "translation_from_e": tf.to_dict(), "median_depth_m": depth}


@verification_analysis(
    "translation",
    ">= 1 'verification' capture showing two verification charts at two depths (a "
    "10x8-square 18 mm chart near, the standard chart far; tripod), e.g. "
    "`phonestereo simulate dual-depth`",
)
def analyze_translation(
    opened: VerificationSet, *, progress: Progress | None = None
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Measure the depth dependence of e per rectification mode; (JSON table, plot data)."""
    t0, cs, rig, caps = opened
    ms = measure_each(caps, lambda c: _measure(cs, c), progress)
    good = [m for m in ms if m["found"]]
    base: dict[str, Any] = {"analysis": "translation", "capture_set": str(cs.root),
                            "captures_total": len(ms), "captures_used": len(good)}
    if not good:
        why = "; ".join(f"{m['id']}: {m['reason']}" for m in ms)[:600]
        return {**base, "ok": False, "reason": f"two charts found in 0 captures: {why}"}, {}
    comps = TranslationComponents.from_rig(rig)
    rects = {mode: Rectification.from_rig(rig, mode) for mode in MODES}
    pooled = {mode: _per_mode(rects[mode], good) for mode in MODES}
    modes = {mode: _mode_row(rects[mode], pooled[mode]) for mode in MODES}
    pc, rc = pooled[AFTER], rects[AFTER]
    fix = RadialResidualFix.fit(pc["q"], pc["e"], principal_point_rect(rc))
    _, e_fixed = fix.correct(pc["q"], pc["d"], pc["e"])
    ag_fixed = depth_agreement(e_fixed, pc["lab"])
    modes[FIXED] = {"agreement": ag_fixed.to_dict(), "spread_px": ag_fixed.spread_px,
                    "radial_fix": fix.to_dict()}
    pb = pooled[BEFORE]  # e the calibration's t_y, t_z predict at each corner's depth and row
    e_pred = predicted_nondisparity_px(
        comps, rects[BEFORE].f_px, rc.depth(pc["d"]), pb["q"][:, 1] - rects[BEFORE].wide_rect.cy
    )
    predicted = depth_agreement(e_pred, pb["lab"]).spread_px
    table: dict[str, Any] = {
        **base, "ok": True, "reason": "",
        "corners": {n: int(sum(len(m[n][0]) for m in good)) for n in CHARTS},
        "calibration_translation": comps.to_dict(),
        "predicted_before_spread_px": round(abs(float(predicted)), 5),
        "spread_before_px": modes[BEFORE]["spread_px"],
        "spread_after_px": modes[AFTER]["spread_px"],
        "modes": modes,
    }
    truth = _truth(cs.root, good, rects)
    if truth is not None:
        table["truth"] = truth
    table["seconds"] = seconds_since(t0)
    return table, {"pooled": pooled, "rects": rects}


def _truth(root: Path, good: list[dict[str, Any]], rects: dict[str, Any]) -> Any:
    """The same measures from the true corner pixels, and the true translation (sim only)."""
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    if not (root / GROUND_TRUTH_NAME).is_file():
        return None
    true_ms = [{"id": m["id"], **(_truth_pairs(root, m) or {})} for m in good]
    out: dict[str, Any] = {"modes": {}}
    for mode, rect in rects.items():
        p = _per_mode(rect, true_ms)
        row = _mode_row(rect, p)
        out["modes"][mode] = {"spread_px": row["spread_px"], "agreement": row["agreement"]}
    rig_true = Rig.from_dict(load_ground_truth(root / GROUND_TRUTH_NAME).calibration_true)
    out["translation"] = TranslationComponents.from_rig(rig_true).to_dict()
    return out


# --- figures -----------------------------------------------------------------------------------


def write_figures(table: dict[str, Any], data: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write the PNG figures into ``out_dir``; returns their paths."""
    pooled = data["pooled"]
    fig = Figure(figsize=(12, 9), constrained_layout=True)
    axes = fig.subplots(2, 2)
    for row, mode in enumerate((BEFORE, AFTER)):
        p = pooled[mode]
        for col, (key, name) in enumerate((("d", "disparity d"), ("e", "non-disparity error e"))):
            ax = axes[row, col]
            vals = p[key]
            if key == "e":
                lim = float(np.nanmax(np.abs(vals - np.nanmedian(vals)))) or 1e-3
                mid = float(np.nanmedian(vals))
                sc = ax.scatter(p["q"][:, 0], p["q"][:, 1], c=vals, s=6, cmap="coolwarm",
                                vmin=mid - lim, vmax=mid + lim)
            else:
                sc = ax.scatter(p["q"][:, 0], p["q"][:, 1], c=vals, s=6, cmap="viridis")
            fig.colorbar(sc, ax=ax, label=f"{name} [px]")
            spread = table["modes"][mode]["spread_px"]
            tag = "before (rotation only)" if row == 0 else "after (canonical, §3.3 fix)"
            ax.set_title(f"{name}, {mode}: {tag}\nmean e near − far = {spread:.3f} px", fontsize=9)
            image_axes(ax)
    fig.suptitle("Dual-depth scene: d and e of every corner, near and far chart (thesis Fig. 3-10)")
    files = [_save(fig, out_dir / "translation_dual_depth.png")]
    fig = Figure(figsize=(8, 4.5), constrained_layout=True)
    ax = fig.subplots()
    names = [*MODES, FIXED]
    x = np.arange(len(names))
    for k, chart in enumerate(CHARTS):
        vals = [table["modes"][n]["agreement"]["groups"][chart]["mean_e_px"] for n in names]
        ax.bar(x + (k - 0.5) * 0.38, vals, 0.38, label=f"{chart} chart")
    ax.set_xticks(x, [f"{n}\nΔ = {table['modes'][n]['spread_px']:.3f} px" for n in names])
    ax.set_ylabel("mean non-disparity error e [px]")
    ax.set_title("Mean e per chart and rectification mode (equal when e is depth independent)")
    ax.axhline(0.0, color="0.3", lw=0.8)
    ax.legend()
    ax.grid(alpha=0.3, axis="y")
    files.append(_save(fig, out_dir / "translation_e_by_depth.png"))
    return files


def _summary(tb: dict[str, Any]) -> tuple[str, ...]:
    if not tb["ok"]:
        return (f"translation: no result: {tb['reason']}",)
    c = tb["calibration_translation"]
    lines = [
        f"translation: {tb['captures_used']}/{tb['captures_total']} captures, "
        f"{tb['corners']['near']} near + {tb['corners']['far']} far corners ({tb['seconds']} s)",
        f"calibration: B = {1e3 * c['baseline_m']:.3f} mm, t_y = {1e3 * c['non_baseline_m']:+.3f}"
        f" mm, t_z = {1e3 * c['z_m']:+.3f} mm (canonical turns by {c['tilt_deg']:.2f}°)",
    ]
    for mode, row in tb["modes"].items():
        lines.append(f"{mode}: mean e near − far = {row['spread_px']:.4f} px")
    tf = tb["modes"][BEFORE]["translation_from_e"]
    if tf["ok"]:
        b = c["baseline_m"] * 1e3
        lines.append(
            f"measured from e ({BEFORE}): t_y = {tf['ty_over_b'] * b:+.3f} mm, "
            f"t_z = {tf['tz_over_b'] * b:+.3f} mm"
        )
    return tuple(lines)


def run(capture_set: Path, out_dir: Path, progress: Progress | None = None) -> AnalysisOutput:
    """Registry entry: analyse, write ``translation.json`` and the figures into ``out_dir``."""
    tb, data = analyze_translation(capture_set, progress=progress)
    files = write_figures(tb, data, out_dir) if tb["ok"] else []
    return write_output("translation", tb, files, _summary(tb), out_dir)
