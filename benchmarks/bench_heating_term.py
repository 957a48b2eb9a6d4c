"""The learned heating term on a rendered capture set: the same learning, applied with and
without ``FlowConfig.heating_by_temperature`` (issue #18 items 3 and 4).

The set is learned once (the learning flow does not depend on the switch); each variant then
builds its :class:`~phonestereo.flows.corrector.Corrector` from the same observations and runs
the application flow on every verification capture. Per capture: the relative error against
the ground truth, σ, |error|/σ and the σ parts of the correction (px); per variant: full-flow
median and p90 |relative error|, within-σ, captures measured, the largest |error|/σ and the
learned heating term (slope px/°C ± σ, or the time-indexed σ when no temperature is reported).

Run: ``.venv/bin/python benchmarks/bench_heating_term.py SET [--json]`` on a set written by
``phonestereo bench modules --keep-images`` (``OUT/work/seed-N/set``) or ``phonestereo demo``.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from typing import Any

import numpy as np

from phonestereo.evaluation.bench import apply_all
from phonestereo.flows import learning
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.corrector import Corrector
from phonestereo.flows.learning import default_backend
from phonestereo.io import load_calibration, load_capture_set
from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth


def run(set_dir: str) -> dict[str, Any]:
    """Learn once, apply with the heating term on and off; the scores (module docstring)."""
    cs = load_capture_set(set_dir)
    gt = load_ground_truth(cs.root / GROUND_TRUTH_NAME)
    cfg = FlowConfig()
    cal = load_calibration(cs.calibration_path())
    lr = learning.run(cfg, cs, cal, None, backend=default_backend())
    obs = [o for c in lr.captures for o in c.observations]
    out: dict[str, Any] = {"set": set_dir, "observations": len(obs), "variants": {}}
    for name, vc in (("heating_by_temperature", cfg),
                     ("without", replace(cfg, heating_by_temperature=False))):
        corr = Corrector(obs, vc)
        rows = []
        for r in apply_all(vc, cs, corr):
            z_true = gt.capture(r.capture_id).roi_depth_m
            row: dict[str, Any] = {"capture_id": r.capture_id, "ok": r.ok, "gate": r.gate}
            if r.ok and z_true:
                row.update(z_true_m=round(z_true, 4), rel_err=round(r.depth_m / z_true - 1, 6),
                           rel_sigma=round(r.sigma_m / z_true, 6),
                           z=round((r.depth_m - z_true) / r.sigma_m, 3),
                           sigma_px=r.stages.get("sigma_px", {}))
            rows.append(row)
        ok = [r for r in rows if "rel_err" in r]
        err = np.abs([r["rel_err"] for r in ok])
        zs = np.abs([r["z"] for r in ok])
        out["variants"][name] = {
            "heating": corr.heating.to_dict(), "heating_time": corr.heating_time.to_dict(),
            "median_rel_err": round(float(np.median(err)), 5) if ok else None,
            "p90_rel_err": round(float(np.percentile(err, 90)), 5) if ok else None,
            "within_sigma": round(float(np.mean(zs <= 1)), 4) if ok else None,
            "measured": len(ok), "captures": len(rows),
            "max_abs_err_over_sigma": round(float(zs.max()), 3) if ok else None,
            "over_4_sigma": int(np.sum(zs > 4)), "rows": rows,
        }
    return out


def _print(res: dict[str, Any]) -> None:
    print(f"{res['set']}: {res['observations']} learned observations")
    for name, v in res["variants"].items():
        h = v["heating"] if v["heating"]["ok"] else v["heating_time"]
        term = (f"{h['index']} slope {h['slope_px_per_c']:+.4g} ± {h['slope_sigma']:.2g} px"
                if h["ok"] else f"no term ({h['reason']})")
        print(f"\n{name}: {term}")
        for r in v["rows"]:
            if "rel_err" not in r:
                print(f"  {r['capture_id']:8s} gated {r['gate']}")
                continue
            parts = " ".join(f"{k.removeprefix('correction_')}={val}"
                             for k, val in r["sigma_px"].items() if k.startswith("correction_"))
            print(f"  {r['capture_id']:8s} Z {r['z_true_m']:5.2f} m  "
                  f"err {100 * r['rel_err']:+6.2f} %  σ {100 * r['rel_sigma']:5.2f} %  "
                  f"err/σ {r['z']:+5.2f}   σ parts px: {parts}")
        print(f"  median {100 * v['median_rel_err']:.2f} %  p90 {100 * v['p90_rel_err']:.2f} %  "
              f"within σ {100 * v['within_sigma']:.0f} %  measured {v['measured']}/"
              f"{v['captures']}  max |err|/σ {v['max_abs_err_over_sigma']}  "
              f"> 4σ {v['over_4_sigma']}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("set", help="a rendered capture set with ground_truth.json and images")
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    args = ap.parse_args()
    res = run(args.set)
    print(json.dumps(res)) if args.json else _print(res)


if __name__ == "__main__":
    main()
