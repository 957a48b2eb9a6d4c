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
