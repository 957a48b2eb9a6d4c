"""W-T scale analysis (thesis §3.5.1–§3.5.2, Figures 3-14 to 3-19, Table 2): wide↔tele scale per
refocus attempt, globally and per depth.

A refocus stack (tripod, static verification chart(s), N attempts) is measured with the chart
ruler; with two charts (``dual-depth``) the first chart found is masked out (its corners' hull,
grown by 20 %) and the image searched again, so each chart is one disparity cluster (near
first). Per attempt: focus-fail detection (sharpness of the ROI against the stack's median,
:mod:`phonestereo.fixes.refocus`); the W-T scale and offset minimising the spread of e
(:func:`~phonestereo.fixes.wt_scale.fit_wt_scale`), over all points and per chart; for one flat
chart also the homography → residual distortion → scale method. Over the stack, per chart:
the chart's disparity range (all corners, all attempts) and the per-corner range, before and
after the scale fix (Figures 3-14 to 3-16), and Table 2: a disparity fix learned at the chart's
centre applied to the rest (fronto-parallel chart: the centre's d is the truth of every
corner), relative depth error before and after.

With ``ground_truth.json`` (simulated) the same fits on the true corner pixels give the true
scales, compared per attempt. Outputs: ``wt_scale.json``, ``wt_scale_corner_range.png``,
``wt_scale_maps.png``, ``wt_scale_scales.png``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from matplotlib.figure import Figure
from scipy.spatial import cKDTree

from phonestereo.evaluation.analyses import AnalysisOutput, Progress
from phonestereo.evaluation.analyses._common import (
    OpenedSet,
    canonical_analysis,
    label_axes,
    map_panel,
    measure_each,
    run_table,
    save_figure,
    seconds_since,
)
from phonestereo.evaluation.analyses.repeatability import focus_check, stack_entries
from phonestereo.evaluation.chart_ruler import corner_keys, match_detections
from phonestereo.features.verification import detect_verification_chart
from phonestereo.fixes.focus import MIN_POINTS
from phonestereo.fixes.refocus import cluster_disparities, flat_scene_scale
from phonestereo.fixes.wt_scale import WTScale, fit_wt_scale
from phonestereo.io import CaptureEntry, CaptureSet, read_gray
from phonestereo.rectification import Rectification

F64 = np.ndarray
MASK_GROW = 1.2  # the masked hull of a found chart, relative to its corners' hull


@dataclass(frozen=True)
class ChartPoints:
    """One chart of one capture: ids (N, 2), rectified wide/tele pixels (N, 2), d and e (N,)."""

    ids: np.ndarray
    q_wide: F64
    q_tele: F64
    d: F64
    e: F64


def _mask(img: np.ndarray, pts: F64) -> np.ndarray:
    hull = cv2.convexHull(pts.astype(np.float32)).reshape(-1, 2)
    grown = (hull - hull.mean(0)) * MASK_GROW + hull.mean(0)
    out = img.copy()
    cv2.fillPoly(out, [np.round(grown).astype(np.int32)], float(np.median(img)))
    return out


def measure_charts(
    cs: CaptureSet, entry: CaptureEntry, rect: Rectification, max_charts: int = 2
) -> tuple[list[ChartPoints], str]:
    """Up to ``max_charts`` charts of a capture (detect, mask, detect again); near first."""
    imgs = [read_gray(p).astype(np.float32) for p in cs.image_paths(entry.id)]
    charts: list[ChartPoints] = []
    reason = ""
    for _ in range(max_charts):
        dw, dt = (detect_verification_chart(im) for im in imgs)
        if not (dw.found and dt.found):
            reason = (dw.reason if not dw.found else dt.reason) if not charts else ""
            break
        ids, qw, qt = match_detections(dw, dt)
        if len(ids) < MIN_POINTS:
            reason = f"only {len(ids)} corners seen in both images" if not charts else ""
            break
        qw_r, qt_r = rect.points_wide(qw), rect.points_tele(qt)
        d, e = rect.disparity(qw_r, qt_r, rectified=True)
        charts.append(ChartPoints(ids, qw_r, qt_r, d, e))
        imgs = [_mask(imgs[0], dw.points), _mask(imgs[1], dt.points)]
    charts.sort(key=lambda ch: -float(np.nanmedian(ch.d)))
    return charts, reason


def _fit(qw: F64, qt: F64, c: F64) -> WTScale:
    f = fit_wt_scale(qw, qt, c)
    return f


def _true_fits(root: Path, cid: str, charts: list[ChartPoints], rect: Rectification) -> Any:
    """True W-T scales (global, per chart) from the true corner pixels, or None (real set)."""
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    if not (root / GROUND_TRUTH_NAME).is_file():
        return None
    cap = load_ground_truth(root / GROUND_TRUTH_NAME).capture(cid)
    c = rect.tele_rect.K[:2, 2]
    kps = [o.keypoints["corners"].arrays() for o in cap.objects]
    tw_all = np.concatenate([rect.points_wide(kp.wide_px) for kp in kps])
    tt_all = np.concatenate([rect.points_tele(kp.tele_px) for kp in kps])
    obj = np.concatenate([np.full(len(kp.ids), j) for j, kp in enumerate(kps)])
    ok = np.isfinite(tw_all).all(1) & np.isfinite(tt_all).all(1)
    tree = cKDTree(tw_all[ok])
    qws, qts, names = [], [], []
    for ch in charts:  # each detected corner ↔ the true corner nearest it (ids may be offset)
        dist, idx = tree.query(ch.q_wide, distance_upper_bound=1.0)
        hit = np.isfinite(dist)
        if hit.sum() < MIN_POINTS:
            continue
        j = idx[hit]
        qws.append(tw_all[ok][j])
        qts.append(tt_all[ok][j])
        names.append(cap.objects[int(np.bincount(obj[ok][j]).argmax())].name)
    if not qws:
        return None
    per = [_fit(a, b, c).scale for a, b in zip(qws, qts, strict=True)]
    glob = _fit(np.concatenate(qws), np.concatenate(qts), c).scale
    return {"scale_global": glob, "scale_per_chart": per, "objects": names,
            "focal_scale_wide": cap.wide.focal_scale,
            "focal_scale_tele": cap.tele.focal_scale}


def _capture_row(
    entry: CaptureEntry, charts: list[ChartPoints], reason: str, c: F64, root: Path,
    rect: Rectification,
) -> dict[str, Any]:
    row: dict[str, Any] = {
        "id": entry.id, "attempt": entry.focus_attempt, "found": bool(charts), "reason": reason,
        "n_corners": [len(ch.ids) for ch in charts],
    }
    if not charts:
        return row
    qw, qt = (
        np.concatenate([ch.q_wide for ch in charts]),
        np.concatenate([ch.q_tele for ch in charts]),
    )
    glob = _fit(qw, qt, c)
    per = [_fit(ch.q_wide, ch.q_tele, c) for ch in charts] if len(charts) > 1 else [glob]
    labels = cluster_disparities(np.concatenate([ch.d for ch in charts]))
    row.update(global_fit=glob.to_dict(), chart_fits=[f.to_dict() for f in per],
               disparity_clusters=int(labels.max() + 1))
    if len(charts) == 1:
        row["flat_scene"] = flat_scene_scale(qw, qt, c).to_dict()
    truth = _true_fits(root, entry.id, charts, rect)
    if truth is not None:
        row["truth"] = truth
        row["scale_error_global"] = abs(glob.scale - truth["scale_global"])
        row["scale_error_per_chart"] = [
            abs(f.scale - t) for f, t in zip(per, truth["scale_per_chart"], strict=False)
        ]
    row["_charts"], row["_fits"] = charts, per
    return row


def _table2(xy: F64, d: F64) -> dict[str, float]:
    """Fix learned at the chart's central third, applied to the rest: |Z/Z_c − 1| in %."""
    lo, hi = np.nanmin(xy, axis=0), np.nanmax(xy, axis=0)
    mid, half = (lo + hi) / 2, (hi - lo) / 6
    centre = np.all(np.abs(xy - mid) <= half, axis=1)
    if not centre.any():
        centre[int(np.argmin(np.linalg.norm(xy - mid, axis=1)))] = True
    d_c = np.nanmedian(d[:, centre], axis=1, keepdims=True)  # (M, 1): learned per attempt
    err = 100 * np.abs(d_c / d[:, ~centre] - 1)
    return {"median_pct": float(np.nanmedian(err)), "max_pct": float(np.nanmax(err))}


def _stack_stats(rows: list[dict[str, Any]], k: int, rect: Rectification) -> Any:
    """Per chart k over the stack: ranges and Table 2, before and after the scale fix (None
    when fewer than ``MIN_POINTS`` corners were seen in every attempt)."""
    used = [r for r in rows if r["found"] and not r["focus_fail"] and len(r["_charts"]) > k]
    keys = corner_keys(used[0]["_charts"][k].ids)
    for r in used[1:]:
        keys = np.intersect1d(keys, corner_keys(r["_charts"][k].ids))
    M, K = len(used), len(keys)
    if K < MIN_POINTS:
        return None
    before, after, xy = np.full((M, K), np.nan), np.full((M, K), np.nan), np.zeros((M, K, 2))
    for i, r in enumerate(used):
        ch, fit = r["_charts"][k], r["_fits"][k]
        _, ia, _ = np.intersect1d(corner_keys(ch.ids), keys, return_indices=True)
        before[i], xy[i] = ch.d[ia], ch.q_wide[ia]
        after[i] = fit.disparity(ch.q_wide[ia], ch.q_tele[ia])[0]
    out: dict[str, Any] = {"chart": k, "attempts": M, "corners_in_every_attempt": K}
    mean_d = float(np.nanmean(before))
    out["mean_d_px"], out["depth_m"] = mean_d, rect.f_px * rect.baseline_m / mean_d
    for name, D in (("before", before), ("after", after)):
        pc = np.ptp(D, axis=0)
        out[name] = {
            "chart_range_px": float(np.nanmax(D) - np.nanmin(D)),
            "corner_range_median_px": float(np.nanmedian(pc)),
            "corner_range_max_px": float(np.nanmax(pc)),
            "within_attempt_range_px": float(np.nanmean(np.ptp(D, axis=1))),
            "table2": _table2(xy.mean(axis=0), D),
        }
    out["chart_range_shrink"] = out["before"]["chart_range_px"] / max(
        out["after"]["chart_range_px"], 1e-9
    )
    scales = [r["_fits"][k].scale for r in used]
    out["scale_mean"], out["scale_std"] = float(np.mean(scales)), float(np.std(scales))
    errs = [r["scale_error_per_chart"][k] for r in used if "scale_error_per_chart" in r]
    if errs:
        out["scale_error_max"] = float(np.max(errs))
    out["_xy"], out["_before"], out["_after"] = xy.mean(axis=0), before, after
    return out


@canonical_analysis(lacking="without a refocus stack of verification captures")
def analyze_wt_scale(
    opened: OpenedSet, *, max_charts: int = 2, progress: Progress | None = None
) -> dict[str, Any]:
    """Measure the W-T scale of a refocus stack; the JSON-ready table (module docstring)."""
    t0, cs, _, rect = opened
    caps = stack_entries(cs, "wt-scale", "one or two static verification charts")
    c = np.asarray(rect.tele_rect.K[:2, 2], dtype=np.float64)
    rows = measure_each(
        caps,
        lambda e: _capture_row(e, *measure_charts(cs, e, rect, max_charts), c, cs.root, rect),
        progress,
    )
    for r, f in zip(rows, focus_check(cs, caps), strict=True):
        r.update(f)
    base = {"analysis": "wt-scale", "capture_set": str(cs.root), "focus_group": caps[0].focus_group,
            "captures_total": len(rows), "f_px": rect.f_px, "baseline_m": rect.baseline_m,
            "center_px": c.tolist()}
    used = [r for r in rows if r["found"] and not r["focus_fail"]]
    if len(used) < 2:
        why = "; ".join(f"{r['id']}: {r['reason'] or 'focus fail'}" for r in rows if r not in used)
        return {**base, "ok": False, "reason": f"{len(used)} usable attempts: {why}"[:600],
                "captures": rows}
    n_charts = min(len(r["_charts"]) for r in used)
    stack = [_stack_stats(rows, k, rect) for k in range(n_charts)]
    if any(st is None for st in stack):
        why = f"< {MIN_POINTS} corners of a chart seen in every attempt: keep it fully in view"
        return {**base, "ok": False, "captures": rows, "reason": why}
    return {**base, "ok": True, "reason": "", "captures_used": len(used), "charts": n_charts,
            "stack": stack, "captures": rows,
            "seconds": seconds_since(t0)}


# --- figures -----------------------------------------------------------------------------------
def write_figures(tb: dict[str, Any], out_dir: Path) -> list[Path]:
    """The three PNG figures of a wt-scale table (see module docstring)."""
    stack, files = tb["stack"], []
    fig = Figure(figsize=(12, 5), constrained_layout=True)
    axes = fig.subplots(1, 2)
    top = max(float(np.nanmax(np.ptp(s["_before"], axis=0))) for s in stack)
    for ax, when in zip(axes, ("before", "after"), strict=True):
        xy = np.concatenate([s["_xy"] for s in stack])
        v = np.concatenate([np.ptp(s[f"_{when}"], axis=0) for s in stack])
        ranges = ", ".join(f"chart {s['chart']}: {s[when]['chart_range_px']:.2f} px" for s in stack)
        label = f"per-corner d range over {stack[0]['attempts']} attempts [px]"
        map_panel(fig, ax, xy, v, f"{when} W-T scale fix — chart disparity range {ranges}",
                  label, vmin=0, vmax=top)
    fig.suptitle("Per-corner disparity range over the refocus stack (thesis Fig. 3-14 to 3-16)")
    files.append(save_figure(fig, out_dir / "wt_scale_corner_range.png"))
    r = next(r for r in tb["captures"] if r["found"] and not r["focus_fail"])
    fig = Figure(figsize=(12, 9), constrained_layout=True)
    axes = fig.subplots(2, 2)
    xy = np.concatenate([ch.q_wide for ch in r["_charts"]])
    fixed = [
        f.disparity(ch.q_wide, ch.q_tele) for ch, f in zip(r["_charts"], r["_fits"], strict=True)
    ]
    for j, (name, raw, fx) in enumerate((("d", "d", 0), ("e", "e", 1))):
        vals = (np.concatenate([getattr(ch, raw) for ch in r["_charts"]]),
                np.concatenate([x[fx] for x in fixed]))
        for i, when in enumerate(("before", "after")):
            map_panel(fig, axes[i, j], xy, vals[i], f"{name} {when} the scale fix (range "
                      f"{np.ptp(vals[i]):.3f} px)", f"{name} [px]", cmap="coolwarm")
    scales = ", ".join(f"{f.scale:.5f}" for f in r["_fits"])
    fig.suptitle(f"{r['id']}: disparity d and non-disparity error e, W-T scale(s) {scales} "
                 "(thesis Fig. 3-16 to 3-19)")
    files.append(save_figure(fig, out_dir / "wt_scale_maps.png"))
    fig = Figure(figsize=(8, 4.5), constrained_layout=True)
    ax = fig.subplots()
    used = [r for r in tb["captures"] if r["found"] and not r["focus_fail"]]
    att = [r["attempt"] for r in used]
    for k in range(tb["charts"]):
        name = f"chart {k} (d {stack[k]['mean_d_px']:.1f} px)"
        ax.plot(att, [r["chart_fits"][k]["scale"] for r in used], "o-", label=f"{name} measured")
        if "truth" in used[0]:
            ax.plot(att, [r["truth"]["scale_per_chart"][k] for r in used], "x", ms=9,
                    label=f"{name} truth")
    if tb["charts"] > 1:
        ax.plot(att, [r["global_fit"]["scale"] for r in used], "s--", label="all points")
    label_axes(ax, "W-T scale per refocus attempt (tele about its rectified principal point)",
               "focus attempt", "W-T scale s [-]", legend_fontsize=8)
    ax.set_xticks(att)
    files.append(save_figure(fig, out_dir / "wt_scale_scales.png"))
    return files


def _summary(tb: dict[str, Any]) -> tuple[str, ...]:
    """The summary lines of an ok table (:func:`run_table` words the others)."""
    fails = sum(r["focus_fail"] for r in tb["captures"])
    lines = [f"wt-scale: {tb['captures_used']}/{tb['captures_total']} attempts of stack "
             f"{tb['focus_group']} ({fails} focus fails), {tb['charts']} chart(s) "
             f"({tb['seconds']} s)"]
    for s in tb["stack"]:
        b, a = s["before"], s["after"]
        lines.append(
            f"chart {s['chart']} at {s['depth_m']:.2f} m: W-T scale {s['scale_mean']:.5f} ± "
            f"{s['scale_std']:.5f}; chart d range {b['chart_range_px']:.2f} → "
            f"{a['chart_range_px']:.3f} px ({s['chart_range_shrink']:.0f}×); per-corner range "
            f"max {b['corner_range_max_px']:.3f} → {a['corner_range_max_px']:.3f} px; Table 2 "
            f"centre fix on the rest: {b['table2']['median_pct']:.2f} → "
            f"{a['table2']['median_pct']:.2f} % (median)"
            + (f"; |s − truth| ≤ {s['scale_error_max']:.1e}" if "scale_error_max" in s else "")
        )
    return tuple(lines)


def run(capture_set: Path, out_dir: Path, progress: Progress | None = None) -> AnalysisOutput:
    """Registry entry: analyse, write ``wt_scale.json`` and the figures into ``out_dir``."""
    return run_table(
        "wt-scale", analyze_wt_scale, write_figures, _summary, capture_set, out_dir, progress
    )
