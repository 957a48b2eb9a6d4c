"""The learned correction's common-mode error, piece by piece, by ground-truth oracles (issue #18).

A rendered capture set (``bench modules --keep-images``, ``demo --out``) is learned and applied
with the product's flows (``flows.learning.run``, ``flows.application.run``, default
``FlowConfig``), with some of its measurements replaced by the truth of ``ground_truth.json``.
What a replacement removes from the set's mean depth error is that piece's share of the common
mode. Flags (combine them, ``-`` for none):

- ``R``: the IPD ruler: each face observation's expected disparity is the one the product's own
  back-projection turns into the face's true depth (times the wide's true focal scale, which the
  ruler carries by design and the wide-breathing fix removes).
- ``F``: the faces' disparities: each eye's disparity is its true correspondence, rectified and
  put through the capture's own W-T fix.
- ``C``: the chart's disparities: every ROI match likewise, and the ROI's plane refitted.
- ``Q``: the flows' ``radial_residual`` knob on (thesis §3.2's non-disparity-axis fix,
  :mod:`~phonestereo.fixes.radial_residual`); with F or C the oracle disparities get its
  correction too (the truth's rectified positions carry the lens residual it removes).
  Without ``Q`` the knob is off, so ``Q`` alone (not ``-``) is the product's default flow,
  which is what ``phonestereo evaluate`` reports.

The verification captures' focus stacks are applied as ``evaluate`` applies them.

Ground truth is read here only: this is a diagnosis, not the product. The monkeypatches are
undone after each run.

Run: ``.venv/bin/python benchmarks/bench_common_mode.py SET [--flags - R RF RFC Q] [--json]``
(~1 min per flag set on 2 cores).
"""

from __future__ import annotations

import argparse
import json
from contextlib import ExitStack
from dataclasses import replace
from typing import Any
from unittest import mock

import numpy as np

import phonestereo.flows.learning as learning
from phonestereo.fixes.radial_residual import radial_shift
from phonestereo.fixes.wt_scale import WTScale
from phonestereo.flows import application
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.corrector import Corrector
from phonestereo.flows.roi_disparity import fit_plane, reference_rectification
from phonestereo.geometry import Transform
from phonestereo.io import load_calibration, load_capture_set, read_gray
from phonestereo.sim.ground_truth import load_ground_truth


def true_tele(g: Any, wide_px: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """True tele pixels (N, 2) and wide-frame depths (N,) of raw wide pixels on the capture's
    first object (a plane: the chart)."""
    rig = g.true_rig()
    T_dc = Transform.from_dict(g.T_world_device).inverse() @ Transform.from_dict(
        g.objects[0].T_world_chart
    )
    R, t = T_dc.matrix[:3, :3], T_dc.matrix[:3, 3]
    n = R[:, 2]
    ray = rig.wide.unproject(wide_px)
    X = ray * ((n @ t) / (ray @ n))[:, None]
    Tt = rig.T_tele_wide.matrix
    return rig.tele.project(X @ Tt[:3, :3].T + Tt[:3, 3]), X[:, 2]


def run_flags(set_dir: str, flags: str) -> dict[str, Any]:
    """Learn and apply ``set_dir`` with the oracles of ``flags``; the depth errors' summary."""
    cs = load_capture_set(set_dir)
    cal = load_calibration(cs.calibration_path())
    gt = load_ground_truth(cs.root / "ground_truth.json")
    cfg = FlowConfig(radial_residual="Q" in flags)
    ref = reference_rectification(cal.rig, cfg.mode)
    current: dict[str, Any] = {}

    def d_true(g: Any, xy: np.ndarray, wt: WTScale) -> tuple[np.ndarray, np.ndarray]:
        tp, z = true_tele(g, ref.unrectify_wide(xy))
        qt = ref.points_tele(tp)
        return np.asarray(wt.correct_disparity(xy[:, 0], xy[:, 0] - qt[:, 0])), z

    base_learn, base_apply_measure = learning.learn_face_capture, application.measure_roi

    def learn(config: Any, cs_: Any, entry: Any, calibration: Any, backend: Any, **kw: Any) -> Any:
        r = base_learn(config, cs_, entry, calibration, backend, **kw)
        if not r.observations:
            return r
        g = gt.capture(entry.id)
        s = r.stages["wt_scale"]
        wt = WTScale(s["scale"], s["offset_px"], np.array(s["center_px"]))
        q = np.array([[o.x_px, o.y_px] for o in r.observations])
        dm = np.array([o.d_measured_px for o in r.observations])
        dt, z = d_true(g, q, wt)
        if "F" in flags:
            dm = dt if r.radial is None else dt - radial_shift(r.radial, q)[:, 0]
        de = np.array([o.d_expected_px for o in r.observations])
        if "R" in flags:
            zr = ref.backproject(q, dm)[:, 2]
            de = dm * zr / z * g.wide.focal_scale
        obs = tuple(
            replace(o, d_measured_px=float(a), d_expected_px=float(b))
            for o, a, b in zip(r.observations, dm, de, strict=True)
        )
        return replace(r, observations=obs)

    def measure_in_application(*a: Any, **k: Any) -> Any:
        m = base_apply_measure(*a, **k)
        if not (m.ok and m.wt is not None and m.wt.ok) or "C" not in flags:
            return m
        d, _ = d_true(gt.capture(current["id"]), m.xy, m.wt)
        if k.get("radial") is not None:
            d = d - radial_shift(k["radial"], m.xy)[:, 0]
        return replace(m, d=d, plane=fit_plane(m.xy, d, m.sigma_d))

    with ExitStack() as stack:
        stack.enter_context(mock.patch.object(learning, "learn_face_capture", learn))
        stack.enter_context(
            mock.patch.object(application, "measure_roi", measure_in_application)
        )
        lr = learning.run(cfg, cs, cal, None)
        corr = Corrector.for_calibration([o for c in lr.captures for o in c.observations], cfg,
                                         cal, radial_fits=[c.radial for c in lr.captures])
        err, z_score, rows = [], [], []
        ver = [c for c in cs.captures() if c.kind == "verification"]
        focus = learning.stack_corrections(cfg, cs, ver, cal)  # as evaluate's apply_all does
        for entry in ver:
            current["id"] = entry.id
            wide, tele = (read_gray(p) for p in cs.image_paths(entry.id))
            r = application.run(cfg, application.ApplicationInputs(
                cal, entry, wide, tele, corr, focus=focus.get(entry.id), reference=ref
            ))
            z_true = gt.capture(entry.id).roi_depth_m
            if not r.ok or z_true is None:
                continue
            err.append(r.depth_m / z_true - 1)
            z_score.append(abs(r.depth_m - z_true) / r.sigma_m)
            rows.append({"capture_id": entry.id, "z_true_m": z_true, "rel_err": err[-1],
                         "rel_sigma": r.sigma_m / z_true})
    e, zs = np.array(err), np.array(z_score)
    return {
        "flags": flags, "n": len(e), "mean_rel_err": float(e.mean()), "sd_rel_err": float(e.std()),
        "median_abs_rel_err": float(np.median(np.abs(e))), "within_sigma": float(np.mean(zs <= 1)),
        "captures": rows,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("set", help="a rendered capture set with ground_truth.json")
    ap.add_argument("--flags", nargs="+", default=["-", "R", "RF", "RFC"],
                    help="oracles (R ruler, F faces' d, C chart's d; Q the radial fix on)")
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    args = ap.parse_args()
    rows = [run_flags(args.set, "" if f == "-" else f) for f in args.flags]
    if args.json:
        print(json.dumps({"set": args.set, "rows": rows}, indent=1))
        return
    print(f"{'oracles':8s} {'mean':>8s} {'sd':>7s} {'median|e|':>10s} {'within σ':>9s}  n")
    for r in rows:
        print(f"{r['flags'] or '-':8s} {100 * r['mean_rel_err']:+7.2f}%"
              f" {100 * r['sd_rel_err']:6.2f}% {100 * r['median_abs_rel_err']:9.2f}%"
              f" {100 * r['within_sigma']:8.0f}%  {r['n']}")


if __name__ == "__main__":
    main()
