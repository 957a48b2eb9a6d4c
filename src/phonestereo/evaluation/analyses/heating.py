"""Heating analysis (thesis §3.1, Figures 3-3 / 3-4, Table 1): the warm-up drift of the disparity.

A static verification chart on a tripod, focus locked, captured from cold: the chart corners are
the ruler. Per capture, the chart is detected in both images, corners are matched by their chart
(row, col), rectified with the set's calibration (canonical, §3.3) and the mean disparity d and
mean non-disparity error e are taken over the corners seen in *every* capture (so a corner
dropped in one capture cannot move the mean). The warm-up curve c + A·(1 − e^(−t/τ)) is fitted
to both (:func:`~phonestereo.fixes.heating.fit_drift_curve`), the saturation time reported,
and the warm-up gates (time, measured drift rate) decide every capture. Table 1 of the thesis
(the depth error heating alone adds) is δZ/Z = Δd / d with d = f·B/Z.

When the set has a ``ground_truth.json`` (simulated), the true τ and the true mean disparity
(the true corner pixels rectified the same way) are compared with the estimates.

Outputs in ``out_dir``: ``heating.json`` (the table), ``heating_drift.png`` (d and e vs time with
the fits), ``heating_corners.png`` (d change of single corners vs time, Figure 3-4 style) and,
when the module reports temperature, ``heating_temperature.png`` (d vs temperature, Figure 3-3).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.figure import Figure

from phonestereo.errors import InputError
from phonestereo.evaluation.analyses import AnalysisOutput, Progress
from phonestereo.evaluation.analyses._common import (
    OpenedSet,
    canonical_analysis,
    label_axes,
    measure_each,
    seconds_since,
    write_output,
)
from phonestereo.evaluation.analyses._common import save_figure as _save
from phonestereo.evaluation.chart_ruler import (
    CaptureMeasurement,
    corner_keys,
    measure_capture,
    per_corner,
    shared_keys,
)
from phonestereo.fixes.heating import (
    MIN_SAMPLES,
    DriftFit,
    HeatingCorrection,
    drift_rate,
    fit_drift_curve,
)
from phonestereo.fixes.warmup import WarmupGate
from phonestereo.io import CaptureEntry, CaptureSet
from phonestereo.rectification import Rectification

F64 = np.ndarray
TABLE1_DEPTHS_M = (0.5, 1.0, 1.5, 2.0, 3.0, 4.0)
MIN_COMMON = 12  # fewest corners seen in every capture before falling back to all corners
RATE_WINDOW = 3  # captures (this one and the ones before) in a measured drift rate


def _series(ms: list[CaptureMeasurement]) -> tuple[np.ndarray, F64, F64, np.ndarray]:
    """Per capture mean d, e over the corners found in every capture; (keys, d, e, D (M, K))."""
    shared = shared_keys(ms)
    use_shared = len(shared) >= MIN_COMMON
    d_mean, e_mean = np.full(len(ms), np.nan), np.full(len(ms), np.nan)
    for i, m in enumerate(ms):
        if not m.found:
            continue
        sel = np.isin(corner_keys(m.ids), shared) if use_shared else np.ones(len(m.ids), bool)
        d_mean[i], e_mean[i] = float(np.mean(m.d_px[sel])), float(np.mean(m.e_px[sel]))
    return shared, d_mean, e_mean, per_corner(ms, shared)


def _truth(
    root: Path, ms: list[CaptureMeasurement], shared: np.ndarray, rect: Rectification
) -> Any:
    """True τ and true mean disparity per capture (sim sets only), or None."""
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    if not (root / GROUND_TRUTH_NAME).is_file():
        return None
    gt = load_ground_truth(root / GROUND_TRUTH_NAME)
    heating_on = bool(gt.module.get("effects", {}).get("heating", True))
    tau = float(gt.module["heating"]["tau_s"]) if heating_on else None
    d_true = []
    for m in ms:
        kp = gt.capture(m.id).objects[0].keypoints["corners"].arrays()
        sel = np.isin(corner_keys(kp.ids), shared)
        d, _ = rect.disparity(kp.wide_px[sel], kp.tele_px[sel])
        d_true.append(float(np.nanmean(d)) if np.any(np.isfinite(d)) else float("nan"))
    return {"tau_s": tau, "d_mean_px": d_true}


def _gates(t: F64, d: F64, min_time_s: float, max_rate: float) -> list[Any]:
    """Both warm-up gates per capture; the rate is measured over the last ``RATE_WINDOW``."""
    time_gate = WarmupGate(min_time_s=min_time_s)
    rate_gate = WarmupGate(max_drift_rate_px_per_s=max_rate)
    rows = []
    for i in range(len(t)):
        lo = max(0, i - RATE_WINDOW + 1)
        rate = drift_rate(t[lo : i + 1], d[lo : i + 1])
        g1 = time_gate.check({"time_s": t[i]})
        g2 = rate_gate.check({"time_s": t[i]}, drift_rate_px_per_s=rate)
        rows.append(
            {"measured_rate_px_per_s": round(rate, 6), "time_gate": g1.passed,
             "time_gate_reason": g1.reason, "rate_gate": g2.passed, "rate_gate_reason": g2.reason}
        )
    return rows


def _check_needs(cs: CaptureSet) -> list[CaptureEntry]:
    caps = [c for c in cs.captures() if c.kind == "verification" and c.time_s is not None]
    if len({c.time_s for c in caps}) < MIN_SAMPLES:
        raise InputError(
            f"the heating analysis needs >= {MIN_SAMPLES} 'verification' captures of a static "
            "chart (tripod, focus locked) at distinct time_s from cold (e.g. every 10 s for "
            f"10 min; `phonestereo simulate heating`); {cs.root} has {len(caps)} verification "
            f"capture(s) at {len({c.time_s for c in caps})} distinct time(s)"
        )
    return sorted(caps, key=lambda c: c.time_s or 0.0)


@canonical_analysis(lacking="lacking the captures the analysis needs (message names them)")
def analyze_heating(
    opened: OpenedSet,
    *,
    min_time_s: float = 180.0,
    max_drift_rate_px_per_s: float = 0.002,
    saturation_fraction: float = 0.95,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Measure the heating drift of a capture set; the JSON-ready table (see module docstring).

    Parameters
    ----------
    capture_set : path or CaptureSet
    min_time_s : float
        Warm-up time of the time gate (thesis: 3 min for the folded module).
    max_drift_rate_px_per_s : float
        Rate gate: largest |d| drift rate of the static chart, px/s, measured over the last
        ``RATE_WINDOW`` captures (0.002 px/s ≈ 0.14 px still to come with τ = 70 s).
    saturation_fraction : float
        Fraction of the drift that defines the saturation time.
    """
    t0, cs, _, rect = opened
    caps = _check_needs(cs)
    n_min = MIN_SAMPLES
    ms = measure_each(caps, lambda c: measure_capture(cs, c, rect, min_corners=n_min), progress)
    found = [m for m in ms if m.found]
    base = {"analysis": "heating", "capture_set": str(cs.root), "captures_total": len(ms)}
    if len(found) < MIN_SAMPLES:
        why = "; ".join(f"{m.id}: {m.reason}" for m in ms if not m.found)[:600]
        return {**base, "ok": False, "reason": f"chart found in {len(found)} captures: {why}"}
    shared, d, e, per_corner = _series(ms)
    t = np.array([m.time_s for m in ms])
    fit_d = fit_drift_curve(t, d, saturation_fraction=saturation_fraction)
    fit_e = fit_drift_curve(t, e, saturation_fraction=saturation_fraction)
    gates = _gates(t, d, min_time_s, max_drift_rate_px_per_s)
    corrected = None
    if fit_d.ok:  # the time-indexed correction of fixes.heating, applied to this very series
        d_corr = HeatingCorrection.from_fit(fit_d).apply(d, time_s=t)
        corrected = round(float(np.nanmax(d_corr) - np.nanmin(d_corr)), 5)
    temps = np.array([np.nan if m.temperature_c is None else m.temperature_c for m in ms])
    temp_corr = None
    if np.isfinite(temps).sum() >= 3:
        temp_corr = HeatingCorrection.from_temperature(temps, d).to_dict()
    d_range = float(np.nanmax(d) - np.nanmin(d))
    fb = rect.f_px * rect.baseline_m
    table1 = [
        {"depth_m": z, "disparity_px": round(fb / z, 4),
         "relative_error_pct": round(100 * d_range / (fb / z), 3)}
        for z in TABLE1_DEPTHS_M
    ]
    rows = [
        {"id": m.id, "time_s": m.time_s, "temperature_c": m.temperature_c, "found": m.found,
         "reason": m.reason, "n_corners": len(m.ids),
         "d_mean_px": None if not np.isfinite(dv) else round(float(dv), 5),
         "e_mean_px": None if not np.isfinite(ev) else round(float(ev), 5), **g}
        for m, dv, ev, g in zip(ms, d, e, gates, strict=True)
    ]
    out: dict[str, Any] = {
        **base, "ok": fit_d.ok, "reason": fit_d.reason,
        "captures_used": len(found), "corners_in_every_capture": len(shared),
        "f_px": rect.f_px, "baseline_m": rect.baseline_m,
        "fit_disparity": fit_d.to_dict(), "fit_nondisparity": fit_e.to_dict(),
        "saturation_time_s": fit_d.saturation_time_s if fit_d.ok else None,
        "disparity_range_px": round(d_range, 5), "corrected_range_px": corrected,
        "gates": {"min_time_s": min_time_s, "max_drift_rate_px_per_s": max_drift_rate_px_per_s},
        "table1": table1, "temperature_correction": temp_corr, "captures": rows,
    }
    truth = _truth(cs.root, ms, shared, rect)
    if truth is not None:
        if truth["tau_s"] is not None and fit_d.ok:
            truth["tau_rel_error"] = round(abs(fit_d.tau_s - truth["tau_s"]) / truth["tau_s"], 5)
        dt = np.asarray(truth["d_mean_px"], dtype=np.float64)
        truth["d_mean_error_px_rms"] = round(float(np.sqrt(np.nanmean((d - dt) ** 2))), 5)
        truth["d_mean_px"] = [round(v, 5) for v in truth["d_mean_px"]]
        out["truth"] = truth
    out["_per_corner_d_px"] = per_corner  # for the figures; dropped from the JSON
    out["seconds"] = seconds_since(t0)
    return out


# --- figures -----------------------------------------------------------------------------------


def _fit_panel(
    ax: Any, t: F64, y: F64, fit: dict[str, Any], label: str, tables: dict[str, Any]
) -> None:
    ax.plot(
        t,
        y,
        "o",
        ms=4,
        color="tab:blue",
        label=f"mean over {tables['corners_in_every_capture']} corners",
    )
    if fit["ok"]:
        f = DriftFit.from_dict(fit)
        tt = np.linspace(0.0, float(np.nanmax(t)), 300)
        ax.plot(
            tt,
            f.value(tt),
            "-",
            color="tab:red",
            label=f"fit: A = {f.amplitude:+.3f} px, τ = {f.tau_s:.1f} ± {f.tau_sigma_s:.2f} s",
        )
        ax.axvline(
            f.saturation_time_s,
            color="tab:green",
            ls="--",
            label=f"{100 * f.saturation_fraction:.0f} % saturated: {f.saturation_time_s:.0f} s",
        )
    ax.axvline(tables["gates"]["min_time_s"], color="0.5", ls=":", label="time gate")
    ax.set_ylabel(f"{label} [px]")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)


def write_figures(table: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write the PNG figures of a heating table into ``out_dir``; returns their paths."""
    t = np.array([r["time_s"] for r in table["captures"]], dtype=np.float64)
    d = np.array([np.nan if r["d_mean_px"] is None else r["d_mean_px"] for r in table["captures"]])
    e = np.array([np.nan if r["e_mean_px"] is None else r["e_mean_px"] for r in table["captures"]])
    files = []
    fig = Figure(figsize=(8, 7), constrained_layout=True)
    a1, a2 = fig.subplots(2, 1, sharex=True)
    _fit_panel(a1, t, d, table["fit_disparity"], "mean disparity d", table)
    a1.set_title("Heating: disparity vs time since camera start (thesis Fig. 3-4)")
    _fit_panel(a2, t, e, table["fit_nondisparity"], "mean non-disparity error e", table)
    a2.set_title("Non-disparity error vs time")
    a2.set_xlabel("time since camera start [s]")
    files.append(_save(fig, out_dir / "heating_drift.png"))
    pc = table.get("_per_corner_d_px")
    if pc is not None and pc.shape[1]:
        fig = Figure(figsize=(8, 4.5), constrained_layout=True)
        ax = fig.subplots()
        pick = np.linspace(0, pc.shape[1] - 1, min(12, pc.shape[1])).astype(int)
        first = np.argmax(np.isfinite(pc[:, 0]))
        for j in pick:
            ax.plot(t, pc[:, j] - pc[first, j], ".-", lw=0.8, ms=3)
        label_axes(
            ax, f"Disparity change of {len(pick)} chart corners vs time (each colour one corner)",
            "time since camera start [s]", "d − d(first capture) [px]",
        )
        files.append(_save(fig, out_dir / "heating_corners.png"))
    temps = np.array(
        [np.nan if r["temperature_c"] is None else r["temperature_c"] for r in table["captures"]]
    )
    if np.isfinite(temps).sum() >= 3:
        fig = Figure(figsize=(7, 4.5), constrained_layout=True)
        ax = fig.subplots()
        ax.plot(temps, d, "o", ms=4)
        corr = table.get("temperature_correction")
        if corr:
            tt = np.linspace(np.nanmin(temps), np.nanmax(temps), 100)
            ax.plot(
                tt, np.polyval(corr["coefficients"], tt), "-", color="tab:red", label="linear fit"
            )
            ax.legend()
        label_axes(ax, "Heating: disparity vs module temperature (thesis Fig. 3-3)",
                   "module temperature [°C]", "mean disparity d [px]")
        files.append(_save(fig, out_dir / "heating_temperature.png"))
    return files


def _summary(tb: dict[str, Any]) -> tuple[str, ...]:
    if "fit_disparity" not in tb:
        return (f"heating: no result: {tb['reason']}",)
    f = tb["fit_disparity"]
    lines = [
        f"heating: {tb['captures_used']}/{tb['captures_total']} captures, "
        f"{tb['corners_in_every_capture']} corners in every capture ({tb['seconds']} s)"
    ]
    if f["ok"]:
        lines.append(
            f"disparity drift A = {f['amplitude']:+.3f} px, τ = {f['tau_s']:.1f} ± "
            f"{f['tau_sigma_s']:.2f} s, {100 * f['saturation_fraction']:.0f} % saturated "
            f"after {f['saturation_time_s']:.0f} s"
        )
    else:
        lines.append(f"disparity drift: no fit: {f['reason']}")
    caps = tb["captures"]
    for key in ("time_gate", "rate_gate"):
        passed = [c["time_s"] for c in caps if c[key]]
        first = f"first passed at {min(passed):.0f} s" if passed else "none passed"
        lines.append(f"{key}: {len(passed)}/{len(caps)} passed, {first}")
    lines.append(
        "Table 1: "
        + ", ".join(f"{r['depth_m']} m → {r['relative_error_pct']:.1f} %" for r in tb["table1"])
    )
    if "truth" in tb and tb["truth"].get("tau_rel_error") is not None:
        tr = tb["truth"]
        lines.append(f"truth: τ = {tr['tau_s']} s (error {100 * tr['tau_rel_error']:.1f} %)")
    return tuple(lines)


def run(capture_set: Path, out_dir: Path, progress: Progress | None = None) -> AnalysisOutput:
    """Registry entry: analyse, write ``heating.json`` and the figures into ``out_dir``."""
    tb = analyze_heating(capture_set, progress=progress)
    files = write_figures(tb, out_dir) if "fit_disparity" in tb else []
    return write_output("heating", tb, files, _summary(tb), out_dir)
