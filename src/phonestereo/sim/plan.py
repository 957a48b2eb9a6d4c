"""A planned capture set: true states, scenes, ROIs and ground truth, before any rendering.

Scenarios (:mod:`phonestereo.sim.scenarios`) build a :class:`Plan`; the writer
(:mod:`phonestereo.sim.writer`) renders it. Planning is cheap, so tests check ground truth
without rendering.

Random streams are derived from the seed and fixed keys, so the same seed gives the same
plan and the same images, and the factory calibration depends only on (module, seed): every
scenario simulated with one seed is one phone.
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from phonestereo.charts.verification import VerificationChart
from phonestereo.errors import InputError
from phonestereo.geometry import Transform
from phonestereo.io import Calibration, CaptureEntry, Manifest
from phonestereo.sim import effects as fx
from phonestereo.sim.capture import (
    CaptureConditions,
    CaptureState,
    calibration_rig,
    image_suffix,
    true_state,
)
from phonestereo.sim.factory import factory_calibration
from phonestereo.sim.ground_truth import CaptureTruth, GroundTruth, capture_truth
from phonestereo.sim.module import ModuleSpec
from phonestereo.sim.scene import PlanarObject, Scene
from phonestereo.sim.truth import visible_pixels

STREAM_CALIBRATION = 0
STREAM_LAYOUT = 1
STREAM_STATE = 2
STREAM_RENDER = 3


def stream(seed: int, *keys: int | str) -> np.random.Generator:
    """An independent random generator for (seed, keys); strings are hashed with CRC-32.

    >>> float(stream(1, "heating", 2).normal()) == float(stream(1, "heating", 2).normal())
    True
    """
    ints = [zlib.crc32(k.encode()) if isinstance(k, str) else int(k) for k in keys]
    if seed < 0:
        raise InputError(f"seed must be >= 0, got {seed}")
    return np.random.default_rng([int(seed), *ints])


@dataclass(frozen=True)
class PlannedCapture:
    """One capture: its true state, the scene it sees, its ROI and its ground truth."""

    state: CaptureState
    scene: Scene
    roi: tuple[int, int, int, int] | None
    truth: CaptureTruth
    index: int


@dataclass(frozen=True)
class Plan:
    """Everything a capture set will contain, except the pixels."""

    scenario: str
    module: ModuleSpec
    seed: int
    calibration: Calibration
    captures: tuple[PlannedCapture, ...]
    description: str = ""
    #: What the planner changed for this module and what it cannot cover (sim.coverage).
    notes: tuple[str, ...] = ()

    def ground_truth(self) -> GroundTruth:
        """The ground truth of the whole set."""
        return GroundTruth(
            scenario=self.scenario,
            seed=self.seed,
            module=self.module.model_dump(mode="json"),
            calibration_true=calibration_rig(self.module).to_dict(),
            captures=[c.truth for c in self.captures],
            notes=list(self.notes),
        )

    def manifest(self, image_dir: str = "images") -> Manifest:
        """The manifest a phone app would write: only what the module reports."""
        entries = []
        for pc in self.captures:
            st, c = pc.state, pc.state.conditions
            gx, gy, gz = (round(g, 9) for g in st.gravity)
            entries.append(
                CaptureEntry(
                    id=c.id,
                    wide=f"{image_dir}/{c.id}_wide{image_suffix(self.module, 'wide')}",
                    tele=f"{image_dir}/{c.id}_tele{image_suffix(self.module, 'tele')}",
                    time_s=round(c.time_s, 6),
                    gravity=(gx, gy, gz),
                    orientation=st.orientation,
                    kind=c.kind,
                    focus_group=c.focus_group,
                    focus_attempt=c.focus_attempt,
                    focus_mode=c.focus_mode,
                    focus_position=st.wide.reported_focus_position,
                    temperature_c=(
                        round(st.temperature_c, 3) if self.module.reports.temperature else None
                    ),
                    roi=pc.roi,
                )
            )
        text = f"{self.scenario} scenario of virtual module '{self.module.name}', seed {self.seed}"
        return Manifest(description=text, captures=entries)


class Planner:
    """Accumulates captures of one scenario with its own random streams."""

    def __init__(self, scenario: str, module: ModuleSpec, seed: int, description: str = ""):
        self.scenario, self.module, self.seed, self.description = (
            scenario,
            module,
            seed,
            description,
        )
        self.captures: list[PlannedCapture] = []
        self.notes: list[str] = []
        self.layout = stream(seed, scenario, STREAM_LAYOUT)

    def add(
        self,
        conditions: CaptureConditions,
        scene: Scene,
        roi_size_px: tuple[int, int] | None,
        roi_jitter: float = 0.0,
    ) -> PlannedCapture:
        """Draw the true state of one capture, its ROI (if asked; ``roi_jitter``:
        :func:`jitter_roi`) and its ground truth."""
        i = len(self.captures)
        state = true_state(
            self.module, conditions, stream(self.seed, self.scenario, STREAM_STATE, i)
        )
        roi = None if roi_size_px is None else chart_roi(state, scene, roi_size_px)
        if roi is not None and roi_jitter > 0:
            rng = stream(self.seed, self.scenario, "roi-jitter", i)  # images stay the same
            roi = jitter_roi(roi, roi_jitter, rng, state.wide.camera.size)
        pc = PlannedCapture(state, scene, roi, capture_truth(state, scene, roi), i)
        self.captures.append(pc)
        return pc

    def plan(self) -> Plan:
        """The finished plan (with the factory calibration of (module, seed))."""
        ids = [c.state.id for c in self.captures]
        if len(set(ids)) != len(ids):
            raise InputError(f"scenario {self.scenario!r} planned duplicate capture ids")
        cal = factory_calibration(self.module, stream(self.seed, STREAM_CALIBRATION))
        caps = tuple(self.captures)
        return Plan(self.scenario, self.module, self.seed, cal, caps, self.description,
                    tuple(self.notes))


def chart_roi(
    state: CaptureState, scene: Scene, size_px: tuple[int, int], index: int = 0
) -> tuple[int, int, int, int] | None:
    """ROI [x, y, w, h] (wide pixels) centred on the projection of object ``index``'s centre,
    shrunk to stay inside the image and the object's projected outline; None if not visible."""
    obj: PlanarObject = scene.objects[index]
    w_m, h_m = obj.chart.size_m
    outline = np.array([[0, 0], [w_m, 0], [w_m, h_m], [0, h_m], [w_m / 2, h_m / 2]], dtype=float)
    wide = state.wide.camera
    q = visible_pixels(wide, state.T_cam_world("wide"), scene.objects, index, outline)
    if not np.isfinite(q[4]).all():
        return None
    cx, cy = q[4]
    finite = q[:4][np.isfinite(q[:4]).all(axis=1)]
    lo = np.array([-0.5, -0.5])
    hi = np.array([wide.width - 0.5, wide.height - 0.5])
    if len(finite) == 4:
        lo, hi = np.maximum(lo, finite.min(axis=0)), np.minimum(hi, finite.max(axis=0))
    half_w = min(size_px[0] / 2, cx - lo[0] - 2, hi[0] - cx - 2)
    half_h = min(size_px[1] / 2, cy - lo[1] - 2, hi[1] - cy - 2)
    if half_w < 8 or half_h < 8:
        return None
    box = np.rint([cx - half_w, cy - half_h, 2 * half_w, 2 * half_h]).astype(int)
    return int(box[0]), int(box[1]), int(box[2]), int(box[3])


def jitter_roi(
    roi: tuple[int, int, int, int],
    jitter: float,
    rng: np.random.Generator,
    size: tuple[int, int],
) -> tuple[int, int, int, int]:
    """A user's ROI instead of the oracle box: centre moved and each side scaled by uniform
    draws within ±``jitter`` of the box's size, kept inside the image only (it may leave the
    chart: a user's box is not shrunk to it).

    >>> jitter_roi((900, 700, 200, 150), 0.2, np.random.default_rng(0), (2000, 1500))
    (929, 701, 163, 121)
    """
    x, y, w, h = roi
    u = rng.uniform(-jitter, jitter, 4)
    cx, cy = x + w / 2 + u[0] * w, y + h / 2 + u[1] * h
    w2, h2 = w * (1 + u[2]), h * (1 + u[3])
    x0, y0 = max(0.0, cx - w2 / 2), max(0.0, cy - h2 / 2)
    x1, y1 = min(float(size[0]), cx + w2 / 2), min(float(size[1]), cy + h2 / 2)
    return round(x0), round(y0), max(round(x1 - x0), 16), max(round(y1 - y0), 16)


def device_pose_towards(offset_n: tuple[float, float], roll_rad: float = 0.0) -> Transform:
    """Nominal T_world_device that makes the world's +z axis appear at normalised wide
    coordinates ``offset_n`` (so a chart on the world axis lands at that sensor position),
    after rolling the device by ``roll_rad`` about its optical axis (π: flipped landscape)."""
    d = np.array([offset_n[0], offset_n[1], 1.0])
    d /= np.linalg.norm(d)
    # R_device_world maps the world z axis onto d; the roll is about the device's z.
    align, _ = Rotation.align_vectors([d], [[0.0, 0.0, 1.0]])
    roll = Rotation.from_rotvec([0.0, 0.0, -roll_rad])
    R_device_world = (align * roll).as_matrix()
    return Transform(R_device_world.T, np.zeros(3))


def chart_pose(
    size_m: tuple[float, float],
    distance_m: float,
    tilt_rad: np.ndarray,
    center_m: tuple[float, float] = (0.0, 0.0),
) -> Transform:
    """T_world_chart of a chart facing the world's −z viewer at ``distance_m`` (world = rest
    device frame), tilted by ``tilt_rad`` about its centre, centre at (center_m, distance)."""
    from phonestereo.sim.scene import facing_pose

    return facing_pose(size_m, distance_m, tilt_rad=tilt_rad, center_m=center_m)


def verification_scene(module: ModuleSpec, distance_m: float, tilt: np.ndarray) -> Scene:
    """The verification chart facing the device at ``distance_m``, tilted by ``tilt`` (rad),
    centred on the baseline midpoint."""
    chart = VerificationChart()
    pose = chart_pose(chart.size_m, distance_m, tilt, baseline_midpoint(module))
    return Scene((PlanarObject(chart, pose, "chart"),))


def baseline_midpoint(module: ModuleSpec) -> tuple[float, float]:
    """(x, y) of the midpoint between the two optical centres (metres, device frame)."""
    c = fx.tele_center_m(module)
    return float(c[0] / 2), float(c[1] / 2)
