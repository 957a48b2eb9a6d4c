"""Where a rendered set's verification error comes from: the matcher, or what the fixes must do.

For every verification capture of a set with ``ground_truth.json``, the application's measuring
blocks (:func:`~phonestereo.flows.roi_disparity.measure_roi`, factory calibration) are run
twice — without and with the W-T scale — and compared at the chart's true corners inside the
ROI with two oracles:

- **matcher error** (px): the measured disparity plane (no W-T scale) minus the disparity of
  the corners' *true* image positions through the same factory rectification. It is what a
  perfect matcher would not have: the per-capture error of the measurement itself.
- **needed correction** (px): the disparity that gives the true depth along each corner's ray
  minus the measured plane (W-T scale on): what the learned correction has to supply. Across
  the captures of one module it should be smooth in disparity and sensor position; jumps from
  capture to capture are the matcher's, not the geometry's.

Plus the blur the equalisation added and the matches on the plane. This is how the periscope
failure of issue #18 was found: on random-1000 the matcher error jumped between −1.09 and
+0.85 px while the needed correction was −2.0 … −2.4 px on every capture (the blur
equalisation compared a misaligned pair and blurred the wide by 2.4–3 px).

Run: ``.venv/bin/python benchmarks/bench_oracle.py SET [--capture V01] [--json]`` on a set written
by ``phonestereo bench modules --keep-images`` (``OUT/work/seed-N/set``) or ``phonestereo demo``.
"""

from __future__ import annotations

import argparse
import json
from typing import Any

import numpy as np

from phonestereo.flows.config import FlowConfig
from phonestereo.flows.roi_disparity import measure_roi, reference_rectification
from phonestereo.io import load_calibration, load_capture_set, read_gray
from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth


def decompose(set_dir: str, prefixes: tuple[str, ...] = ()) -> list[dict[str, Any]]:
    """One row per verification capture (module docstring); gated captures carry the reason."""
    cs = load_capture_set(set_dir)
    cal = load_calibration(cs.calibration_path())
    gt = load_ground_truth(cs.root / GROUND_TRUTH_NAME)
    cfg = FlowConfig()
    ref = reference_rectification(cal.rig, cfg.mode)
    rows = []
    for c in cs.captures():
        if c.kind != "verification" or c.roi is None or (
                prefixes and not c.id.startswith(prefixes)):
            continue
        truth = gt.capture(c.id)
        kp = truth.objects[0].keypoints["corners"].arrays()
        x, y, w, h = c.roi
        qw, qt, z = kp.wide_px, kp.tele_px, kp.depth_m
        inside = (np.isfinite(qw).all(1) & np.isfinite(qt).all(1) & (qw[:, 0] >= x)
                  & (qw[:, 0] <= x + w) & (qw[:, 1] >= y) & (qw[:, 1] <= y + h))
        row: dict[str, Any] = {"capture_id": c.id, "z_true_m": float(np.median(z[inside]))
                               if inside.any() else None, "corners": int(inside.sum())}
        wide, tele = (read_gray(p) for p in cs.image_paths(c.id))
        raw, scaled = (measure_roi(cal.rig, wide, tele, c.roi, cfg.roi, ref, mode=cfg.mode,
                                   wt_scale=s) for s in (False, True))
        if not (raw.ok and scaled.ok and raw.plane and scaled.plane) or not inside.any():
            row["reason"] = raw.reason or scaled.reason or "no chart corner inside the ROI"
            rows.append(row)
            continue
        q = ref.points_wide(qw[inside])
        d_true, _ = ref.disparity(qw[inside], qt[inside])
        d_raw, sd_raw = raw.plane.predict(q)
        d_wt = scaled.plane.predict(q)[0]
        z_wt = ref.backproject(q, d_wt)[:, 2]
        need = d_wt * z_wt / z[inside] - d_wt  # Z ∝ 1/d along a ray
        row.update({
            "matcher_error_px": round(float(np.median(d_raw - d_true)), 4),
            "needed_correction_px": round(float(np.median(need)), 4),
            "disparity_px": round(float(np.median(d_wt)), 3),
            "blur_added_px": raw.counts.get("blur_added_x100", 0) / 100,
            "matches": raw.counts.get("plane", 0),
            "sigma_plane_px": round(float(np.median(sd_raw)), 4),
            "e_median_px": round(float(np.median(raw.e)), 3),
            "scatter_px": round(float(raw.plane.scatter_px), 4),
            "wt_scale": None if scaled.wt is None else round(float(scaled.wt.scale), 5),
        })
        rows.append(row)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("set_dir")
    ap.add_argument("--capture", action="append", default=[], help="capture id prefix")
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args()
    rows = decompose(a.set_dir, tuple(a.capture))
    if a.json:
        print(json.dumps(rows, indent=1))
        return
    print(f"{'capture':8} {'Z m':>6} {'d px':>7} {'matcher px':>10} {'needed px':>9} "
          f"{'blur':>5} {'n':>4} {'σ_d':>6} {'e':>6}")
    for r in rows:
        if "reason" in r:
            print(f"{r['capture_id']:8} gated: {r['reason'][:90]}")
            continue
        print(f"{r['capture_id']:8} {r['z_true_m']:6.3f} {r['disparity_px']:7.2f} "
              f"{r['matcher_error_px']:+10.3f} {r['needed_correction_px']:+9.3f} "
              f"{r['blur_added_px']:5.2f} {r['matches']:4d} {r['sigma_plane_px']:6.3f} "
              f"{r['e_median_px']:+6.2f}")
    ok = [r for r in rows if "reason" not in r]
    if len(ok) > 1:
        m = np.array([r["matcher_error_px"] for r in ok])
        n = np.array([r["needed_correction_px"] for r in ok])
        s = np.array([r["sigma_plane_px"] for r in ok])
        print(f"matcher error: median {np.median(m):+.3f} px, spread (SD) {m.std(ddof=1):.3f} px"
              f" against the plane's σ_d (RMS) {np.sqrt(np.mean(s**2)):.3f} px;"
              f" needed correction: SD {n.std(ddof=1):.3f} px over {len(ok)} captures")


if __name__ == "__main__":
    main()
