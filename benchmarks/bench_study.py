"""Tolerance-study benchmark (issue #8): Dask scaling, per-sample cost, stability of the ranking.

Scaling: the same study samples (analytic bench, folded-x3, the shipped tolerances) run on a
LocalCluster of 1 worker and of 2 workers (one thread each); throughput = samples / wall time
from the first submit to the last record written (cluster start excluded, workers warmed up
first). Acceptance: 2 workers vs 1 ≥ 1.7× on this 2-core machine.

Per-sample cost: serial, in-process, seconds per sample (draw + module validation + bench).
Projection for 10,000 samples on a 100-core cluster: 10,000 × cost / (100 × efficiency), with
the parallel efficiency measured here (ratio / 2).

Stability: a 200-sample study with two seeds; the top three tolerances must be the same set.

Run: ``.venv/bin/python benchmarks/bench_study.py [--samples 120] [--study 200] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from pathlib import Path
from typing import Any

from phonestereo.evaluation.runner import dask_client, run_tasks
from phonestereo.evaluation.study import StudyConfig, run_study, study_sample
from phonestereo.evaluation.study_bench import AnalyticBenchConfig
from phonestereo.evaluation.tolerances import load_tolerances
from phonestereo.sim.module import load_module

TOLERANCES = Path(__file__).parents[1] / "src/phonestereo/evaluation/data/tolerances-folded-x3.json"


def _tasks(spec: Any, tol: Any, seed: int, n: int, offset: int = 0) -> dict[str, Any]:
    cfg = AnalyticBenchConfig()
    return {
        f"s{i:06d}": (study_sample, (spec, tol, seed, i, "analytic", cfg))
        for i in range(offset, offset + n)
    }


def _throughput(spec: Any, tol: Any, workers: int, n: int) -> dict[str, float]:
    with dask_client(None, workers) as client, tempfile.TemporaryDirectory() as tmp:
        run_tasks(_tasks(spec, tol, 99, 4 * workers), Path(tmp) / "warm", client=client)
        t0 = time.perf_counter()
        records, _ = run_tasks(_tasks(spec, tol, 0, n), Path(tmp) / "run", client=client)
        wall = time.perf_counter() - t0
    assert all(r["status"] == "ok" for r in records.values())
    return {"workers": workers, "samples": n, "wall_s": wall, "samples_per_s": n / wall}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--samples", type=int, default=120, help="samples per scaling run")
    ap.add_argument("--study", type=int, default=200, help="samples of the stability study")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    spec = load_module("folded-x3")
    tol = load_tolerances(TOLERANCES, spec)

    with tempfile.TemporaryDirectory() as tmp:
        run_tasks(_tasks(spec, tol, 98, 3), Path(tmp) / "warm")
        t0 = time.perf_counter()
        run_tasks(_tasks(spec, tol, 0, 30), Path(tmp) / "serial")
        per_sample = (time.perf_counter() - t0) / 30

    one = _throughput(spec, tol, 1, args.samples)
    two = _throughput(spec, tol, 2, args.samples)
    ratio = two["samples_per_s"] / one["samples_per_s"]
    efficiency = ratio / 2
    projection_s = 10_000 * per_sample / (100 * efficiency)
    # the same with the cost per sample seen through one Dask worker (scheduler, transfer and
    # record writing included, and whatever else loads this shared machine)
    per_sample_dask = one["wall_s"] / one["samples"]
    projection_dask_s = 10_000 * per_sample_dask / (100 * efficiency)

    studies: dict[int, dict[str, Any]] = {}
    with dask_client(None, 2) as client:
        for seed in (0, 1):
            with tempfile.TemporaryDirectory() as tmp:
                res = run_study(spec, tol, tmp, StudyConfig(args.study, seed=seed), client=client)
            studies[seed] = {
                "top3": list(res.top[:3]),
                "share_top3": [round(s.share_of_variance, 3) for s in res.sensitivities[:3]],
                "coef_top3_pp": [round(100 * s.coefficient, 2) for s in res.sensitivities[:3]],
                "r_squared": round(res.r_squared, 3),
                "mean_median_rel_err": round(res.metric_mean, 4),
                "seconds": round(res.seconds, 1),
            }
    stable = set(studies[0]["top3"]) == set(studies[1]["top3"])
    report = {
        "per_sample_s_serial": round(per_sample, 4),
        "one_worker": one,
        "two_workers": two,
        "speedup_2_vs_1": round(ratio, 3),
        "speedup_ok": ratio >= 1.7,
        "per_sample_s_one_worker": round(per_sample_dask, 4),
        "projection_10000_samples_100_cores_s": round(projection_s, 1),
        "projection_10000_samples_100_cores_s_dask_cost": round(projection_dask_s, 1),
        "load_average_1min_at_end": round(os.getloadavg()[0], 2),
        "study": studies,
        "top3_stable": stable,
    }
    if args.json:
        print(json.dumps(report, indent=1))
        return
    print(f"per sample (serial, in-process): {1000 * per_sample:.1f} ms")
    print(f"1 worker : {one['samples_per_s']:.2f} samples/s ({one['wall_s']:.1f} s)")
    print(f"2 workers: {two['samples_per_s']:.2f} samples/s ({two['wall_s']:.1f} s)")
    print(f"speed-up 2 vs 1: {ratio:.2f}x (target >= 1.7x) -> {'ok' if ratio >= 1.7 else 'LOW'}")
    print(
        f"projection: 10,000 samples on 100 cores ≈ {projection_s:.0f} s from the serial cost, "
        f"{projection_dask_s:.0f} s from the one-worker cost (efficiency {efficiency:.2f})"
    )
    print(f"load average (1 min) at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    for seed, s in studies.items():
        print(f"study seed {seed}: top3 {s['top3']} shares {s['share_top3']} R² {s['r_squared']}")
    print(f"top three stable between seeds: {stable}")


if __name__ == "__main__":
    main()
