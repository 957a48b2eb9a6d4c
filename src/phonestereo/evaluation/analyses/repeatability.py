"""Same-camera focus repeatability analysis (thesis §3.5.3, Figures 3-20 / 3-21, Table 3).

A refocus stack (tripod, one static verification chart, N manual refocus attempts at the same
focus setting) is measured with the chart ruler over the corners seen in every attempt. Even
on a tripod each attempt has its own scale per camera, so every corner's disparity ranges over
the stack (Figure 3-20). Two fixes are measured:

* normalisation to the stack's median (§3.5.3 option 2.b.1): per camera, the scale and offset
  of every attempt against the first (:func:`~phonestereo.fixes.focus.fit_scale_offset`), the
  median of those as the stack's geometry, and each attempt's pixels mapped there
  (:func:`~phonestereo.fixes.focus.normalise_to_median`) before rectification;
* averaging the disparity of n attempts chosen at random (option 2, Figure 3-21, Table 3):
  the per-corner range of the n-averages over random trials and their relative error against
  the all-attempt mean (δZ/Z = δd/d).

Focus fails (sharpness far below the stack's median) are left out. With ``ground_truth.json``
the fitted per-attempt scales are compared with the true focal-length ratios. Outputs:
``repeatability.json``, ``repeatability_corner_range.png``, ``repeatability_averaging.png``,
``repeatability_scales.png``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from phonestereo.evaluation.analyses import AnalysisOutput, Progress
from phonestereo.evaluation.analyses._common import (
    OpenedSet,
    canonical_analysis,
    label_axes,
    map_panel,
    measure_each,
    refocus_stacks,
    run_table,
    save_figure,
    seconds_since,
)
from phonestereo.evaluation.chart_ruler import corner_keys, measure_capture, shared_keys
from phonestereo.fixes.focus import fit_scale_offset, normalise_to_median
from phonestereo.fixes.refocus import averaging_trials, detect_focus_failures, sharpness
from phonestereo.io import CaptureEntry, CaptureSet, read_gray

F64 = np.ndarray
AVERAGE_N = (1, 3, 5)  # attempts averaged (Table 3 rows)


# --- shared with the wt-scale analysis ------------------------------------------------------
def stack_entries(cs: CaptureSet, analysis: str, what: str) -> list[CaptureEntry]:
    """The largest refocus stack of verification captures (>= 2 attempts), ordered by attempt;
    ``what``: the chart(s) it shows (:func:`refocus_stacks`)."""
    return max(refocus_stacks(cs, analysis, f"{what} on a tripod").values(), key=len)


def focus_check(cs: CaptureSet, caps: list[CaptureEntry]) -> list[dict[str, Any]]:
    """Focus-fail verdicts of a stack (§3.5.1): sharpness of the wide ROI and the tele image
    against the stack's median; per capture ``focus_wide``, ``focus_tele``, ``focus_fail``."""
    sharp = []
    for entry in caps:
        w, t = (read_gray(p) for p in cs.image_paths(entry.id))
        sharp.append((sharpness(w, entry.roi), sharpness(t)))
    vw, vt = (detect_focus_failures([s[j] for s in sharp]) for j in (0, 1))
    return [
        {"focus_wide": a.to_dict(), "focus_tele": b.to_dict(), "focus_fail": a.failed or b.failed}
        for a, b in zip(vw, vt, strict=True)
    ]


def _stats(D: F64) -> dict[str, float]:
    pc = np.ptp(D, axis=0)
    return {"corner_range_median_px": float(np.nanmedian(pc)),
            "corner_range_max_px": float(np.nanmax(pc)),
            "chart_range_px": float(np.nanmax(D) - np.nanmin(D))}


def _truth_scales(root: Path, ids: list[str]) -> Any:
    """True focal-length ratio of each attempt to the first, per camera (sim), or None."""
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    if not (root / GROUND_TRUTH_NAME).is_file():
        return None
    gt = load_ground_truth(root / GROUND_TRUTH_NAME)
    caps = [gt.capture(i) for i in ids]
    return {
        role: [getattr(c, role).true_camera().fx / getattr(caps[0], role).true_camera().fx
               for c in caps]
        for role in ("wide", "tele")
    }


@canonical_analysis(lacking="without a refocus stack of verification captures")
def analyze_repeatability(
    opened: OpenedSet,
    *,
    trials: int = 200,
    seed: int = 0,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Measure the refocus repeatability of a stack; the JSON-ready table (module docstring).

    Parameters
    ----------
    capture_set : path or CaptureSet
    trials : int
        Random draws of n attempts per Table 3 row.
    seed : int
        Seed of those draws.
    """
    t0, cs, rig, rect = opened
    caps = stack_entries(cs, "repeatability", "one static verification chart")
    ms = measure_each(caps, lambda c: measure_capture(cs, c, rect), progress)
    focus = focus_check(cs, caps)
    rows = [
        {
            "id": m.id,
            "attempt": e.focus_attempt,
            "found": m.found,
            "reason": m.reason,
            "n_corners": len(m.ids),
            **f,
        }
        for m, e, f in zip(ms, caps, focus, strict=True)
    ]
    used = [m for m, r in zip(ms, rows, strict=True) if m.found and not r["focus_fail"]]
    base = {
        "analysis": "repeatability",
        "capture_set": str(cs.root),
        "focus_group": caps[0].focus_group,
        "captures_total": len(ms),
        "captures_used": len(used),
        "f_px": rect.f_px,
        "baseline_m": rect.baseline_m,
    }
    keys = shared_keys(used)
    if len(used) < 2 or len(keys) < 6:
        why = "; ".join(f"{r['id']}: {r['reason'] or 'focus fail'}" for r in rows
                        if not r["found"] or r["focus_fail"])
        reason = f"{len(used)} usable attempts, {len(keys)} corners in all: {why}"[:600]
        return {**base, "ok": False, "reason": reason, "captures": rows}
    sel = [np.intersect1d(corner_keys(m.ids), keys, return_indices=True)[1] for m in used]
    Qw = np.stack([m.q_wide[i] for m, i in zip(used, sel, strict=True)])  # (M, K, 2) raw px
    Qt = np.stack([m.q_tele[i] for m, i in zip(used, sel, strict=True)])
    D0 = np.stack([m.d_px[i] for m, i in zip(used, sel, strict=True)])  # (M, K)
    c_w, c_t = rig.wide.K[:2, 2], rig.tele.K[:2, 2]
    fits = {"wide": [fit_scale_offset(Qw[0], q, c_w) for q in Qw],
            "tele": [fit_scale_offset(Qt[0], q, c_t) for q in Qt]}
    corr = {role: normalise_to_median(f) for role, f in fits.items()}
    Qw_n = np.stack([t.apply(q) for t, q in zip(corr["wide"], Qw, strict=True)])
    Qt_n = np.stack([t.apply(q) for t, q in zip(corr["tele"], Qt, strict=True)])
    D1 = rect.disparity(Qw_n, Qt_n)[0]
    before, after = _stats(D0), _stats(D1)
    mean_all = np.nanmean(D0, axis=0)
    table3, avg = [], {}
    for n in (k for k in AVERAGE_N if k <= len(used)):
        A = averaging_trials(D0, n, trials, seed)  # (trials, K)
        rel = 100 * np.abs(A / mean_all - 1)
        pc = np.ptp(A, axis=0)
        table3.append({"n": n, "corner_range_median_px": float(np.nanmedian(pc)),
                       "corner_range_max_px": float(np.nanmax(pc)),
                       "relative_error_median_pct": float(np.nanmedian(rel)),
                       "relative_error_p90_pct": float(np.nanpercentile(rel, 90)),
                       "relative_error_max_pct": float(np.nanmax(rel))})
        avg[n] = pc
    out: dict[str, Any] = {
        **base, "ok": True, "reason": "", "corners_in_every_attempt": len(keys),
        "mean_d_px": float(np.nanmean(D0)),
        "depth_m": rect.f_px * rect.baseline_m / float(np.nanmean(D0)),
        "before": before, "after_normalisation": after,
        "normalisation_shrink": before["corner_range_median_px"]
        / max(after["corner_range_median_px"], 1e-9),
        "fits": {role: [f.to_dict() for f in fs] for role, fs in fits.items()},
        "corrections": {role: [f.to_dict() for f in fs] for role, fs in corr.items()},
        "table3": table3, "trials": trials, "captures": rows,
    }
    truth = _truth_scales(cs.root, [m.id for m in used])
    if truth is not None:
        err = {r: float(np.max(np.abs(np.array([f.scale for f in fits[r]]) - np.array(truth[r]))))
               for r in ("wide", "tele")}
        out["truth"] = {"scale_ratio": truth, "scale_error_max": err}
    out["_xy"] = np.nanmean(rect.points_wide(Qw), axis=0)
    out["_before"], out["_after"], out["_avg"] = D0, D1, avg
    out["seconds"] = seconds_since(t0)
    return out


def write_figures(tb: dict[str, Any], out_dir: Path) -> list[Path]:
    """The three PNG figures of a repeatability table (see module docstring)."""
    xy, M, files = tb["_xy"], tb["captures_used"], []
    fig = Figure(figsize=(12, 5), constrained_layout=True)
    axes = fig.subplots(1, 2)
    top = float(np.nanmax(np.ptp(tb["_before"], axis=0)))
    for ax, key, name in zip(axes, ("_before", "_after"), ("raw", "normalised to the median"),
                             strict=True):
        pc = np.ptp(tb[key], axis=0)
        map_panel(
            fig,
            ax,
            xy,
            pc,
            f"{name}: per-corner range median {np.median(pc):.3f}, max {np.max(pc):.3f} px",
            f"d range over {M} attempts [px]",
            vmin=0,
            vmax=top,
        )
    fig.suptitle("Disparity range of each corner over the refocus stack (thesis Fig. 3-20)")
    files.append(save_figure(fig, out_dir / "repeatability_corner_range.png"))
    rows = tb["table3"]
    fig = Figure(figsize=(5 * len(rows), 4.8), constrained_layout=True)
    axes = np.atleast_1d(fig.subplots(1, len(rows)))
    top = max(float(np.nanmax(tb["_avg"][r["n"]])) for r in rows)
    for ax, r in zip(axes, rows, strict=True):
        map_panel(fig, ax, xy, tb["_avg"][r["n"]], f"mean of {r['n']} attempt(s): range median "
                  f"{r['corner_range_median_px']:.3f} px, rel. error median "
                  f"{r['relative_error_median_pct']:.2f} %",
                  f"range over {tb['trials']} random draws [px]", vmin=0, vmax=top)
    fig.suptitle("Averaging the disparity over refocus attempts (thesis Fig. 3-21, Table 3)")
    files.append(save_figure(fig, out_dir / "repeatability_averaging.png"))
    fig = Figure(figsize=(8, 4.5), constrained_layout=True)
    ax = fig.subplots()
    for role, mk in (("wide", "o"), ("tele", "s")):
        s = [f["scale"] for f in tb["fits"][role]]
        ax.plot(range(len(s)), s, mk + "-", label=f"{role}: fitted (vs attempt 0)")
        if "truth" in tb:
            ax.plot(range(len(s)), tb["truth"]["scale_ratio"][role], "x", ms=9,
                    label=f"{role}: true focal ratio")
    label_axes(ax, "Same-camera scale of each refocus attempt against the first",
               "focus attempt (usable, in order)", "scale s [-]", legend_fontsize=8)
    files.append(save_figure(fig, out_dir / "repeatability_scales.png"))
    return files


def _summary(tb: dict[str, Any]) -> tuple[str, ...]:
    """The summary lines of an ok table (:func:`run_table` words the others)."""
    b, a = tb["before"], tb["after_normalisation"]
    lines = [
        f"repeatability: {tb['captures_used']}/{tb['captures_total']} attempts of stack "
        f"{tb['focus_group']}, {tb['corners_in_every_attempt']} corners in all ({tb['seconds']} s)",
        f"per-corner d range: median {b['corner_range_median_px']:.3f} → "
        f"{a['corner_range_median_px']:.3f} px, max {b['corner_range_max_px']:.3f} → "
        f"{a['corner_range_max_px']:.3f} px after normalisation to the median "
        f"({tb['normalisation_shrink']:.1f}×)",
        "Table 3: " + "; ".join(
            f"mean of {r['n']}: range {r['corner_range_median_px']:.3f} px, error "
            f"{r['relative_error_median_pct']:.2f} % (p90 {r['relative_error_p90_pct']:.2f} %)"
            for r in tb["table3"]),
    ]
    if "truth" in tb:
        e = tb["truth"]["scale_error_max"]
        lines.append(f"truth: same-camera scale error ≤ {e['wide']:.1e} (wide), "
                     f"{e['tele']:.1e} (tele)")
    return tuple(lines)


def run(capture_set: Path, out_dir: Path, progress: Progress | None = None) -> AnalysisOutput:
    """Registry entry: analyse, write ``repeatability.json`` and the figures into ``out_dir``."""
    analyze, name = analyze_repeatability, "repeatability"
    return run_table(name, analyze, write_figures, _summary, capture_set, out_dir, progress)
