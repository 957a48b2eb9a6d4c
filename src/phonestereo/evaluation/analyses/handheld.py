"""Handheld analysis (thesis §3.5.3, Figure 3-27): the optimal scale correction, handheld.

Between the attempts of a handheld refocus stack the phone moves a little, so a same-camera
scale/offset fit absorbs motion as well as focus (the worry of §3.5.3 that led to the essential
approach). The thesis found the "optimal" correction — per camera, each attempt's scale and
offset against the first attempt, normalised to the stack's median (option 2.b.1,
:func:`~phonestereo.fixes.focus.fit_scale_offset` and
:func:`~phonestereo.fixes.focus.normalise_to_median`) — works well even handheld, with the
only large ranges on the closest chart, whose relative error is small anyway.

Per refocus stack (``focus_group``) the chart corners seen in every attempt are measured with the
chart ruler; per corner the disparity range (max − min over the attempts) and the relative error
range / mean d (= the relative depth spread, eq. 4) are reported before and after the
correction. With a ``ground_truth.json`` (simulated) the true hand motion of every attempt
relative to the first (rotation, translation) is reported beside them.

Outputs: ``handheld.json`` and ``handheld_ranges.png`` (Figure 3-27: disparity ranges and
relative errors before / after, per stack).
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
    run_table,
    seconds_since,
)
from phonestereo.evaluation.analyses._common import save_figure as _save
from phonestereo.evaluation.analyses.essential import MIN_ATTEMPTS, measure_stacks
from phonestereo.fixes.essential_compare import MIN_POINTS, shared_points
from phonestereo.fixes.focus import fit_scale_offset, normalise_to_median
from phonestereo.geometry import Rig
from phonestereo.rectification import Rectification

F64 = np.ndarray


def optimal_correction(
    pts: list[tuple[F64, F64]], rig: Rig, rect: Rectification
) -> tuple[F64, F64, list[dict[str, Any]]]:
    """(d before (M, K), d after (M, K), per-attempt fits): the optimal scale correction."""
    corr = []
    for role, cam in ((0, rig.wide), (1, rig.tele)):
        c = np.array([cam.cx, cam.cy])
        corr.append(normalise_to_median([fit_scale_offset(pts[0][role], p[role], c) for p in pts]))
    before = np.array([rect.disparity(qw, qt)[0] for qw, qt in pts])
    after = np.array([
        rect.disparity(cw.apply(qw), ct.apply(qt))[0]
        for (qw, qt), cw, ct in zip(pts, corr[0], corr[1], strict=True)
    ])
    fits = [{"wide": cw.to_dict(), "tele": ct.to_dict()} for cw, ct in zip(*corr, strict=True)]
    return before, after, fits


def _stats(d: F64) -> dict[str, Any]:
    rng = np.nanmax(d, axis=0) - np.nanmin(d, axis=0)
    rel = 100.0 * rng / np.nanmean(d, axis=0)
    return {"median_range_px": round(float(np.median(rng)), 5),
            "p90_range_px": round(float(np.percentile(rng, 90)), 5),
            "median_relative_error_pct": round(float(np.median(rel)), 5),
            "p90_relative_error_pct": round(float(np.percentile(rel, 90)), 5),
            "_ranges": rng, "_relative": rel}


def _motion(root: Path, ids: list[str]) -> Any:
    """Sim only: true device motion of each attempt relative to the first (deg, mm)."""
    from phonestereo.geometry import Transform
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    if not (root / GROUND_TRUTH_NAME).is_file():
        return None
    gt = load_ground_truth(root / GROUND_TRUTH_NAME)
    poses = [Transform.from_dict(gt.capture(i).T_world_device) for i in ids]
    out = []
    for p in poses:
        rel = poses[0].inverse() @ p
        out.append({"rotation_deg": round(float(np.rad2deg(np.linalg.norm(rel.rotvec))), 5),
                    "translation_mm": round(float(np.linalg.norm(rel.t) * 1e3), 5)})
    return out


@canonical_analysis(lacking="without a refocus stack of verification captures")
def analyze_handheld(opened: OpenedSet, *, progress: Progress | None = None) -> dict[str, Any]:
    """Disparity ranges and relative errors before/after the optimal correction, per stack."""
    t0, cs, rig, rect = opened
    stacks, rows = measure_stacks(cs, rect, "handheld", progress)
    groups: dict[str, Any] = {}
    for g, atts in stacks.items():
        keys, pts = shared_points(atts) if len(atts) >= MIN_ATTEMPTS else (np.zeros(0), [])
        if len(atts) < MIN_ATTEMPTS or len(keys) < MIN_POINTS:
            groups[g] = {"ok": False, "reason": f"{len(atts)} measured attempt(s), "
                                                f"{len(keys)} corners in every one"}
            continue
        before, after, fits = optimal_correction(pts, rig, rect)
        sb, sa = _stats(before), _stats(after)
        entry = {
            "ok": True, "reason": "", "attempts": [a.id for a in atts],
            "corners_in_every_attempt": len(keys),
            "mean_disparity_px": round(float(np.mean(before)), 4),
            "depth_m": round(float(rect.depth(np.mean(before))), 4),
            "before": sb, "after": sa,
            "range_shrink": round(sb["median_range_px"] / max(sa["median_range_px"], 1e-12), 3),
            "fits": fits,
        }
        motion = _motion(cs.root, [a.id for a in atts])
        if motion is not None:
            entry["truth"] = {"motion": motion}
        groups[g] = entry
    done = {k: v for k, v in groups.items() if v["ok"]}
    base = {"analysis": "handheld", "capture_set": str(cs.root), "captures": rows,
            "groups": groups, "seconds": seconds_since(t0)}
    if not done:
        why = "; ".join(f"{k}: {v['reason']}" for k, v in groups.items())[:600]
        return {**base, "ok": False, "reason": f"no refocus stack could be measured: {why}"}
    return {**base, "ok": True, "reason": ""}


def write_figures(tb: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write ``handheld_ranges.png`` (Figure 3-27) into ``out_dir``."""
    done = {k: v for k, v in tb["groups"].items() if v["ok"]}
    names = sorted(done, key=lambda k: done[k]["depth_m"])
    fig = Figure(figsize=(11, 5), constrained_layout=True)
    axes = fig.subplots(1, 2)
    for ax, key, ylabel, title in (
        (axes[0], "_ranges", "disparity range [px]", "Per-corner disparity range over the stack"),
        (axes[1], "_relative", "relative error [%]", "Per-corner relative error (range / d)"),
    ):
        data, pos, colours = [], [], []
        for i, g in enumerate(names):
            for j, when in enumerate(("before", "after")):
                data.append(done[g][when][key])
                pos.append(3 * i + j)
                colours.append(("tab:red", "tab:green")[j])
        bp = ax.boxplot(data, positions=pos, showfliers=False, patch_artist=True, widths=0.8)
        for patch, c in zip(bp["boxes"], colours, strict=True):
            patch.set_facecolor(c)
        ax.set_xticks([3 * i + 0.5 for i in range(len(names))],
                      [f"{g}\nnaive Z ≈ {done[g]['depth_m']:.2f} m" for g in names])
        ax.set_ylabel(ylabel)
        ax.set_title(title)
        ax.grid(alpha=0.3, axis="y")
        ax.legend([bp["boxes"][0], bp["boxes"][1]], ["before", "after optimal correction"],
                  fontsize=8)
    fig.suptitle("Handheld refocus stacks: optimal scale correction (thesis Fig. 3-27)")
    return [_save(fig, out_dir / "handheld_ranges.png")]


def _summary(tb: dict[str, Any]) -> tuple[str, ...]:
    """The summary lines of an ok table (:func:`run_table` words the others)."""
    lines = [f"handheld: {len(tb['captures'])} captures ({tb['seconds']} s)"]
    for g, v in tb["groups"].items():
        if not v["ok"]:
            lines.append(f"{g}: no result: {v['reason']}")
            continue
        b, a = v["before"], v["after"]
        lines.append(
            f"{g} (≈{v['depth_m']:.2f} m): median range {b['median_range_px']:.4f} → "
            f"{a['median_range_px']:.4f} px ({v['range_shrink']:.1f}×), relative error "
            f"{b['median_relative_error_pct']:.3f} → {a['median_relative_error_pct']:.3f} %"
        )
    return tuple(lines)


def run(capture_set: Path, out_dir: Path, progress: Progress | None = None) -> AnalysisOutput:
    """Registry entry: analyse, write ``handheld.json`` and the figure into ``out_dir``."""
    return run_table(
        "handheld", analyze_handheld, write_figures, _summary, capture_set, out_dir, progress
    )
