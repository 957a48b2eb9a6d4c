"""Distortion analysis (thesis §3.2, Figures 3-5 to 3-7): residual distortion seen through e.

A flat verification chart on a tripod (``phonestereo simulate refocus``: one chart, several
manual refocus attempts). Per capture the chart corners are matched by id and rectified in every
mode; with a perfect lens model the non-disparity error e would be constant. Reported:

- the spread of e per rectification mode (fix 2: ``undistort-both`` vs ``tele-to-wide``);
- the non-disparity-axis fix (:class:`~phonestereo.fixes.distortion.RadialResidualFix`) per
  capture and pooled: the offset o, the radial polynomial P(r), e before and after (Figure 3-7);
- P(r) of each capture (each refocus attempt / focus group) side by side: distortion changes
  with focus (Figures 3-5, 3-6);
- when the set also has ``calibration`` captures (a plain chessboard, default 9×6 inner corners
  of 20 mm, as ``phonestereo simulate calibration`` makes), the wide camera calibrated with the
  even ``opencv5`` and the odd ``radial-odd`` model and the radial residual of each (fix 3):
  all of it, and its systematic part (the mean in radius bins, which detection noise does not
  reach), in ``distortion_lens_models.png``.

With a ``ground_truth.json`` (simulated) the true corners are rectified the same way and fitted
too (the offset a perfect detector would give), and the calibrated cameras are compared with
the true lens over the image (radial mapping error).

Outputs in ``out_dir``: ``distortion.json``, ``distortion_e_map.png`` (e of every corner over the
image before/after the fix), ``distortion_radial.png`` (Figure 3-7's three panels) and
``distortion_per_capture.png`` (P(r) per capture), and with calibration captures
``distortion_lens_models.png`` (radial residual vs radius per lens model).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from phonestereo.calibration.views import BoardView, chessboard_object_points
from phonestereo.evaluation.analyses import AnalysisOutput, Progress
from phonestereo.evaluation.analyses._common import (
    VerificationSet,
    image_axes,
    label_axes,
    measure_each,
    seconds_since,
    verification_analysis,
    write_output,
)
from phonestereo.evaluation.analyses._common import save_figure as _save
from phonestereo.evaluation.chart_ruler import (
    CaptureMeasurement,
    corner_keys,
    measure_capture,
    true_corners,
)
from phonestereo.features.chessboard import find_chessboard
from phonestereo.fixes.distortion import RadialResidualFix, principal_point_rect, radial_projection
from phonestereo.fixes.lens_model_compare import (
    LensModelFit,
    compare_lens_models,
    radial_mapping_error,
    radial_residual_profile,
    radial_residuals,
)
from phonestereo.geometry import Rig
from phonestereo.io import CaptureSet, read_gray
from phonestereo.rectification import MODES, Rectification

F64 = np.ndarray
MODE = "canonical"  # the fix is fitted after the full rectification (§3.3 before §3.2 fix)
DEGREE = 4
BOARD = (9, 6)  # inner corners (cols, rows) of the calibration chessboard
SQUARE_M = 0.02


def _fit(rect: Rectification, m: CaptureMeasurement) -> tuple[RadialResidualFix, F64]:
    q = rect.points_wide(m.q_wide)
    return RadialResidualFix.fit(q, m.e_px, principal_point_rect(rect), degree=DEGREE), q


def _calibration_compare(cs: CaptureSet) -> dict[str, Any] | None:
    """Even vs odd lens model on the wide images of the ``calibration`` captures, or None."""
    caps = [c for c in cs.captures() if c.kind == "calibration"]
    if not caps:
        return None
    obj = chessboard_object_points(BOARD, SQUARE_M)
    views, size = [], (0, 0)
    for c in caps:  # the calibration's own detector: saddle-refined corners (~0.01 px)
        img = read_gray(cs.image_paths(c.id)[0])
        size = (img.shape[1], img.shape[0])
        det = find_chessboard(img, BOARD)
        if det.found:
            views.append(BoardView(obj[det.ids], det.points, det.ids))
    if len(views) < 3:
        return {"ok": False, "reason": f"a {BOARD[0]}x{BOARD[1]} board found in {len(views)} "
                f"of {len(caps)} calibration captures; >= 3 needed"}
    fits = compare_lens_models(views, size)
    out: dict[str, Any] = {"ok": True, "reason": "", "views": len(views), "models": {}}
    for name, f in fits.items():
        out["models"][name] = {"rms_px": f.rms_px, "radial_rms_px": f.radial_rms_px,
                               "radial_systematic_px": f.radial_systematic_px,
                               "camera": f.camera.to_dict()}
    even, odd = out["models"]["opencv5"], out["models"]["radial-odd"]
    out["radial_rms_ratio_even_over_odd"] = even["radial_rms_px"] / max(odd["radial_rms_px"], 1e-12)
    out["radial_systematic_ratio_even_over_odd"] = even["radial_systematic_px"] / max(
        odd["radial_systematic_px"], 1e-12
    )
    out["_fits"] = fits
    return out


@verification_analysis(
    "distortion",
    ">= 1 'verification' capture of one flat verification chart filling the tele (tripod, "
    "heated), e.g. `phonestereo simulate refocus`; 'calibration' captures (9x6 chessboard) "
    "add the even-vs-odd lens comparison",
)
def analyze_distortion(
    opened: VerificationSet, *, progress: Progress | None = None
) -> tuple[dict[str, Any], dict[str, Any]]:
    """Measure residual distortion through e; (JSON table, plot data)."""
    t0, cs, rig, caps = opened
    rects = {mode: Rectification.from_rig(rig, mode) for mode in MODES}
    rect = rects[MODE]
    n_min = DEGREE + 3
    ms = measure_each(caps, lambda c: measure_capture(cs, c, rect, min_corners=n_min), progress)
    good = [m for m in ms if m.found]
    base = {"analysis": "distortion", "capture_set": str(cs.root), "captures_total": len(ms),
            "captures_used": len(good), "mode": MODE, "degree": DEGREE}
    if not good:
        why = "; ".join(f"{m.id}: {m.reason}" for m in ms)[:600]
        return {**base, "ok": False, "reason": f"chart found in 0 captures: {why}"}, {}
    groups = {c.id: c.focus_group for c in caps}
    rows: list[dict[str, Any]] = []
    per_fix: list[RadialResidualFix] = []
    e_fixed_parts = []
    for m in good:
        fix, qm = _fit(rect, m)
        e_fixed_parts.append(fix.correct(qm, m.d_px, m.e_px)[1])  # the fix of this capture
        spread = {
            mode: float(np.std(r.disparity(m.q_wide, m.q_tele)[1])) for mode, r in rects.items()
        }
        rows.append({"id": m.id, "focus_group": groups[m.id], "n_corners": len(m.ids),
                     "fix": fix.to_dict(), "e_std_by_mode_px": spread})
        per_fix.append(fix)
    q_all = np.concatenate([rect.points_wide(m.q_wide) for m in good])
    e_all = np.concatenate([m.e_px for m in good])
    d_all = np.concatenate([m.d_px for m in good])
    pooled = RadialResidualFix.fit(q_all, e_all, principal_point_rect(rect), degree=DEGREE)
    no_offset = RadialResidualFix.fit(
        q_all, e_all, principal_point_rect(rect), degree=DEGREE, offset=0.0
    )
    _, e_pooled = pooled.correct(q_all, d_all, e_all)
    e_fixed = np.concatenate(e_fixed_parts)
    by_mode = {mode: float(np.mean([r["e_std_by_mode_px"][mode] for r in rows])) for mode in MODES}
    table: dict[str, Any] = {
        **base, "ok": True, "reason": "",
        "e_std_by_mode_px": by_mode,
        "pooled_fix": pooled.to_dict(),
        "pooled_fix_without_offset": no_offset.to_dict(),
        "e_std_before_px": float(np.std(e_all)), "e_std_after_px": float(np.std(e_fixed)),
        "e_std_after_pooled_fix_px": float(np.std(e_pooled)),
        "offset_spread_over_captures_px": float(np.ptp([f.offset_px for f in per_fix])),
        "captures": rows,
    }
    calib = _calibration_compare(cs)
    truth = _truth(cs.root, good, rect, calib)
    fits = None
    if calib is not None:
        fits = calib.pop("_fits", None)
        table["lens_models"] = calib
    if truth is not None:
        table["truth"] = truth
    table["seconds"] = seconds_since(t0)
    data = {"q": q_all, "e": e_all, "e_fixed": e_fixed, "fix": pooled, "fixes": per_fix,
            "labels": [f"{r['id']} ({r['focus_group']})" for r in rows],
            "lens_fits": fits}
    return table, data


def _truth(
    root: Path, good: list[CaptureMeasurement], rect: Rectification, calib: dict[str, Any] | None
) -> Any:
    """The fix fitted on the true corners, and the lens models against the true wide (sim)."""
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    if not (root / GROUND_TRUTH_NAME).is_file():
        return None
    q, e, e_meas = [], [], []
    for m in good:
        kp = true_corners(root, m.id, 0)
        _, it, im = np.intersect1d(corner_keys(kp.ids), corner_keys(m.ids), return_indices=True)
        _, et = rect.disparity(kp.wide_px[it], kp.tele_px[it])
        q.append(rect.points_wide(kp.wide_px[it]))
        e.append(et)
        e_meas.append(m.e_px[im])
    qa, ea, em = np.concatenate(q), np.concatenate(e), np.concatenate(e_meas)
    ok = np.isfinite(ea) & np.isfinite(qa).all(axis=1)
    fix = RadialResidualFix.fit(qa[ok], ea[ok], principal_point_rect(rect), degree=DEGREE)
    out: dict[str, Any] = {
        "fix": fix.to_dict(),
        "e_detection_error_rms_px": float(np.sqrt(np.mean((em[ok] - ea[ok]) ** 2))),
    }
    if calib is not None and calib.get("ok"):
        gt = load_ground_truth(root / GROUND_TRUTH_NAME)
        wide_true = Rig.from_dict(gt.calibration_true).wide
        out["lens_models"] = {}
        for name, f in calib["_fits"].items():  # within the radius the boards covered
            res = f.result
            rmax = float(np.max(np.hypot(*(res.image_points - [f.camera.cx, f.camera.cy]).T)))
            _, dr = radial_mapping_error(wide_true, f.camera, max_radius_px=rmax, remove_scale=True)
            out["lens_models"][name] = {"radial_mapping_rms_px": float(np.sqrt(np.mean(dr**2)))}
        ev, od = (out["lens_models"][k]["radial_mapping_rms_px"] for k in ("opencv5", "radial-odd"))
        out["lens_models"]["ratio_even_over_odd"] = ev / max(od, 1e-12)
    return out


# --- figures -----------------------------------------------------------------------------------


def write_figures(table: dict[str, Any], data: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write the PNG figures into ``out_dir``; returns their paths."""
    fix: RadialResidualFix = data["fix"]
    q, e = data["q"], data["e"]
    files = []
    fig = Figure(figsize=(12, 5.5), constrained_layout=True)
    axes = fig.subplots(1, 2)
    after = (axes[1], data["e_fixed"], "after the e-axis fix (per capture)")
    for ax, vals, tag in ((axes[0], e, "before"), after):
        mid = float(np.median(vals))
        lim = float(np.max(np.abs(vals - mid))) or 1e-3
        sc = ax.scatter(q[:, 0], q[:, 1], c=vals, s=7, cmap="coolwarm", vmin=mid - lim,
                        vmax=mid + lim)
        fig.colorbar(sc, ax=ax, label="non-disparity error e [px]")
        ax.plot(*fix.center_px, "k+", ms=14, label="distortion centre")
        ax.set_title(f"e of every corner, {tag} (std {np.std(vals):.4f} px)")
        image_axes(ax)
        ax.legend(fontsize=8, loc="lower right")
    fig.suptitle(f"Residual distortion over the image ({MODE} rectification, all captures)")
    files.append(_save(fig, out_dir / "distortion_e_map.png"))

    fig = Figure(figsize=(14, 4.5), constrained_layout=True)
    a1, a2, a3 = fig.subplots(1, 3)
    r = np.hypot(*(q - np.asarray(fix.center_px)).T)
    rr = np.linspace(0.0, float(r.max()), 200)
    a1.plot(r, e, ".", ms=2)
    a1.set_title("non-disparity error e vs radius")
    a1.set_ylabel("e [px]")
    a2.plot(r, radial_projection(q, e, fix.center_px), ".", ms=2)
    a2.set_title("radial component e·û_y (no offset)")
    a2.set_ylabel("radial error [px]")
    dr = fix.radial_error(q, e)
    a3.plot(r, dr, ".", ms=2, label="(e − o)/û_y, |û_y| ≥ 0.3")
    a3.plot(rr, fix.radial(rr), "r-", lw=2, label=f"P(r), degree {fix.degree}")
    a3.set_title(f"radial error with optimal offset o = {fix.offset_px:+.4f} px")
    a3.set_ylabel("dr [px]")
    a3.legend(fontsize=8)
    for ax in (a1, a2, a3):
        ax.set_xlabel("radius from the distortion centre [rectified px]")
        ax.grid(alpha=0.3)
    fig.suptitle("The non-disparity-axis fix (thesis Fig. 3-7)")
    files.append(_save(fig, out_dir / "distortion_radial.png"))

    fig = Figure(figsize=(8, 5), constrained_layout=True)
    ax = fig.subplots()
    for f, label in zip(data["fixes"], data["labels"], strict=True):
        rr = np.linspace(0.0, f.radius_scale_px, 100)
        ax.plot(rr, f.radial(rr), lw=1.2, label=f"{label}: o = {f.offset_px:+.3f} px")
    label_axes(ax, "Residual radial distortion P(r) per capture (Figs. 3-5, 3-6)",
               "radius from the distortion centre [rectified px]",
               "residual radial displacement P(r) [px]")
    ax.legend(fontsize=7, ncol=2)
    files.append(_save(fig, out_dir / "distortion_per_capture.png"))
    if data.get("lens_fits"):
        files.append(_lens_model_figure(data["lens_fits"], out_dir))
    return files


def _lens_model_figure(fits: dict[str, LensModelFit], out_dir: Path) -> Path:
    """Radial residual vs radius per lens model, with the binned systematic profile (fix 3)."""
    fig = Figure(figsize=(12, 4.5), constrained_layout=True)
    axes = fig.subplots(1, len(fits), sharey=True, squeeze=False)[0]
    for ax, (name, f) in zip(axes, fits.items(), strict=True):
        r, dr = radial_residuals(f.result)
        rb, db, _ = radial_residual_profile(r, dr)
        ax.plot(r, dr, ".", ms=2, alpha=0.5, label="corner residual (radial part)")
        ax.plot(rb, db, "ro-", lw=2, label="binned mean (systematic)")
        ax.axhline(0.0, color="k", lw=0.8)
        ax.set_title(f"{name}: radial rms {f.radial_rms_px:.4f} px, "
                     f"systematic {f.radial_systematic_px:.4f} px")
        ax.set_xlabel("radius from the principal point [px]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    axes[0].set_ylabel("radial residual (predicted − observed) [px]")
    fig.suptitle("Even (opencv5) vs odd-degree (radial-odd) lens model on the same board views "
                 "(thesis §3.2 fix 3)")
    return _save(fig, out_dir / "distortion_lens_models.png")


def _summary(tb: dict[str, Any]) -> tuple[str, ...]:
    if not tb["ok"]:
        return (f"distortion: no result: {tb['reason']}",)
    p = tb["pooled_fix"]
    lines = [
        f"distortion: {tb['captures_used']}/{tb['captures_total']} captures ({tb['seconds']} s)",
        "std of e by mode: "
        + ", ".join(f"{k} {v:.4f} px" for k, v in tb["e_std_by_mode_px"].items()),
        f"e-axis fix ({MODE}): pooled offset {p['offset_px']:+.4f} px, e std "
        f"{tb['e_std_before_px']:.4f} → {tb['e_std_after_px']:.4f} px (per-capture fit), "
        f"{tb['e_std_after_pooled_fix_px']:.4f} px (one fit for all)",
    ]
    lm = tb.get("lens_models")
    if lm and lm["ok"]:
        m = lm["models"]
        lines.append(
            f"lens models ({lm['views']} views): systematic radial residual opencv5 "
            f"{m['opencv5']['radial_systematic_px']:.4f} px, radial-odd "
            f"{m['radial-odd']['radial_systematic_px']:.4f} px "
            f"(×{lm['radial_systematic_ratio_even_over_odd']:.1f}); with detection noise "
            f"{m['opencv5']['radial_rms_px']:.4f} vs {m['radial-odd']['radial_rms_px']:.4f} px "
            f"(×{lm['radial_rms_ratio_even_over_odd']:.1f})"
        )
    elif lm:
        lines.append(f"lens models: {lm['reason']}")
    return tuple(lines)


def run(capture_set: Path, out_dir: Path, progress: Progress | None = None) -> AnalysisOutput:
    """Registry entry: analyse, write ``distortion.json`` and the figures into ``out_dir``."""
    tb, data = analyze_distortion(capture_set, progress=progress)
    files = write_figures(tb, data, out_dir) if tb["ok"] else []
    return write_output("distortion", tb, files, _summary(tb), out_dir)
