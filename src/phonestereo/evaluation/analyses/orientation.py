"""Orientation analysis (thesis §3.4, Figure 3-11): the disparity offset between orientations.

A static verification chart on a tripod, heated module, captured in two (or more) device
orientations — the thesis's landscape stack and the same scene flipped by 180°. Each capture
is bucketed from its gravity vector (:func:`~phonestereo.fixes.orientation.orientation_bucket`),
the chart corners are measured with the chart ruler (canonical rectification of the set's
calibration) and, per corner seen in every capture, the disparity is compared with the same
corner's mean disparity in the reference bucket (``landscape``, the calibration orientation,
when present). :class:`~phonestereo.fixes.orientation.OrientationOffsets` fitted on those
samples gives the per-bucket offset of Figure 3-11 with its 1σ.

When the set has a ``ground_truth.json`` (simulated), two more things are reported:

- the *absolute* per-bucket offsets, with the expected disparity f·B/Z of each corner from its
  true depth (f, B and the rectified Z from the calibration's canonical rectification) — what
  the learning flow would learn from known depths — fitted once from the detected corners and
  once from the true corner pixels;
- the same relative offsets computed from the true corner pixels, and the errors of both.

Outputs in ``out_dir``: ``orientation.json``, ``orientation_disparity.png`` (per-corner
disparity of every capture coloured by bucket, and the per-bucket offsets) and
``orientation_map.png`` (the offset per corner over the wide image, one panel per bucket).
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
    run_table,
    seconds_since,
)
from phonestereo.evaluation.analyses._common import save_figure as _save
from phonestereo.evaluation.chart_ruler import (
    CaptureMeasurement,
    corner_keys,
    measure_capture,
    per_corner,
    shared_keys,
)
from phonestereo.fixes.orientation import OrientationOffsets, capture_bucket
from phonestereo.io import CaptureEntry, CaptureSet
from phonestereo.rectification import Rectification

F64 = np.ndarray
MIN_SHARED = 8  # fewest corners seen in every capture


def _check_needs(cs: CaptureSet) -> tuple[list[CaptureEntry], list[str]]:
    caps = [c for c in cs.captures() if c.kind == "verification"]
    buckets = [capture_bucket(c.gravity, c.orientation) for c in caps]
    if len(set(buckets)) < 2:
        raise InputError(
            "the orientation analysis needs 'verification' captures of one static chart (tripod, "
            "heated) in >= 2 device orientations, each with 'gravity' or an orientation label "
            f"(e.g. `phonestereo simulate orientation`); {cs.root} has {len(caps)} verification "
            f"capture(s) in {len(set(buckets))} orientation(s) {sorted(set(buckets))}"
        )
    return caps, buckets


def _reference(buckets: list[str]) -> str:
    return "landscape" if "landscape" in buckets else buckets[0]


def _relative_samples(table: F64, buckets: list[str], ref: str) -> tuple[F64, F64, list[str]]:
    """One (d_measured, d_expected, bucket) sample per capture: its mean over the corners vs the
    same corners' mean in the reference bucket (per-corner differences are not independent: a
    flip mirrors the sensor positions, so calibration errors cancel only in the mean)."""
    rows = np.array([b == ref for b in buckets])
    d_ref = np.nanmean(table[rows], axis=0)
    return np.nanmean(table, axis=1), np.full(len(buckets), float(np.nanmean(d_ref))), buckets


def _expected_true(root: Path, ms: list[CaptureMeasurement], keys: F64, rect: Rectification) -> Any:
    """Sim only: per capture and corner, d from the true pixels and f·B/Z_rect from true depth."""
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    if not (root / GROUND_TRUTH_NAME).is_file():
        return None
    gt = load_ground_truth(root / GROUND_TRUTH_NAME)
    d_true = np.full((len(ms), len(keys)), np.nan)
    d_exp = np.full((len(ms), len(keys)), np.nan)
    for i, m in enumerate(ms):
        ct = gt.capture(m.id)
        kp = ct.objects[0].keypoints["corners"].arrays()
        kk = corner_keys(kp.ids)
        _, ia, ib = np.intersect1d(keys, kk, return_indices=True)
        d, _ = rect.disparity(kp.wide_px[ib], kp.tele_px[ib])
        p_wide = ct.wide.true_camera().unproject(kp.wide_px[ib]) * kp.depth_m[ib, None]
        z_rect = (p_wide @ rect.R_rect_wide.T)[:, 2]
        d_true[i, ia] = d
        d_exp[i, ia] = rect.f_px * rect.baseline_m / z_rect
    return d_true, d_exp


def _offsets_rows(fit: OrientationOffsets) -> dict[str, Any]:
    return {k: v.to_dict() for k, v in fit.offsets.items()}


@canonical_analysis(lacking="without verification captures in two orientations")
def analyze_orientation(opened: OpenedSet, *, progress: Progress | None = None) -> dict[str, Any]:
    """Measure the per-orientation disparity offset of a capture set (see module docstring)."""
    t0, cs, _, rect = opened
    caps, buckets = _check_needs(cs)
    ms = measure_each(caps, lambda c: measure_capture(cs, c, rect), progress)
    base = {"analysis": "orientation", "capture_set": str(cs.root), "captures_total": len(ms)}
    keep = [i for i, m in enumerate(ms) if m.found]
    ms_ok, bk_ok = [ms[i] for i in keep], [buckets[i] for i in keep]
    keys = shared_keys(ms_ok)
    if len(set(bk_ok)) < 2 or len(keys) < MIN_SHARED:
        why = "; ".join(f"{m.id}: {m.reason}" for m in ms if not m.found)[:600]
        return {**base, "ok": False,
                "reason": f"chart measured in {len(ms_ok)} captures over {len(set(bk_ok))} "
                          f"orientation(s), {len(keys)} corners in every one; {why}"}
    ref = _reference(bk_ok)
    table = per_corner(ms_ok, keys)
    dm, de, bk = _relative_samples(table, bk_ok, ref)
    rel = OrientationOffsets.fit(bk, dm, de)
    rows = [
        {"id": m.id, "bucket": b, "gravity": None if c.gravity is None else list(c.gravity),
         "found": m.found, "reason": m.reason, "n_corners": len(m.ids),
         "d_mean_px": round(float(np.mean(m.d_px)), 5) if m.found else None}
        for m, b, c in zip(ms, buckets, caps, strict=True)
    ]
    out: dict[str, Any] = {
        **base, "ok": True, "reason": "", "reference_bucket": ref,
        "captures_used": len(ms_ok), "corners_in_every_capture": len(keys),
        "f_px": rect.f_px, "baseline_m": rect.baseline_m,
        "offsets_relative": _offsets_rows(rel), "captures": rows,
    }
    truth = _expected_true(cs.root, ms_ok, keys, rect)
    if truth is not None:
        d_true, d_exp = truth
        e_mean = np.nanmean(d_exp, axis=1)
        abs_meas = OrientationOffsets.fit(bk_ok, np.nanmean(table, axis=1), e_mean)
        abs_true = OrientationOffsets.fit(bk_ok, np.nanmean(d_true, axis=1), e_mean)
        tm, te, tb = _relative_samples(d_true, bk_ok, ref)
        rel_true = OrientationOffsets.fit(tb, tm, te)
        err_abs = {k: abs(abs_meas.offsets[k].offset_px - abs_true.offsets[k].offset_px)
                   for k in abs_true.offsets}
        err_rel = {k: abs(rel.offsets[k].offset_px - rel_true.offsets[k].offset_px)
                   for k in rel_true.offsets}
        out["offsets_absolute"] = _offsets_rows(abs_meas)
        out["truth"] = {
            "offsets_absolute": _offsets_rows(abs_true),
            "offsets_relative": _offsets_rows(rel_true),
            "absolute_error_px": {k: round(v, 5) for k, v in err_abs.items()},
            "relative_error_px": {k: round(v, 5) for k, v in err_rel.items()},
            "max_error_px": round(max([*err_abs.values(), *err_rel.values()]), 5),
        }
    out["_table"] = table
    out["_q_wide"] = [m.q_wide[np.isin(corner_keys(m.ids), keys)] for m in ms_ok]
    out["_buckets"] = bk_ok
    out["seconds"] = seconds_since(t0)
    return out


# --- figures -----------------------------------------------------------------------------------
_COLOURS = ("tab:blue", "tab:red", "tab:green", "tab:orange", "tab:purple", "tab:brown")


def write_figures(tb: dict[str, Any], out_dir: Path) -> list[Path]:
    """Write the PNG figures of an orientation table into ``out_dir``; returns their paths."""
    table, bks, ref = tb["_table"], tb["_buckets"], tb["reference_bucket"]
    names = list(dict.fromkeys(bks))
    colour = {b: _COLOURS[i % len(_COLOURS)] for i, b in enumerate(names)}
    files = []
    fig = Figure(figsize=(9, 7.5), constrained_layout=True)
    a1, a2 = fig.subplots(2, 1)
    idx = np.arange(table.shape[1])
    seen: set[str] = set()
    for row, b in zip(table, bks, strict=True):
        a1.plot(idx, row, ".-", lw=0.6, ms=2, color=colour[b], label=None if b in seen else b)
        seen.add(b)
    label_axes(a1, "Disparity of every chart corner per capture, by orientation (thesis Fig. 3-11)",
               "chart corner (row-major order of the corners seen in every capture)",
               "disparity d [px]", legend_fontsize=8)
    rel = tb["offsets_relative"]
    x = np.arange(len(names))
    vals = [rel[b]["offset_px"] for b in names]
    sig = [rel[b]["sigma_px"] or 0.0 for b in names]
    a2.bar(x, vals, yerr=sig, color=[colour[b] for b in names], capsize=4,
           label="measured (chart corners)")
    if "truth" in tb:
        tr = tb["truth"]["offsets_relative"]
        a2.plot(x, [tr[b]["offset_px"] for b in names], "k_", ms=30, mew=2, label="truth")
    a2.set_xticks(x, names)
    a2.axhline(0.0, color="0.4", lw=0.8)
    a2.set_ylabel(f"offset vs {ref} [px]")
    a2.set_title(f"Per-orientation disparity offset relative to {ref} (mean ± 1σ)")
    a2.grid(alpha=0.3, axis="y")
    a2.legend(fontsize=8)
    files.append(_save(fig, out_dir / "orientation_disparity.png"))
    others = [b for b in names if b != ref]
    rows_ref = np.array([b == ref for b in bks])
    d_ref = np.nanmean(table[rows_ref], axis=0)
    fig = Figure(figsize=(5.5 * len(others), 4.8), constrained_layout=True)
    axes = np.atleast_1d(fig.subplots(1, len(others)))
    for ax, b in zip(axes, others, strict=True):
        i = bks.index(b)
        rows = np.array([x == b for x in bks])
        delta = np.nanmean(table[rows], axis=0) - d_ref
        q = tb["_q_wide"][i]
        sc = ax.scatter(q[:, 0], q[:, 1], c=delta, s=14, cmap="coolwarm")
        fig.colorbar(sc, ax=ax, label=f"d({b}) − d({ref}) [px]")
        ax.set_title(f"Offset per corner, {b} vs {ref}")
        ax.set_xlabel(f"corner x in the wide image ({b} capture) [px]")
        ax.set_ylabel("y [px]")
        ax.invert_yaxis()
        ax.set_aspect("equal")
    files.append(_save(fig, out_dir / "orientation_map.png"))
    return files


def _summary(tb: dict[str, Any]) -> tuple[str, ...]:
    """The summary lines of an ok table (:func:`run_table` words the others)."""
    lines = [
        f"orientation: {tb['captures_used']}/{tb['captures_total']} captures, "
        f"{tb['corners_in_every_capture']} corners in every capture ({tb['seconds']} s)"
    ]
    for k, v in tb["offsets_relative"].items():
        if k != tb["reference_bucket"]:
            sig = "n/a" if v["sigma_px"] is None else f"{v['sigma_px']:.4f}"
            n = f"{v['n']} capture" + ("s" if v["n"] != 1 else "")
            lines.append(
                f"{k}: offset {v['offset_px']:+.4f} px ± {sig} vs {tb['reference_bucket']} ({n})"
            )
    if "truth" in tb:
        lines.append(f"truth: largest offset error {tb['truth']['max_error_px']:.4f} px")
    return tuple(lines)


def run(capture_set: Path, out_dir: Path, progress: Progress | None = None) -> AnalysisOutput:
    """Registry entry: analyse, write ``orientation.json`` and the figures into ``out_dir``."""
    return run_table(
        "orientation", analyze_orientation, write_figures, _summary, capture_set, out_dir, progress
    )
