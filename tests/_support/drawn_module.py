"""A drawn module (``module random --seed N``) rendered with the demo's quick plan and run
through the thesis bench, as the held-out probes of docs/module-random.md are."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from phonestereo.evaluation.bench import run_bench
from phonestereo.evaluation.module_bench import demo_quick_config
from phonestereo.sim.random_module import load_ranges, random_module
from phonestereo.sim.scenarios import plan_scenario
from phonestereo.sim.writer import write_capture_set


def bench_drawn_module(seed: int, folder: Path) -> dict[str, Any]:
    """``run_bench`` of module ``seed`` rendered (one worker) into ``folder``/set."""
    plan = plan_scenario("thesis-bench", random_module(seed, load_ranges()), seed,
                         config=demo_quick_config())
    out = folder / "set"
    write_capture_set(out, plan, workers=1)
    return run_bench(out)


def scored_drawn_module(seed: int, folder: Path) -> tuple[Any, Any]:
    """(relative depth errors, |error| / σ) of the measured captures of :func:`bench_drawn_module`,
    each shape (n,); asserts that ≥ 80 % of the captures were measured (issue #18's line)."""
    import numpy as np

    res = bench_drawn_module(seed, folder)
    caps = [c for c in res["captures"] if c["ok"]]
    assert len(caps) >= 0.8 * len(res["captures"]), [c["reason"] for c in res["captures"]]
    err = np.array([c["depth_m"] / c["z_true_m"] - 1 for c in caps])
    return err, np.abs(err) / np.array([c["sigma_m"] / c["z_true_m"] for c in caps])
