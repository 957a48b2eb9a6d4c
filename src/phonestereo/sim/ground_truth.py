"""``ground_truth.json`` of a simulated capture set: schema, builder, writer and reader.

Only :mod:`phonestereo.sim` and :mod:`phonestereo.evaluation` may read it (the ground-truth
wall of docs/architecture.md).
Per capture it holds the true state (per-camera focal scale relative to the
calibration-condition true camera, principal-point shift in pixels, temperature, gravity,
focus distance, autofocus failure, the true cameras and T_tele_wide, the device pose) and per
object its keypoints (ids, true wide and tele pixels — NaN where not visible, stored as
``null`` — and true depth Z in the wide frame, metres); for verification captures the ROI and
its true depth.

Examples
--------
>>> kp = KeypointSet(ids=[[0, 0]], wide_px=[[None, None]], tele_px=[[2.0, 3.0]], depth_m=[2.0])
>>> kp.arrays().wide_px.tolist()
[[nan, nan]]
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, ValidationError

from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.sim.capture import CaptureState
from phonestereo.sim.scene import Scene
from phonestereo.sim.truth import KeypointTruth, keypoint_truth, roi_depth_m

GROUND_TRUTH_NAME = "ground_truth.json"
_CFG = ConfigDict(extra="forbid", frozen=True)
PX_DECIMALS = 6  # 1e-6 px: far below any sub-pixel claim, keeps the file small
M_DECIMALS = 9  # 1 nm

Opt = float | None


def _num(v: float, decimals: int) -> float | None:
    return None if not math.isfinite(v) else round(float(v), decimals)


def _pairs(a: np.ndarray) -> list[tuple[Opt, Opt]]:
    """(N, 2) → list of pairs, a point with any NaN coordinate becomes (None, None)."""
    bad = ~np.isfinite(a).all(axis=1)
    return [
        (None, None) if b else (_num(x, PX_DECIMALS), _num(y, PX_DECIMALS))
        for (x, y), b in zip(a.tolist(), bad.tolist(), strict=True)
    ]


def _array(rows: list[tuple[Opt, Opt]]) -> np.ndarray:
    out = np.array([[np.nan if v is None else v for v in r] for r in rows], dtype=np.float64)
    return out.reshape(-1, 2)


class KeypointSet(BaseModel):
    """True pixels and depths of one keypoint set (e.g. chessboard corners) of one object."""

    model_config = _CFG
    ids: list[list[int]]
    wide_px: list[tuple[Opt, Opt]]
    tele_px: list[tuple[Opt, Opt]]
    depth_m: list[Opt]

    def arrays(self) -> KeypointTruth:
        """As arrays: ids (N, k), wide_px / tele_px (N, 2) with NaN, depth_m (N,)."""
        depth = np.array([np.nan if v is None else v for v in self.depth_m], dtype=np.float64)
        ids = np.array(self.ids, dtype=np.int64).reshape(len(self.ids), -1)
        return KeypointTruth(ids, _array(self.wide_px), _array(self.tele_px), depth)


class ObjectTruth(BaseModel):
    """One posed object of the scene."""

    model_config = _CFG
    name: str
    chart: str
    T_world_chart: dict[str, Any]
    keypoints: dict[str, KeypointSet]


class CameraTruth(BaseModel):
    """One camera's true state at a capture."""

    model_config = _CFG
    focal_scale: float
    principal_point_shift_px: tuple[float, float]
    focus_distance_m: float
    image_distance_m: float
    af_failed: bool
    camera: dict[str, Any]

    def true_camera(self) -> Camera:
        """The true Camera."""
        return Camera.from_dict(self.camera)


class CaptureTruth(BaseModel):
    """Everything true about one capture."""

    model_config = _CFG
    id: str
    kind: str
    time_s: float
    temperature_c: float
    gravity: tuple[float, float, float]
    orientation: str
    focus_mode: Literal["manual", "auto"]
    focus_target_m: float
    focus_group: str | None
    focus_attempt: int | None
    handheld: bool
    T_world_device: dict[str, Any]
    T_tele_wide: dict[str, Any]
    wide: CameraTruth
    tele: CameraTruth
    objects: list[ObjectTruth]
    roi: tuple[int, int, int, int] | None = None
    roi_depth_m: float | None = None

    def true_rig(self) -> Rig:
        """The true rig at this capture."""
        return Rig(
            self.wide.true_camera(),
            self.tele.true_camera(),
            Transform.from_dict(self.T_tele_wide),
        )

    def object(self, name: str) -> ObjectTruth:
        """An object by name (InputError listing the names if absent)."""
        for o in self.objects:
            if o.name == name:
                return o
        raise InputError(
            f"capture {self.id!r} has no object {name!r}; objects: {[o.name for o in self.objects]}"
        )


class GroundTruth(BaseModel):
    """The whole ``ground_truth.json``."""

    model_config = _CFG
    schema_version: Literal[1] = 1
    scenario: str
    seed: int
    module: dict[str, Any]
    calibration_true: dict[str, Any]
    captures: list[CaptureTruth]
    #: The plan's notes: distances/focus re-planned for the module, what it cannot cover.
    notes: list[str] = []

    def capture(self, capture_id: str) -> CaptureTruth:
        """One capture by id (InputError naming the known ids if absent)."""
        for c in self.captures:
            if c.id == capture_id:
                return c
        known = [c.id for c in self.captures]
        raise InputError(f"ground truth has no capture {capture_id!r}; known ids: {known}")


def _camera_truth(state: CaptureState, role: Literal["wide", "tele"]) -> CameraTruth:
    cs = state.camera(role)
    dx, dy = cs.principal_point_shift_px
    return CameraTruth(
        focal_scale=cs.focal_scale,
        principal_point_shift_px=(dx, dy),
        focus_distance_m=cs.focus_distance_m,
        image_distance_m=cs.image_distance_m,
        af_failed=cs.af_failed,
        camera=cs.camera.to_dict(),
    )


def capture_truth(
    state: CaptureState, scene: Scene, roi: tuple[int, int, int, int] | None = None
) -> CaptureTruth:
    """Build the ground truth of one capture from its true state and scene (no rendering)."""
    objects = []
    for obj, entry in zip(scene.objects, keypoint_truth(state, scene.objects), strict=True):
        sets = {
            key: KeypointSet(
                ids=kt.ids.tolist(),
                wide_px=_pairs(kt.wide_px),
                tele_px=_pairs(kt.tele_px),
                depth_m=[_num(z, M_DECIMALS) for z in kt.depth_m.tolist()],
            )
            for key, kt in entry["keypoints"].items()
        }
        objects.append(
            ObjectTruth(
                name=entry["name"],
                chart=entry["chart"],
                T_world_chart=obj.T_world_chart.to_dict(),
                keypoints=sets,
            )
        )
    c = state.conditions
    return CaptureTruth(
        id=c.id,
        kind=c.kind,
        time_s=c.time_s,
        temperature_c=state.temperature_c,
        gravity=state.gravity,
        orientation=state.orientation,
        focus_mode=c.focus_mode,
        focus_target_m=c.focus_m,
        focus_group=c.focus_group,
        focus_attempt=c.focus_attempt,
        handheld=c.handheld,
        T_world_device=state.T_world_device.to_dict(),
        T_tele_wide=state.T_tele_wide.to_dict(),
        wide=_camera_truth(state, "wide"),
        tele=_camera_truth(state, "tele"),
        objects=objects,
        roi=roi,
        roi_depth_m=None if roi is None else _num(roi_depth_m(state, scene.objects, roi), 9),
    )


def ground_truth_json(gt: GroundTruth) -> str:
    """Deterministic JSON text (equal ground truth → equal bytes)."""
    return json.dumps(gt.model_dump(mode="json"), indent=1, allow_nan=False) + "\n"


def write_ground_truth(path: str | os.PathLike[str], gt: GroundTruth) -> Path:
    """Write ``ground_truth.json`` (a folder path gets the standard file name)."""
    p = Path(path)
    if p.is_dir():
        p = p / GROUND_TRUTH_NAME
    p.write_text(ground_truth_json(gt))
    return p


def load_ground_truth(path: str | os.PathLike[str]) -> GroundTruth:
    """Read and validate ``ground_truth.json`` (a capture-set folder or the file itself).

    Raises
    ------
    InputError
        Missing file, malformed JSON (line, column) or an invalid field (named).
    """
    p = Path(path)
    if p.is_dir():
        p = p / GROUND_TRUTH_NAME
    if not p.is_file():
        raise InputError(f"no ground truth at {p}: only simulated capture sets have one")
    try:
        data = json.loads(p.read_text())
    except json.JSONDecodeError as exc:
        raise InputError(f"{p} is not valid JSON: {exc.msg} at line {exc.lineno}") from None
    try:
        return GroundTruth.model_validate(data)
    except ValidationError as err:
        first = err.errors()[0]
        loc = ".".join(str(x) for x in first["loc"])
        raise InputError(f"{p}: field '{loc}': {first['msg']}") from None
