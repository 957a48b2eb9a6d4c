"""Per-sample benches of a tolerance study: ``bench(spec, seed, config) -> dict``.

A bench measures the relative depth error of one simulated phone (one module, one seed). The
study (:mod:`phonestereo.evaluation.study`) calls it once per tolerance sample. Every bench
returns at least ``median_rel_err``, ``p90_rel_err`` (fractions, over all verification points)
and ``stages`` (per pipeline stage, the same two numbers).

``analytic``
    No rendering: the true cameras of every verification capture of a small thesis bench
    (docs/architecture.md: heated, manual focus at 1.5 m, handheld, chart at 0.8–4 m) come from the
    simulator's effect functions (:func:`~phonestereo.sim.capture.true_state`), a grid of chart
    points is projected with the true rig, and the naive depth Z = f·B/d is taken with the
    phone's factory calibration (:func:`~phonestereo.evaluation.naive.naive_depth`). Costs a
    few tens of milliseconds.
``flow``
    The full Phase 0 flow per sample (issue #7); not available yet.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.evaluation.naive import naive_depth
from phonestereo.geometry import Transform
from phonestereo.sim.capture import CaptureConditions, true_state
from phonestereo.sim.factory import factory_calibration
from phonestereo.sim.module import ModuleSpec
from phonestereo.sim.plan import (
    STREAM_CALIBRATION,
    STREAM_LAYOUT,
    STREAM_STATE,
    baseline_midpoint,
    stream,
)
from phonestereo.sim.scene import facing_pose

BENCH_KEY = "analytic-bench"
Bench = Callable[[ModuleSpec, int, Any], dict[str, Any]]


@dataclass(frozen=True)
class AnalyticBenchConfig:
    """The verification half of the thesis bench, analytically (no images)."""

    #: tuple of float. Chart distances, metres.
    distances_m: tuple[float, ...] = (0.8, 1.2, 1.6, 2.0, 2.4, 2.8, 3.2, 3.6, 4.0)
    #: Captures per distance (manual refocus attempts).
    attempts: int = 1
    #: Manual focus distance, metres.
    focus_m: float = 1.5
    #: ``start_s``, ``attempt_s``: Time of the first capture (heated) and the spacing between
    #: captures, seconds.
    start_s: float = 300.0
    #: See ``start_s`` above.
    attempt_s: float = 10.0
    #: Hand shake on every capture.
    handheld: bool = True
    #: Chart points (columns, rows).
    grid: tuple[int, int] = (9, 7)
    #: Fraction of the tele's field of view the grid spans (the wide sees it all).
    field: float = 0.6
    #: 1σ chart tilt about x and y, degrees.
    tilt_deg: float = 4.0

    def __post_init__(self) -> None:
        if not self.distances_m or min(self.distances_m) <= 0:
            raise InputError(f"distances_m must be positive metres, got {self.distances_m}")
        if self.attempts < 1 or min(self.grid) < 2 or not 0 < self.field <= 1:
            raise InputError("attempts >= 1, grid >= (2, 2) and 0 < field <= 1 are required")

    @classmethod
    def quick(cls) -> AnalyticBenchConfig:
        """Three distances, a 5×4 grid (tests)."""
        return cls(distances_m=(1.0, 2.0, 3.5), grid=(5, 4))


def _grid(spec: ModuleSpec, cfg: AnalyticBenchConfig, distance_m: float) -> np.ndarray:
    """Chart-frame points (N, 3) of a grid spanning ``field`` of the tele's view at a distance."""
    tele = spec.tele
    w = cfg.field * tele.size[0] / tele.focal_px_infinity * distance_m
    h = cfg.field * tele.size[1] / tele.focal_px_infinity * distance_m
    u, v = np.meshgrid(np.linspace(0, w, cfg.grid[0]), np.linspace(0, h, cfg.grid[1]))
    return np.column_stack([u.ravel(), v.ravel(), np.zeros(u.size)])


def _stats(rel: np.ndarray) -> dict[str, float]:
    if rel.size == 0:
        return {"median_rel_err": float("nan"), "p90_rel_err": float("nan")}
    return {
        "median_rel_err": float(np.median(rel)),
        "p90_rel_err": float(np.percentile(rel, 90)),
    }


def analytic_bench(
    spec: ModuleSpec, seed: int, config: AnalyticBenchConfig | None = None
) -> dict[str, Any]:
    """Naive relative depth error of one simulated phone at the verification distances.

    Parameters
    ----------
    spec : ModuleSpec
        The (sampled) module.
    seed : int
        The phone: factory-calibration noise (the same stream as any scenario simulated with
        this seed), chart tilts, hand shake and lens-position noise.
    config : AnalyticBenchConfig, optional
        Default: the thesis's verification distances, one capture each.

    Returns
    -------
    dict
        ``median_rel_err``, ``p90_rel_err`` (fractions), ``n_points``, ``stages``
        (``{"naive": {...}}``) and ``per_distance`` (distance in m as text → median).

    Examples
    --------
    The folded ×3 module lands near the thesis's ~30 % naive error (docs/architecture.md):

    >>> from phonestereo.sim.module import load_module
    >>> out = analytic_bench(load_module("folded-x3"), 0)
    >>> 0.15 < out["median_rel_err"] < 0.45
    True
    """
    cfg = config if config is not None else AnalyticBenchConfig()
    cal = factory_calibration(spec, stream(seed, STREAM_CALIBRATION))
    layout = stream(seed, BENCH_KEY, STREAM_LAYOUT)
    center = baseline_midpoint(spec)
    t, n = cfg.start_s, 0
    qw, qt, z_true, which = [], [], [], []
    for i, distance in enumerate(cfg.distances_m):
        tilt = layout.normal(size=3) * np.deg2rad([cfg.tilt_deg, cfg.tilt_deg, 1.0])
        pts = _grid(spec, cfg, distance)
        size = (float(pts[:, 0].max()), float(pts[:, 1].max()))
        world = facing_pose(size, distance, tilt_rad=tilt, center_m=center).apply(pts)
        for k in range(cfg.attempts):
            cond = CaptureConditions(
                f"V{i:02d}_{k}",
                "verification",
                t,
                Transform.identity(),
                cfg.handheld,
                "manual",
                cfg.focus_m,
                f"V{i:02d}",
                k,
            )
            state = true_state(spec, cond, stream(seed, BENCH_KEY, STREAM_STATE, n))
            p_wide = state.T_cam_world("wide").apply(world)
            q_w, q_t = state.rig.project(p_wide)
            seen = state.wide.camera.contains(q_w) & state.tele.camera.contains(q_t)
            qw.append(q_w[seen])
            qt.append(q_t[seen])
            z_true.append(p_wide[seen, 2])
            which.append(np.full(int(seen.sum()), i))
            t += cfg.attempt_s
            n += 1
    zt = np.concatenate(z_true)
    # One naive-depth call for every point of every capture: the calibration is the same.
    rel = np.abs(naive_depth(np.concatenate(qw), np.concatenate(qt), cal) - zt) / zt
    idx = np.concatenate(which)
    ok = np.isfinite(rel)
    naive = _stats(rel[ok])
    per_distance = {
        f"{d:g}": _stats(rel[ok & (idx == i)])["median_rel_err"]
        for i, d in enumerate(cfg.distances_m)
    }
    return {
        **naive,
        "n_points": int(ok.sum()),
        "stages": {"naive": naive},
        "per_distance": per_distance,
    }


def _flow_bench(spec: ModuleSpec, seed: int, config: Any = None) -> dict[str, Any]:
    # Imported when used: it pulls in the flows (and MediaPipe) that the analytic bench avoids.
    from phonestereo.evaluation.flow_bench import flow_bench

    return flow_bench(spec, seed, config)


def _flow_config() -> Any:
    from phonestereo.evaluation.flow_bench import FlowBenchConfig

    return FlowBenchConfig()


#: Bench name → function (the analytic stand-in, and the full flow of issue #7).
BENCHES: dict[str, Bench | None] = {"analytic": analytic_bench, "flow": _flow_bench}
BENCH_CONFIGS: dict[str, Any] = {"analytic": AnalyticBenchConfig, "flow": _flow_config}


def get_bench(name: str) -> Bench:
    """The bench function of a name.

    Raises
    ------
    InputError
        Unknown bench (the message lists them) or a bench not available yet.
    """
    if name not in BENCHES:
        raise InputError(f"unknown bench {name!r}; choose one of {sorted(BENCHES)}")
    fn = BENCHES[name]
    if fn is None:
        raise InputError(f"bench {name!r} is not available; choose one of {sorted(BENCHES)}")
    return fn


__all__ = ["BENCHES", "AnalyticBenchConfig", "Bench", "analytic_bench", "get_bench"]
