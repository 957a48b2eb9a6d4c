"""The ``heating`` scenario: a static verification chart from cold, focus locked (thesis §3.1).

A capture every ``interval_s`` from t = 0 for ``duration_s`` on a tripod, the lens noise drawn
once (focus locked), so the only change between captures is the warm-up.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from phonestereo.sim.capture import CaptureConditions
from phonestereo.sim.module import ModuleSpec
from phonestereo.sim.plan import Plan, Planner, device_pose_towards, verification_scene

LANDSCAPE = device_pose_towards((0.0, 0.0))


@dataclass(frozen=True)
class HeatingConfig:
    """A capture every ``interval_s`` from cold (t = 0) for ``duration_s``, focus locked."""

    distance_m: float = 1.5
    focus_m: float = 1.5
    interval_s: float = 10.0
    duration_s: float = 600.0

    @classmethod
    def quick(cls) -> HeatingConfig:
        return cls(interval_s=60.0, duration_s=180.0)


def plan_heating(module: ModuleSpec, seed: int, cfg: HeatingConfig) -> Plan:
    p = Planner("heating", module, seed, "tripod, static chart, from cold, focus locked")
    scene = verification_scene(module, cfg.distance_m, np.zeros(3))
    lock = p.layout.normal(size=2)
    n = int(np.floor(cfg.duration_s / cfg.interval_s + 1e-9)) + 1
    for i in range(n):
        t = i * cfg.interval_s
        c = CaptureConditions(
            f"h{i:03d}",
            "verification",
            t,
            LANDSCAPE,
            False,
            "manual",
            cfg.focus_m,
            lens_noise=(float(lock[0]), float(lock[1])),
        )
        p.add(c, scene, (200, 150))
    return p.plan()


__all__ = ["HeatingConfig", "plan_heating"]
