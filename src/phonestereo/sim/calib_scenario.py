"""The ``calibration`` scenario: calibration captures of the virtual module (thesis §1.3.2).

Two variants (:class:`CalibrationConfig` ``chart``):

``chessboard``   a plain chessboard in many poses, both cameras in every capture. ``wide_poses``
                 place the board all over the wide image (tilted up to ``max_tilt_deg``; the
                 tele mostly sees none of it); ``tele_poses`` fill the tele with the whole
                 board (the wide then sees it in its centre). Every planned board lies wholly
                 inside the image it is planned for, with a quiet zone, so OpenCV's
                 detector (which needs the complete board) finds it.
``three-plane``  one capture of :class:`~phonestereo.charts.three_plane.ThreePlaneChart`
                 centred in the tele, every corner visible in both cameras (also registered
                 as the scenario ``calibration-3plane``, so ``phonestereo simulate`` makes it).

The device stands on a tripod in landscape; the chart moves. The focus is locked (manual focus
at the module's calibration distance, one shared lens-position draw) and the captures are
taken heated, seconds apart, so every capture has the same true cameras and T_tele_wide (to
~1e-4 px of heating drift): the ground truth of any capture is what a calibration must recover.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from phonestereo.charts.three_plane import ThreePlaneChart
from phonestereo.charts.verification import Chessboard
from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Transform
from phonestereo.sim.capture import CaptureConditions, calibration_rig
from phonestereo.sim.module import ModuleSpec
from phonestereo.sim.plan import Plan, Planner, device_pose_towards
from phonestereo.sim.scene import PlanarObject, Scene, facing_pose

#: Pixels between a planned board outline (its white margin included) and the image border.
QUIET_PX = 8.0
#: Sensor positions (fractions of the half-size) the wide poses cycle through.
_WIDE_TARGETS = ((-1, -1), (1, 1), (1, -1), (-1, 1), (0, -1), (0, 1), (-1, 0), (1, 0), (0, 0))


@dataclass(frozen=True)
class CalibrationConfig:
    """Calibration captures: a chessboard in many poses, or one shot of the three-plane chart."""

    #: The variant.
    chart: Literal["chessboard", "three-plane"] = "chessboard"
    #: ``wide_poses``, ``tele_poses``: Board poses spread over the wide image, and poses filling the
    #: tele.
    wide_poses: int = 12
    #: See ``wide_poses`` above.
    tele_poses: int = 6
    #: Inner corners (cols, rows) of the chessboard; cols + rows odd so that its 180° turn is
    #: visible (the first square is black).
    pattern: tuple[int, int] = (9, 6)
    #: Chessboard square, metres (one-square white margin).
    square_m: float = 0.02
    #: Range of board distances of the wide poses, metres.
    wide_distance_m: tuple[float, float] = (0.3, 0.45)
    #: Board distance of the tele poses (and of the three-plane chart), metres.
    tele_distance_m: float = 0.65
    #: Largest board tilt (wide poses; the tele poses halve it so the board stays whole).
    max_tilt_deg: float = 45.0
    #: Manual focus distance; None = the module's calibration focus distance.
    focus_m: float | None = None
    #: ``start_s``, ``interval_s``: Time of the first capture (heated by then) and the spacing,
    #: seconds.
    start_s: float = 600.0
    #: See ``start_s`` above.
    interval_s: float = 2.0

    def __post_init__(self) -> None:
        if self.chart not in ("chessboard", "three-plane"):
            raise InputError(f"chart must be 'chessboard' or 'three-plane', got {self.chart!r}")
        if self.wide_poses < 0 or self.tele_poses < 0 or self.wide_poses + self.tele_poses < 1:
            raise InputError("wide_poses and tele_poses must be >= 0 and plan at least one pose")
        if (self.pattern[0] + self.pattern[1]) % 2 == 0:
            raise InputError(
                f"pattern {self.pattern}: use cols + rows odd (e.g. 9x6) so a detector can "
                "tell the board from its 180° turn"
            )
        lo, hi = self.wide_distance_m
        if not 0 < lo <= hi or self.tele_distance_m <= 0:
            raise InputError("distances must be > 0 m and wide_distance_m ordered (near, far)")
        if not 0 <= self.max_tilt_deg < 80:
            raise InputError(f"max_tilt_deg must be in [0, 80), got {self.max_tilt_deg}")

    @classmethod
    def quick(cls) -> CalibrationConfig:
        return cls(wide_poses=4, tele_poses=2)


@dataclass(frozen=True)
class ThreePlaneCalibrationConfig(CalibrationConfig):
    """The ``calibration-3plane`` scenario: :class:`CalibrationConfig` with the three-plane
    chart by default (one capture; the board fields do not apply)."""

    chart: Literal["chessboard", "three-plane"] = "three-plane"

    @classmethod
    def quick(cls) -> ThreePlaneCalibrationConfig:
        return cls()


def _fits(cam: Camera, T_cam_chart: Transform, outline: np.ndarray) -> bool:
    q = cam.project(T_cam_chart.apply(outline))
    return bool(np.all(cam.contains(q, margin=QUIET_PX)))


def _outline(size_m: tuple[float, float]) -> np.ndarray:
    w, h = size_m
    s = np.linspace(0.0, 1.0, 9)
    edges = [np.column_stack([s * w, 0 * s]), np.column_stack([w + 0 * s, s * h])]
    edges += [np.column_stack([s * w, h + 0 * s]), np.column_stack([0 * s, s * h])]
    uv = np.concatenate(edges)
    return np.column_stack([uv, np.zeros(len(uv))])


def _random_tilt(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    """A tilt up to ``max_deg`` about a random in-plane axis, plus a roll of up to 10°."""
    axis = rng.uniform(0.0, 2 * np.pi)
    angle = np.deg2rad(max_deg) * np.sqrt(rng.uniform(0.3, 1.0))
    roll = np.deg2rad(10.0) * rng.uniform(-1.0, 1.0)
    return np.array([angle * np.cos(axis), angle * np.sin(axis), roll])


def _wide_pose(
    cam: Camera, board: Chessboard, target: tuple[int, int], d: float, tilt: np.ndarray
) -> Transform:
    """T_wide_chart with the board centre towards ``target`` as far as the board stays whole."""
    half = np.array([cam.width / 2 / cam.fx, cam.height / 2 / cam.fy])
    outline = _outline(board.size_m)
    for shrink in np.linspace(1.0, 0.0, 41):
        xy = np.asarray(target, dtype=float) * half * shrink
        T = facing_pose(board.size_m, d, tilt_rad=tilt, center_m=xy * d)
        if _fits(cam, T, outline):
            return T
    raise InputError(
        f"a {board.size_m[0]:.3f} m board at {d} m does not fit the wide image; "
        "increase wide_distance_m or use a smaller board"
    )


def _tele_pose(
    cam: Camera,
    size_m: tuple[float, float],
    outline: np.ndarray,
    d: float,
    tilt: np.ndarray,
    rng: np.random.Generator,
) -> Transform:
    """T_tele_chart of a chart (outline in its frame) near the tele's axis, wholly in view."""
    for scale in np.linspace(1.0, 0.0, 21):
        off = rng.uniform(-0.03, 0.03, 2) * d * scale
        T = facing_pose(size_m, d, tilt_rad=tilt * scale, center_m=off)
        if _fits(cam, T, outline):
            return T
    raise InputError(
        f"the chart ({size_m[0]:.3f} m wide) does not fit the tele at {d} m; "
        "increase tele_distance_m"
    )


def plan_calibration(module: ModuleSpec, seed: int, cfg: CalibrationConfig) -> Plan:
    """Plan the calibration captures (see the module docstring)."""
    name = "calibration-3plane" if cfg.chart == "three-plane" else "calibration"
    p = Planner(name, module, seed, f"tripod, focus locked, {cfg.chart} calibration")
    lock = p.layout.normal(size=2)
    focus = module.calibration.focus_distance_m if cfg.focus_m is None else cfg.focus_m
    rig = calibration_rig(module)  # placement only: the captures draw their own true state
    T_world_tele = rig.T_tele_wide.inverse()  # the device (wide) frame is the world at rest
    kind: Any = "calibration"

    def add(cid: str, k: int, scene: Scene) -> None:
        t = cfg.start_s + k * cfg.interval_s
        c = CaptureConditions(
            cid,
            kind,
            t,
            device_pose_towards((0.0, 0.0)),
            False,
            "manual",
            focus,
            lens_noise=(float(lock[0]), float(lock[1])),
        )
        p.add(c, scene, None)

    if cfg.chart == "three-plane":
        chart = ThreePlaneChart()
        w, h = chart.extent_m
        # facing_pose centres a (w, h) box; the three-plane frame has its origin at the centre.
        centre = Transform(np.eye(3), np.array([w / 2, h / 2, 0.0]))
        outline = centre.apply(chart.outline_chart())
        tilt = p.layout.normal(size=3) * np.deg2rad([2.0, 2.0, 1.0])
        T_tele_box = _tele_pose(rig.tele, (w, h), outline, cfg.tele_distance_m, tilt, p.layout)
        T_world_chart = T_world_tele @ T_tele_box @ centre
        objects = tuple(
            PlanarObject(pl.board, T_world_chart @ pl.T_chart_plane, pl.name) for pl in chart.planes
        )
        add("P00", 0, Scene(objects))
        return p.plan()
    board = Chessboard(cfg.pattern, square_m=cfg.square_m, margin_m=cfg.square_m, name="board")
    outline = _outline(board.size_m)
    for k in range(cfg.wide_poses):
        d = p.layout.uniform(*cfg.wide_distance_m)
        tilt = _random_tilt(p.layout, cfg.max_tilt_deg)
        target = _WIDE_TARGETS[k % len(_WIDE_TARGETS)]
        T = _wide_pose(rig.wide, board, target, d, tilt)
        add(f"W{k:02d}", k, Scene((PlanarObject(board, T, "board"),)))
    for k in range(cfg.tele_poses):
        tilt = _random_tilt(p.layout, cfg.max_tilt_deg / 2)
        T = T_world_tele @ _tele_pose(
            rig.tele, board.size_m, outline, cfg.tele_distance_m, tilt, p.layout
        )
        add(f"T{k:02d}", cfg.wide_poses + k, Scene((PlanarObject(board, T, "board"),)))
    return p.plan()
