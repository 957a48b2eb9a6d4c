"""The true per-capture state of the virtual module, and rendering it (docs/architecture.md).

:func:`true_state` composes the effects of :mod:`phonestereo.sim.effects` into one frozen
:class:`CaptureState`: the true wide and tele cameras at this capture (focus breathing, lens
travel, heating drift, sag), the true T_tele_wide, the device pose in the world (hand shake),
gravity, temperature and what the module reports. :func:`render_capture` turns a state and a
scene into the two 8-bit images a phone would give.

The calibration-condition cameras (cold, calibration focus, landscape, no noise) are what the
per-capture focal scale and principal-point shift of the ground truth are relative to.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.sim import effects as fx
from phonestereo.sim.lensfit import fit_even_lens
from phonestereo.sim.module import ModuleSpec
from phonestereo.sim.scene import Scene

Role = Literal["wide", "tele"]
ROLES: tuple[Role, Role] = ("wide", "tele")


@dataclass(frozen=True)
class CaptureConditions:
    """What the scenario asks for at one capture (the simulator adds the randomness)."""

    #: Capture id (unique in the set).
    id: str
    #: Manifest kind.
    kind: Literal["verification", "face", "scene"]
    #: Seconds since the camera app started (drives heating).
    time_s: float
    #: Nominal device pose in the world (before hand shake).
    T_world_device: Transform
    #: Hand shake on this capture (False: tripod).
    handheld: bool
    #: Manual focus at ``focus_m`` or autofocus on a subject at ``focus_m``.
    focus_mode: Literal["manual", "auto"]
    #: Manual focus distance or autofocus subject distance, metres.
    focus_m: float
    #: ``focus_group``, ``focus_attempt``: str or None, int or None. Refocus stack name and index.
    focus_group: str | None = None
    #: See ``focus_group`` above.
    focus_attempt: int | None = None
    #: Standard-normal draws of the (wide, tele) lens-position noise to use instead of fresh ones:
    #: captures that share them have the focus locked (thesis §3.1 heating runs).
    lens_noise: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.focus_m <= 0 or not np.isfinite(self.focus_m):
            raise InputError(f"capture {self.id!r}: focus_m must be > 0 m, got {self.focus_m}")
        if self.time_s < 0:
            raise InputError(f"capture {self.id!r}: time_s must be >= 0, got {self.time_s}")


@dataclass(frozen=True)
class CameraState:
    """One camera's true state at a capture."""

    #: The true camera (K, lens) at this capture.
    camera: Camera
    #: Distance the lens is focused at (after autofocus error / failure).
    focus_distance_m: float
    #: Lens-to-sensor distance v, metres.
    image_distance_m: float
    #: fx / fx of the calibration-condition true camera (focus breathing, eq. 8's s).
    focal_scale: float
    #: (cx, cy) minus the calibration-condition true camera's, pixels.
    principal_point_shift_px: tuple[float, float]
    #: Autofocus missed the subject.
    af_failed: bool
    #: What the module reports (lens travel in µm plus noise), if it reports it.
    reported_focus_position: float | None


@dataclass(frozen=True)
class CaptureState:
    """The true state of the module at one capture (everything the ground truth records)."""

    conditions: CaptureConditions
    T_world_device: Transform
    T_tele_wide: Transform
    gravity: tuple[float, float, float]
    temperature_c: float
    wide: CameraState
    tele: CameraState

    @property
    def id(self) -> str:
        """Capture id."""
        return self.conditions.id

    @property
    def orientation(self) -> str:
        """Orientation label from gravity."""
        return fx.orientation_label(self.gravity)

    @property
    def rig(self) -> Rig:
        """The true rig at this capture."""
        return Rig(self.wide.camera, self.tele.camera, self.T_tele_wide)

    def camera(self, role: Role) -> CameraState:
        """The wide or tele state."""
        return self.wide if role == "wide" else self.tele

    def T_cam_world(self, role: Role) -> Transform:
        """World → camera transform of one camera (the wide frame is the device frame)."""
        T_wide_world = self.T_world_device.inverse()
        return T_wide_world if role == "wide" else self.T_tele_wide @ T_wide_world


def true_camera(
    spec: ModuleSpec, role: Role, time_s: float, gravity: tuple[float, float, float], v_m: float
) -> Camera:
    """The true camera of ``role`` at a time, gravity and lens position v (metres)."""
    cam = spec.camera(role)
    f = fx.focal_px(spec, role, v_m)
    cx, cy = cam.principal_point_px
    for dx, dy in (
        fx.heating_drift_px(spec, role, time_s),
        fx.sag_shift_px(spec, role, gravity),
        fx.focus_principal_point_shift_px(spec, role, v_m),
    ):
        cx, cy = cx + dx, cy + dy
    camera = Camera(cam.size, f, f, cx, cy, fx.lens_at_focus(spec, role, v_m))
    if not spec.effects.odd_distortion and camera.lens.name != "opencv5":
        camera = fit_even_lens(camera)  # the true lens is then exactly what a factory models
    return camera


@functools.lru_cache(maxsize=64)
def calibration_camera(spec: ModuleSpec, role: Role) -> Camera:
    """The true camera at calibration conditions (cold, calibration focus, landscape)."""
    return true_camera(
        spec,
        role,
        spec.calibration.time_s,
        fx.calibration_gravity(spec),
        fx.calibration_image_distance_m(spec, role),
    )


def calibration_rig(spec: ModuleSpec) -> Rig:
    """The true rig at calibration conditions (what a perfect factory calibration measures)."""
    return Rig(
        calibration_camera(spec, "wide"),
        calibration_camera(spec, "tele"),
        fx.true_T_tele_wide(spec),
    )


def true_state(
    spec: ModuleSpec, conditions: CaptureConditions, rng: np.random.Generator
) -> CaptureState:
    """Draw the true state of one capture.

    The random draws are made in a fixed order whatever the switches, so switching one effect
    off changes only that effect's contribution (the other effects keep their values).
    """
    shake = fx.handheld_offset(spec, rng)
    pose = conditions.T_world_device @ shake if conditions.handheld else conditions.T_world_device
    gravity = fx.device_gravity(pose)
    t = conditions.time_s
    states: dict[str, CameraState] = {}
    travel: dict[str, float] = {}
    for k, role in enumerate(ROLES):
        focus_m, failed = fx.autofocus_distance(spec, role, conditions.focus_m, rng)
        if conditions.focus_mode == "manual":
            focus_m, failed = conditions.focus_m, False
        eps = float(rng.normal())
        if conditions.lens_noise is not None:
            eps = conditions.lens_noise[k]
        v = fx.lens_image_distance_m(spec, role, focus_m, eps)
        report = fx.reported_focus_position(spec, role, v, rng)
        camera = true_camera(spec, role, t, gravity, v)
        ref = calibration_camera(spec, role)
        states[role] = CameraState(
            camera=camera,
            focus_distance_m=float(focus_m),
            image_distance_m=v,
            focal_scale=camera.fx / ref.fx,
            principal_point_shift_px=(camera.cx - ref.cx, camera.cy - ref.cy),
            af_failed=failed,
            reported_focus_position=report,
        )
        travel[role] = fx.lens_travel_um(spec, role, v)
    return CaptureState(
        conditions=conditions,
        T_world_device=pose,
        T_tele_wide=fx.true_T_tele_wide(spec, travel["wide"], travel["tele"]),
        gravity=gravity,
        temperature_c=fx.temperature_c(spec, t),
        wide=states["wide"],
        tele=states["tele"],
    )


@dataclass(frozen=True)
class CapturedImage:
    """One camera's output at a capture."""

    #: ndarray, shape (H, W), uint8. The grey image the pipeline reads (``io.read_gray`` of the
    #: stored file).
    gray: NDArray[np.uint8]
    #: The file a phone stores (JPEG or PNG bytes from the ISP); None on the linear path, where
    #: ``gray`` is written as a PNG.
    data: bytes | None
    #: ``.jpg`` or ``.png``.
    suffix: str


def image_suffix(spec: ModuleSpec, role: str) -> str:
    """Suffix of a camera's image files: ``.jpg`` if its active ISP encodes JPEG, else ``.png``."""
    isp = spec.isp(role)
    return ".jpg" if isp is not None and isp.jpeg_quality is not None else ".png"


def render_capture_images(
    spec: ModuleSpec, state: CaptureState, scene: Scene, rng: np.random.Generator
) -> tuple[CapturedImage, CapturedImage]:
    """Render both cameras of a capture: scene → optics → sensor (→ ISP) → (wide, tele).

    Defocus blur follows each camera's focus distance (switch ``defocus``); shot and read
    noise follow the camera's sensor spec (switch ``sensor_noise``); a camera with an ``isp``
    block goes through :func:`phonestereo.sim.isp.isp_file` (switch ``isp``), otherwise through
    the linear grey :func:`phonestereo.sim.sensor.capture` (exactly the path before the ISP).
    """
    from phonestereo.sim import isp as isp_mod
    from phonestereo.sim import optics, sensor
    from phonestereo.sim.render import render_view

    images = []
    for role in ROLES:
        cam_spec = spec.camera(role)
        cs = state.camera(role)
        blur = None
        if spec.effects.defocus:
            blur = optics.defocus_sigma_function(
                cam_spec.focal_length_m,
                cam_spec.f_number,
                cs.focus_distance_m,
                cam_spec.pixel_pitch_m,
            )
        view = render_view(cs.camera, state.T_cam_world(role), scene, defocus_sigma_px=blur)
        model = sensor.SensorModel(**cam_spec.sensor.model_dump())
        isp = spec.isp(role)
        if isp is None:
            gray = sensor.capture(view.radiance, rng, model, noise=spec.effects.sensor_noise)
            images.append(CapturedImage(gray, None, ".png"))
        else:
            data, suffix = isp_mod.isp_file(
                view.radiance, isp, model, rng, noise=spec.effects.sensor_noise
            )
            images.append(CapturedImage(isp_mod.gray_of_file(data), data, suffix))
    return images[0], images[1]


def render_capture(
    spec: ModuleSpec, state: CaptureState, scene: Scene, rng: np.random.Generator
) -> tuple[NDArray[np.uint8], NDArray[np.uint8]]:
    """The two grey 8-bit images (wide, tele) the pipeline reads (:func:`render_capture_images`)."""
    wide, tele = render_capture_images(spec, state, scene, rng)
    return wide.gray, tele.gray
