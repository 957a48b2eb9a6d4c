"""Essential-matrix scales analysis (thesis §3.5.3, Figures 3-22 to 3-26, eq. 8–9).

A refocus stack on a tripod (heated, manual focus: every attempt lands on a slightly different
lens position, so each camera has its own focal scale per attempt). The verification-chart
corners of every attempt are the matches;
:func:`~phonestereo.fixes.essential_compare.compare_variants` estimates E′ per attempt with
the set's calibration, recovers the per-camera scales by every method of Figure 3-26 (eq. 9,
match E, match rotation, match rotation keeping translation; each against the first attempt
and against the calibration; with and without offset) beside the same-camera "optimal"
normalisation, corrects the attempts and ranks the methods by the
per-corner disparity range over the stack (Figure 3-24/3-26). Figure 3-25 — the rotation and
translation decomposed from E of each attempt, before and after the optimal fix — is reported
too, and eq. 9's conditioning with every result.

Every focus group (``focus_group``) with >= 2 measured verification attempts is compared; the
overall ranking is by the median over groups of each method's median range.

A planar scene (the chart) makes E′ come from the plane's homography, where a focal scale is
indistinguishable from a translation along the optical axis: the E-based methods cannot work
there and the table says so (``essential_method``); with a depth scene they can (the fix's
tests reproduce the thesis's exact simulation, 1.0518 / 0.91532).

With a ``ground_truth.json`` (simulated) the true per-attempt focal scales (true f over the
calibration's f, or over the first attempt's) score every method's recovered scales.

Outputs: ``essential.json``, ``essential_ranges.png`` (Figure 3-26: per-corner disparity
ranges per method), ``essential_pose.png`` (Figure 3-25) and ``essential_scales.png``
(recovered vs true scales per attempt, sim only).
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from matplotlib.figure import Figure

from phonestereo.errors import InputError
from phonestereo.evaluation.analyses import AnalysisOutput, Progress
from phonestereo.evaluation.analyses._common import (
    MIN_ATTEMPTS,
    OpenedSet,
    canonical_analysis,
    label_axes,
    refocus_stacks,
    run_table,
    seconds_since,
)
from phonestereo.evaluation.analyses._common import save_figure as _save
from phonestereo.evaluation.chart_ruler import measure_capture
from phonestereo.fixes.essential_compare import (
    StackAttempt,
    VariantComparison,
    compare_variants,
    essential_from_points,
)
from phonestereo.geometry import Rig
from phonestereo.io import CaptureSet
from phonestereo.rectification import Rectification


def measure_stacks(
    cs: CaptureSet, rect: Rectification, name: str, progress: Progress | None = None
) -> tuple[dict[str, list[StackAttempt]], list[dict[str, Any]]]:
    """Chart corners of every attempt of every refocus stack: (group → attempts, capture rows)."""
    groups = refocus_stacks(cs, name, "one static chart (tripod, heated, manual focus)")
    total = sum(len(v) for v in groups.values())
    stacks: dict[str, list[StackAttempt]] = {}
    rows, done = [], 0
    for g, caps in groups.items():
        stacks[g] = []
        for c in caps:
            m = measure_capture(cs, c, rect)
            rows.append({"id": c.id, "focus_group": g, "focus_attempt": c.focus_attempt,
                         "found": m.found, "reason": m.reason,
                         "n_corners": len(m.ids)})
            if m.found:
                stacks[g].append(StackAttempt(c.id, m.ids, m.q_wide, m.q_tele))
            done += 1
            if progress is not None:
                progress(done, total, c.id)
    return stacks, rows


def _true_scales(root: Path, ids: list[str], rig: Rig) -> Any:
    """Sim only: per attempt (true f_wide / f_calib, true f_tele / f_calib)."""
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    if not (root / GROUND_TRUTH_NAME).is_file():
        return None
    gt = load_ground_truth(root / GROUND_TRUTH_NAME)
    out = []
    for i in ids:
        ct = gt.capture(i)
        out.append((ct.wide.true_camera().fx / rig.wide.fx, ct.tele.true_camera().fx / rig.tele.fx))
    return np.array(out)


def _pose(rig: Rig, atts: list[StackAttempt], cmp: VariantComparison) -> dict[str, Any]:
    """Figure 3-25: rotation vector (deg) and t̂ of each attempt, raw and after the optimal fix."""
    opt = cmp.row("focus opt")
    raw: list[dict[str, Any]] = []
    fixed: list[dict[str, Any]] = []
    for a, e, r in zip(atts, cmp.estimates, opt.per_attempt, strict=True):
        cw, ct = r.corrections(rig)
        e2 = essential_from_points(cw.apply(a.q_wide), ct.apply(a.q_tele), rig)
        for dst, est in ((raw, e), (fixed, e2)):
            om = np.rad2deg(cv2.Rodrigues(est.R)[0].reshape(3)) if est.ok else np.full(3, np.nan)
            dst.append({"id": a.id, "om_deg": om.round(5).tolist(),
                        "t_unit": np.asarray(est.t).round(5).tolist()})
    cal_om = np.rad2deg(cv2.Rodrigues(rig.T_tele_wide.R)[0].reshape(3))
    t = rig.T_tele_wide.t / np.linalg.norm(rig.T_tele_wide.t)
    return {"calibration": {"om_deg": cal_om.round(5).tolist(), "t_unit": t.round(5).tolist()},
            "attempts": raw, "after_optimal": fixed}


def _score(cmp: VariantComparison, true: Any) -> dict[str, float | None]:
    """RMS error of each method's recovered scales vs truth (both cameras, all attempts)."""
    out: dict[str, float | None] = {}
    for r in cmp.rows:
        if r.variant == "none":
            continue
        # optimal: the stack's median geometry; focus: the first attempt; calib: calibration
        ref = {"optimal": np.median(true, axis=0)}.get(
            r.variant, true[0] if r.reference == "focus" else np.ones(2)
        )
        got = np.array([[a.s_wide, a.s_tele] if a.ok else [np.nan, np.nan] for a in r.per_attempt])
        err = got - true / ref
        out[r.label] = (
            round(float(np.sqrt(np.nanmean(err**2))), 7) if np.isfinite(err).any() else None
        )
    return out


@canonical_analysis(lacking="without a refocus stack of verification captures")
def analyze_essential(opened: OpenedSet, *, progress: Progress | None = None) -> dict[str, Any]:
    """Compare the essential-matrix scale methods on every refocus stack (module docstring)."""
    t0, cs, rig, rect = opened
    stacks, rows = measure_stacks(cs, rect, "essential", progress)
    base = {"analysis": "essential", "capture_set": str(cs.root), "captures": rows}
    groups: dict[str, Any] = {}
    figs: dict[str, Any] = {}
    for g, atts in stacks.items():
        if len(atts) < MIN_ATTEMPTS:
            groups[g] = {"ok": False, "reason": f"chart measured in {len(atts)} attempt(s)"}
            continue
        try:
            cmp = compare_variants(atts, rig)
        except InputError as err:  # too few shared corners: the data's fault
            groups[g] = {"ok": False, "reason": str(err)}
            continue
        entry: dict[str, Any] = {
            "ok": True, "reason": "", "attempts": [a.id for a in atts],
            "corners_in_every_attempt": len(cmp.corner_keys),
            "essential_method": sorted({e.method for e in cmp.estimates}),
            "plane_rms_px": [round(e.plane_rms_px, 4) for e in cmp.estimates],
            "ranking": list(cmp.ranking), "methods": [r.to_dict() for r in cmp.rows],
            "pose": _pose(rig, atts, cmp),
        }
        true = _true_scales(cs.root, [a.id for a in atts], rig)
        if true is not None:
            entry["truth"] = {
                "scales": true.round(7).tolist(),
                "scale_rms_error": _score(cmp, true),
            }
        groups[g] = entry
        figs.setdefault("cmp", (g, cmp, true))
    done = {k: v for k, v in groups.items() if v["ok"]}
    if not done:
        why = "; ".join(f"{k}: {v['reason']}" for k, v in groups.items())[:600]
        return {**base, "ok": False, "reason": f"no refocus stack could be compared: {why}",
                "groups": groups, "seconds": seconds_since(t0)}
    med: dict[str, list[float]] = defaultdict(list)
    for v in done.values():
        for m in v["methods"]:
            med[m["label"]].append(np.nan if m["median_range_px"] is None else m["median_range_px"])
    overall = sorted(med, key=lambda k: (not np.isfinite(np.nanmedian(med[k] + [np.inf])),
                                         float(np.nanmedian(med[k])) if np.isfinite(med[k]).any()
                                         else math.inf))
    out = {**base, "ok": True, "reason": "", "groups": groups, "ranking": overall,
           "best": overall[0], "_fig": figs.get("cmp"),
           "seconds": seconds_since(t0)}
    return out


# --- figures -----------------------------------------------------------------------------------
def write_figures(tb: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write the PNG figures of an essential table into ``out_dir``; returns their paths."""
    g, cmp, true = tb["_fig"]
    files = []
    fig = Figure(figsize=(11, 5.5), constrained_layout=True)
    ax = fig.subplots()
    rows = [r for r in cmp.rows if np.isfinite(r.ranges_px).any()]
    data = [r.ranges_px[np.isfinite(r.ranges_px)] for r in rows]
    bp = ax.boxplot(data, showfliers=False, patch_artist=True)
    colours = {"-": "0.7", "focus": "tab:blue", "calib": "tab:orange"}
    for patch, r in zip(bp["boxes"], rows, strict=True):
        patch.set_facecolor(colours.get(r.reference, "0.7"))
    ax.set_xticks(np.arange(1, len(rows) + 1),
                  [f"{r.label} ({r.attempts_ok}/{len(r.per_attempt)})" for r in rows],
                  rotation=60, ha="right", fontsize=8)
    ax.set_yscale("log")
    ax.set_ylabel("per-corner disparity range over the stack [px]")
    ax.set_title(f"Disparity ranges after each method, stack {g!r}, best first "
                 "(thesis Fig. 3-26; blue: vs first attempt, orange: vs calibration)")
    ax.grid(alpha=0.3, axis="y")
    missing = [r.label for r in cmp.rows if not np.isfinite(r.ranges_px).any()]
    if missing:
        ax.text(0.01, 0.98, "no result (see JSON reasons): " + ", ".join(missing),
                transform=ax.transAxes, va="top", fontsize=8, color="0.3")
    files.append(_save(fig, out_dir / "essential_ranges.png"))
    pose = tb["groups"][g]["pose"]
    fig = Figure(figsize=(10, 6.5), constrained_layout=True)
    axes = fig.subplots(2, 3)
    k = np.arange(len(pose["attempts"]))
    for j in range(3):
        for row_i, key, unit in ((0, "om_deg", "°"), (1, "t_unit", "")):
            ax = axes[row_i, j]
            raw = [a[key][j] for a in pose["attempts"]]
            fixed = [a[key][j] for a in pose["after_optimal"]]
            ax.plot(k, raw, "o-", label="attempt (raw)")
            ax.plot(k, fixed, "s--", label="after optimal fix")
            ax.axhline(pose["calibration"][key][j], color="k", lw=0.8, label="calibration")
            name = ("om", "t̂")[row_i] + "_" + "xyz"[j]
            label_axes(ax, f"{name} from E per attempt", "attempt", f"{name} {unit}".strip())
    axes[0, 0].legend(fontsize=7)
    fig.suptitle("Rotation and translation decomposed from E (thesis Fig. 3-25)")
    files.append(_save(fig, out_dir / "essential_pose.png"))
    if true is not None:
        fig = Figure(figsize=(10, 4.5), constrained_layout=True)
        axes = fig.subplots(1, 2)
        show = [r for r in cmp.rows if r.label in ("focus opt", "calib eq9", "calib E", "focus E",
                                                   "calib Om", "calib OmT")]
        for c, ax in enumerate(axes):
            ax.plot(k, true[:, c], "k*-", ms=9, label="truth (vs calibration)")
            ax.plot(k, true[:, c] / true[0, c], "k+:", ms=9, label="truth (vs first attempt)")
            med = np.median(true[:, c])
            ax.plot(k, true[:, c] / med, "kx--", ms=7, lw=0.6, label="truth (vs stack median)")
            for r in show:
                s = [(a.s_wide, a.s_tele)[c] if a.ok else np.nan for a in r.per_attempt]
                ax.plot(k, s, ".-", lw=0.8, label=r.label)
            label_axes(ax, f"{('wide', 'tele')[c]} focal scale per attempt", "attempt",
                       "f / f_reference")
            lo, hi = np.nanmin(true[:, c]), np.nanmax(true[:, c])
            ax.set_ylim(min(lo, 1.0) - 0.01, max(hi, 1.0) + 0.01)
        axes[1].legend(fontsize=7)
        files.append(_save(fig, out_dir / "essential_scales.png"))
    return files


def _summary(tb: dict[str, Any]) -> tuple[str, ...]:
    """The summary lines of an ok table (:func:`run_table` words the others)."""
    lines = [f"essential: {len([g for g in tb['groups'].values() if g['ok']])} refocus stack(s), "
             f"{len(tb['captures'])} captures ({tb['seconds']} s)"]
    for g, v in tb["groups"].items():
        if not v["ok"]:
            lines.append(f"{g}: no result: {v['reason']}")
            continue
        m = {x["label"]: x for x in v["methods"]}
        top = ", ".join(f"{k} {m[k]['median_range_px']}" for k in v["ranking"][:4])
        lines.append(
            f"{g}: E from {'/'.join(v['essential_method'])}; best (median range px): {top}"
        )
        eq9 = m.get("calib eq9")
        if eq9 and eq9["attempts_ok"]:
            lines.append(
                f"{g}: eq. 9 vs calibration, median condition {eq9['median_condition']}, "
                f"range {eq9['median_range_px']} px (none: {m['none']['median_range_px']})"
            )
        elif eq9:
            lines.append(f"{g}: eq. 9 vs calibration failed: {eq9['per_attempt'][0]['reason']}")
    lines.append(f"overall best: {tb['best']}")
    return tuple(lines)


def run(capture_set: Path, out_dir: Path, progress: Progress | None = None) -> AnalysisOutput:
    """Registry entry: analyse, write ``essential.json`` and the figures into ``out_dir``."""
    return run_table(
        "essential", analyze_essential, write_figures, _summary, capture_set, out_dir, progress
    )
