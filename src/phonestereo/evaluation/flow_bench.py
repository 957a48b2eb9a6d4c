"""The full Phase 0 thesis bench as a study bench: render, learn, apply, score one phone.

``study --bench flow`` runs this per sampled module: a small thesis bench (face chart at a few
distances and sensor positions, verification chart at a few distances) is rendered into a
temporary folder, the learning and application flows run on it
(:func:`~phonestereo.evaluation.bench.run_bench`) and the stage errors are returned. About
30–60 s per sample on one core (rendering the face chart dominates): use the analytic bench to
screen and this one to confirm.
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from phonestereo.evaluation.bench import run_bench
from phonestereo.sim.module import ModuleSpec
from phonestereo.sim.scenarios import BenchConfig, LearningConfig, VerificationConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set


@dataclass(frozen=True)
class FlowBenchConfig:
    """Distances of the small bench (metres) and refocus attempts per verification stack."""

    learning_distances_m: tuple[float, ...] = (1.0, 2.0, 3.0)
    verification_distances_m: tuple[float, ...] = (0.8, 1.6, 2.4, 3.2, 4.0)
    attempts: int = 1

    @classmethod
    def quick(cls) -> FlowBenchConfig:
        return cls((1.0, 3.0), (1.2, 2.4, 3.6))


def flow_bench(spec: ModuleSpec, seed: int, config: Any = None) -> dict[str, Any]:
    """Run the flow bench on one simulated phone; keys as the analytic bench's."""
    cfg = config if isinstance(config, FlowBenchConfig) else FlowBenchConfig(**(config or {}))
    bench = BenchConfig(
        LearningConfig(distances_m=cfg.learning_distances_m, attempts=1),
        VerificationConfig(distances_m=cfg.verification_distances_m, attempts=cfg.attempts),
    )
    folder = Path(tempfile.mkdtemp(prefix="phonestereo-flow-bench-"))
    try:
        write_capture_set(folder, plan_scenario("thesis-bench", spec, seed, config=bench))
        res = run_bench(folder)
    finally:
        shutil.rmtree(folder, ignore_errors=True)
    full = res["stages"]["full"]
    nan = float("nan")
    return {
        "median_rel_err": nan if full["median_rel_err"] is None else full["median_rel_err"],
        "p90_rel_err": nan if full["p90_rel_err"] is None else full["p90_rel_err"],
        "n_points": full["n"],
        "gated": res["stages"]["gated"],
        "stages": {k: res["stages"][k] for k in ("naive", "measured", "full")},
        "per_distance": {
            f"{p['distance_m']:g}": p["full"]["median_rel_err"] for p in res["per_distance"]
        },
    }


__all__ = ["FlowBenchConfig", "flow_bench"]
