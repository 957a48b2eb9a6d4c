"""Scenarios of the virtual module: the thesis's experiments as planned capture sets.

Each scenario has a small frozen config with the thesis's setup as defaults and a ``quick()``
variant for tests, and a planner that returns a :class:`~phonestereo.sim.plan.Plan` (true
states + ground truth, nothing rendered). The world frame is the device frame at rest in
landscape; charts face the device.

=============== ========================================================================
``heating``      tripod, static verification chart, a capture every 10 s for 10 min from
                 cold, focus locked (§3.1)
``refocus``      tripod, verification chart, 7 manual refocus attempts, heated (§3.5.3)
``handheld``     handheld, verification chart at 1, 1.5, 2.5 m, a 5-attempt manual refocus
                 stack at each, heated (§3.5.3, Figure 3-27); ``refocus`` with
                 ``StackConfig(handheld=True)`` is a single handheld stack
``orientation``  tripod, the same chart in landscape and flipped by 180°, heated (§3.4)
``dual-depth``   tripod, two verification charts at two depths, 7 attempts (§3.3, §3.5.2)
``learning``     face chart at 1–3 m at several sensor positions, handheld, heated, each a
                 5-attempt manual-focus stack (§3.6, §4.1.3)
``verification`` verification chart at 0.8–4 m, handheld, heated, each a 5-attempt stack
                 with an ROI (§4.1.3)
``thesis-bench`` learning + verification on one phone (docs/architecture.md)
``calibration``  tripod, focus locked, heated: a chessboard in many poses, or one shot of
                 the three-plane chart, also named ``calibration-3plane`` (§1.3.2;
                 :mod:`~phonestereo.sim.calib_scenario`)
=============== ========================================================================
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, Literal

import numpy as np

from phonestereo.charts.faces import FaceChart
from phonestereo.charts.verification import VerificationChart
from phonestereo.errors import InputError
from phonestereo.sim.calib_scenario import (
    CalibrationConfig,
    ThreePlaneCalibrationConfig,
    plan_calibration,
)
from phonestereo.sim.capture import CaptureConditions
from phonestereo.sim.coverage import fit_config, heated_start_s
from phonestereo.sim.heating_scenario import HeatingConfig, plan_heating
from phonestereo.sim.module import ModuleSpec
from phonestereo.sim.plan import (
    Plan,
    Planner,
    baseline_midpoint,
    chart_pose,
    device_pose_towards,
)
from phonestereo.sim.plan import verification_scene as _verification_scene
from phonestereo.sim.scene import PlanarObject, Scene

LANDSCAPE = device_pose_towards((0.0, 0.0))
FLIPPED = device_pose_towards((0.0, 0.0), roll_rad=np.pi)


@dataclass(frozen=True)
class Timing:
    """Capture times: heated start, spacing inside a refocus stack, gap between stacks (s)."""

    start_s: float = 300.0
    attempt_s: float = 1.5
    group_gap_s: float = 10.0


@dataclass(frozen=True)
class StackConfig:
    """One chart at ``distance_m``, ``attempts`` refocus attempts: manual focus at ``focus_m``
    (thesis §3.5.3, folded module) or autofocus aimed at ``focus_m`` (``focus_mode="auto"``,
    §3.5.2: set ``focus_m`` to the chart distance)."""

    distance_m: float = 1.5
    focus_m: float = 1.5
    attempts: int = 7
    focus_mode: Literal["manual", "auto"] = "manual"
    timing: Timing = Timing()
    handheld: bool = False

    @classmethod
    def quick(cls) -> StackConfig:
        return cls(attempts=2)


@dataclass(frozen=True)
class OrientationConfig(StackConfig):
    """A refocus stack in landscape, then one flipped by 180° (same scene)."""

    attempts: int = 5

    @classmethod
    def quick(cls) -> OrientationConfig:
        return cls(attempts=1)


@dataclass(frozen=True)
class HandheldConfig(StackConfig):
    """Handheld refocus stacks of the chart at each of ``distances_m`` (thesis Figure 3-27);
    ``distance_m`` is not used."""

    distances_m: tuple[float, ...] = (1.0, 1.5, 2.5)
    attempts: int = 5
    handheld: bool = True

    @classmethod
    def quick(cls) -> HandheldConfig:
        return cls(distances_m=(1.5,), attempts=3)


@dataclass(frozen=True)
class DualDepthConfig:
    """A small chart at ``near_m`` beside the line of sight to a large one at ``far_m``."""

    near_m: float = 1.0
    far_m: float = 2.0
    focus_m: float = 1.5
    attempts: int = 7
    focus_mode: Literal["manual", "auto"] = "manual"
    timing: Timing = Timing()

    @classmethod
    def quick(cls) -> DualDepthConfig:
        return cls(attempts=2)


@dataclass(frozen=True)
class LearningConfig:
    """Face chart at each distance and sensor position (chart centre offset in the tele image,
    in fractions of its half-size), each a handheld ``attempts`` refocus stack."""

    distances_m: tuple[float, ...] = (1.0, 1.5, 2.0, 2.5, 3.0)
    positions: tuple[tuple[float, float], ...] = ((0, 0), (-0.5, 0), (0.5, 0), (0, -0.5), (0, 0.5))
    attempts: int = 5
    focus_m: float = 1.5
    handheld: bool = True
    timing: Timing = Timing()
    focus_per_distance: bool = False  # each stack focused on its chart (sim.coverage)

    @classmethod
    def quick(cls) -> LearningConfig:
        return cls(distances_m=(1.5,), positions=((0, 0), (0.5, 0)), attempts=2)


@dataclass(frozen=True)
class VerificationConfig:
    """Verification chart at each distance, handheld, each a refocus stack with an ROI: the
    oracle box (centred on the chart, shrunk to stay on it), or with ``roi_jitter`` > 0 a
    user's box (:func:`~phonestereo.sim.plan.jitter_roi`: moved and resized by up to ±that
    fraction of its size, possibly off the chart; the images do not change)."""

    distances_m: tuple[float, ...] = (0.8, 1.2, 1.6, 2.0, 2.4, 2.8, 3.2, 3.6, 4.0)
    attempts: int = 5
    focus_m: float = 1.5
    handheld: bool = True
    roi_px: tuple[int, int] = (200, 150)
    tilt_deg: float = 4.0
    roi_jitter: float = 0.0
    timing: Timing = Timing()
    focus_per_distance: bool = False  # each stack focused on its chart (sim.coverage)

    @classmethod
    def quick(cls) -> VerificationConfig:
        return cls(distances_m=(1.0, 3.0), attempts=2)


@dataclass(frozen=True)
class BenchConfig:
    """The thesis bench (docs/architecture.md): learning then verification on one phone."""

    learning: LearningConfig = field(default_factory=LearningConfig)
    verification: VerificationConfig = field(default_factory=VerificationConfig)

    @classmethod
    def quick(cls) -> BenchConfig:
        return cls(LearningConfig.quick(), VerificationConfig.quick())


def _conditions(
    cid: str, kind: Any, t: float, pose: Any, handheld: bool, cfg: Any, group: Any, k: Any,
    focus_m: float | None = None,
) -> CaptureConditions:
    mode: Literal["manual", "auto"] = getattr(cfg, "focus_mode", "manual")
    focus = cfg.focus_m if focus_m is None else focus_m
    return CaptureConditions(cid, kind, t, pose, handheld, mode, focus, group, k)


def _stack(
    p: Planner,
    scene: Scene,
    cfg: Any,
    group: str,
    t: float,
    *,
    kind: Any = "verification",
    pose: Any = LANDSCAPE,
    handheld: bool = False,
    roi: tuple[int, int] | None = (200, 150),
    roi_jitter: float = 0.0,
    focus_m: float | None = None,
) -> float:
    for k in range(cfg.attempts):
        c = _conditions(f"{group}_{k}", kind, t, pose, handheld, cfg, group, k, focus_m)
        p.add(c, scene, roi, roi_jitter)
        t += cfg.timing.attempt_s
    return t + cfg.timing.group_gap_s


def plan_refocus(module: ModuleSpec, seed: int, cfg: StackConfig) -> Plan:
    p = Planner("refocus", module, seed, f"tripod, {cfg.attempts} {cfg.focus_mode} focus attempts")
    scene = _verification_scene(module, cfg.distance_m, np.zeros(3))
    _stack(p, scene, cfg, "r00", cfg.timing.start_s, handheld=cfg.handheld)
    return p.plan()


def plan_handheld(module: ModuleSpec, seed: int, cfg: HandheldConfig) -> Plan:
    hold = "handheld" if cfg.handheld else "tripod"
    p = Planner("handheld", module, seed, f"{hold}, refocus stacks at {list(cfg.distances_m)} m")
    t = cfg.timing.start_s
    for i, d in enumerate(cfg.distances_m):
        scene = _verification_scene(module, d, np.zeros(3))
        t = _stack(p, scene, cfg, f"H{i:02d}", t, handheld=cfg.handheld)
    return p.plan()


def plan_orientation(module: ModuleSpec, seed: int, cfg: OrientationConfig) -> Plan:
    p = Planner("orientation", module, seed, "tripod, same scene in landscape and flipped")
    scene = _verification_scene(module, cfg.distance_m, np.zeros(3))
    t = _stack(p, scene, cfg, "land", cfg.timing.start_s, pose=LANDSCAPE)
    _stack(p, scene, cfg, "flip", t, pose=FLIPPED)
    return p.plan()


def plan_dual_depth(module: ModuleSpec, seed: int, cfg: DualDepthConfig) -> Plan:
    p = Planner("dual-depth", module, seed, "tripod, two charts at two depths")
    mx, my = baseline_midpoint(module)
    far = VerificationChart()
    near = VerificationChart(squares=(10, 8), square_m=0.018)
    # Near chart left of the line of sight, far chart's centre slightly right of it, so the
    # tele sees both charts and both sets of circle pairs.
    far_pose = chart_pose(far.size_m, cfg.far_m, np.zeros(3), (mx + 0.05 * cfg.far_m, my))
    near_pose = chart_pose(
        near.size_m, cfg.near_m, np.zeros(3), (mx - 0.13 * cfg.near_m, my + 0.011 * cfg.near_m)
    )
    scene = Scene((PlanarObject(near, near_pose, "near"), PlanarObject(far, far_pose, "far")))
    _stack(p, scene, cfg, "d00", cfg.timing.start_s)
    return p.plan()


def _plan_learning(p: Planner, module: ModuleSpec, cfg: LearningConfig, t: float) -> float:
    cfg = fit_config(cfg, module, "faces", p.notes)
    chart = FaceChart()
    tele = module.tele
    half = (tele.size[0] / 2 / tele.focal_px_infinity, tele.size[1] / 2 / tele.focal_px_infinity)
    for i, d in enumerate(cfg.distances_m):
        tilt = p.layout.normal(size=3) * np.deg2rad([3.0, 3.0, 1.0])
        scene = Scene(
            (
                PlanarObject(
                    chart, chart_pose(chart.size_m, d, tilt, baseline_midpoint(module)), "faces"
                ),
            )
        )
        for j, (ox, oy) in enumerate(cfg.positions):
            pose = device_pose_towards((ox * half[0], oy * half[1]))
            t = _stack(
                p,
                scene,
                cfg,
                f"L{i:02d}p{j:02d}",
                t,
                kind="face",
                pose=pose,
                handheld=cfg.handheld,
                roi=None,
                focus_m=d if cfg.focus_per_distance else None,
            )
    return t


def _plan_verification(p: Planner, module: ModuleSpec, cfg: VerificationConfig, t: float) -> float:
    cfg = fit_config(cfg, module, "verification chart", p.notes)
    for i, d in enumerate(cfg.distances_m):
        tilt = p.layout.normal(size=3) * np.deg2rad([cfg.tilt_deg, cfg.tilt_deg, 1.0])
        scene = _verification_scene(module, d, tilt)
        focus = d if cfg.focus_per_distance else None
        t = _stack(p, scene, cfg, f"V{i:02d}", t, handheld=cfg.handheld, roi=cfg.roi_px,
                   roi_jitter=cfg.roi_jitter, focus_m=focus)
    return t


def plan_learning(module: ModuleSpec, seed: int, cfg: LearningConfig) -> Plan:
    p = Planner("learning", module, seed, "face chart at 1-3 m, several sensor positions")
    _plan_learning(p, module, cfg, heated_start_s(module, cfg.timing.start_s, p.notes))
    return p.plan()


def plan_verification(module: ModuleSpec, seed: int, cfg: VerificationConfig) -> Plan:
    p = Planner("verification", module, seed, "verification chart at 0.8-4 m, handheld")
    _plan_verification(p, module, cfg, heated_start_s(module, cfg.timing.start_s, p.notes))
    return p.plan()


def plan_thesis_bench(module: ModuleSpec, seed: int, cfg: BenchConfig) -> Plan:
    """Learning then verification. One focus regime for both: when the verification chart has
    to be focused per distance (the user taps the chart, :func:`~phonestereo.sim.coverage.
    fit_focus`), so are the face stacks. A learned correction holds only for the focus states it
    was learned at (the tele's principal point and distortion move with its lens, §3.2): faces
    at one manual focus taught random-1013 a 2.7 % gain error that per-distance focus removes
    (docs/module-random.md, session 12)."""
    p = Planner("thesis-bench", module, seed, "learning + verification (docs/architecture.md)")
    learn = cfg.learning
    verification = fit_config(cfg.verification, module, "verification chart", [])  # notes later
    if not learn.focus_per_distance and verification.focus_per_distance:
        learn = replace(learn, focus_per_distance=True)
        p.notes.append("faces: each stack focused on its chart, as the verification chart is "
                       "(one focus regime for learning and application)")
    t = _plan_learning(p, module, learn, heated_start_s(module, learn.timing.start_s, p.notes))
    _plan_verification(p, module, cfg.verification, t)
    return p.plan()


@dataclass(frozen=True)
class Scenario:
    """A named scenario: its config type and planner."""

    name: str
    config: Any  # the config class (with a ``quick()`` classmethod)
    planner: Callable[[ModuleSpec, int, Any], Plan]
    summary: str


SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        Scenario("heating", HeatingConfig, plan_heating, "tripod, every 10 s for 10 min from cold"),
        Scenario("refocus", StackConfig, plan_refocus, "tripod, 7 refocus attempts"),
        Scenario("orientation", OrientationConfig, plan_orientation, "landscape and flipped"),
        Scenario("dual-depth", DualDepthConfig, plan_dual_depth, "two charts at two depths"),
        Scenario("handheld", HandheldConfig, plan_handheld, "handheld refocus stacks, 1-2.5 m"),
        Scenario("learning", LearningConfig, plan_learning, "face chart at 1-3 m, stacks"),
        Scenario("verification", VerificationConfig, plan_verification, "chart at 0.8-4 m"),
        Scenario("thesis-bench", BenchConfig, plan_thesis_bench, "learning + verification"),
        Scenario("calibration", CalibrationConfig, plan_calibration, "chessboard in 18 poses"),
        Scenario(
            "calibration-3plane", ThreePlaneCalibrationConfig, plan_calibration, "3-plane chart"
        ),
    )
}


def plan_scenario(
    name: str, module: ModuleSpec, seed: int = 0, *, quick: bool = False, config: Any = None
) -> Plan:
    """Plan a scenario by name (no rendering).

    Parameters
    ----------
    name : str
        One of :data:`SCENARIOS`.
    module : ModuleSpec
        The virtual module.
    seed : int
        Seed (>= 0); the same seed gives the same plan.
    quick : bool
        Use the scenario's small ``quick()`` config (tests).
    config : optional
        A config of the scenario's type, overriding ``quick``.

    Raises
    ------
    InputError
        Unknown scenario (the message lists them) or a config of the wrong type.
    """
    if name not in SCENARIOS:
        raise InputError(f"unknown scenario {name!r}; choose one of {list(SCENARIOS)}")
    sc = SCENARIOS[name]
    if config is None:
        config = sc.config.quick() if quick else sc.config()
    if not isinstance(config, sc.config):
        raise InputError(
            f"scenario {name!r} takes a {sc.config.__name__}, got {type(config).__name__}"
        )
    if not isinstance(seed, int | np.integer) or seed < 0:
        raise InputError(f"seed must be an integer >= 0, got {seed!r}")
    return sc.planner(module, int(seed), config)
