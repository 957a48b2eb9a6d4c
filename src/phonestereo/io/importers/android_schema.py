"""The Android dump format (docs/import-android.md) as pydantic schemas.

A capture app writes ``DUMP/session.json`` once per camera session and one
``DUMP/captures/<name>.json`` per capture, beside the images. Every Camera2 value keeps its
Camera2 key name (``android.lens.intrinsicCalibration``, ...) and unit; arrays may be JSON
lists or the comma-separated strings ``Arrays.toString`` prints. Rectangles are
``android.graphics.Rect`` fields ``[left, top, right, bottom]`` (right and bottom exclusive),
in the pixel-array coordinates Camera2 reports them in.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, field_validator

from phonestereo.io.importers.dump_schema import CaptureLabels, before

FORMAT_SESSION = "phonestereo-android-session"
FORMAT_CAPTURE = "phonestereo-android-capture"
POSE_REFERENCES = {0: "PRIMARY_CAMERA", 1: "GYROSCOPE", 2: "UNDEFINED", 3: "AUTOMOTIVE"}

_STRICT = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False, populate_by_name=True)


def _numbers(value: Any, n: int, what: str) -> tuple[float, ...]:
    if isinstance(value, str):
        try:
            value = [float(v) for v in value.strip("[] ").split(",")]
        except ValueError as exc:
            raise ValueError(f"not a list of numbers ({exc}); give {n} numbers: {what}") from exc
    if not isinstance(value, list | tuple):
        raise ValueError(f"must be a list of {n} numbers ({what}), got {value!r}")
    if len(value) != n:
        raise ValueError(f"needs {n} numbers ({what}), got {len(value)}")
    out = []
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ValueError(f"{v!r} is not a number ({what})")
        if not math.isfinite(v):
            raise ValueError(
                f"non-finite value {v!r}: the device reported no valid value; re-export the "
                "dump, or leave the key out where it is optional"
            )
        out.append(float(v))
    return tuple(out)


def _numbers_of(n: int, what: str, *, optional: bool = False) -> BeforeValidator:
    """A field's check: :func:`_numbers` of ``n`` numbers (``what``)."""
    return before(lambda v: _numbers(v, n, what), optional=optional)


def _rect(value: Any) -> tuple[int, int, int, int]:
    nums = _numbers(value, 4, "Rect [left, top, right, bottom] in pixels")
    if any(v != int(v) for v in nums) or nums[2] <= nums[0] or nums[3] <= nums[1]:
        raise ValueError(
            f"must be integer [left, top, right, bottom] with right > left and "
            f"bottom > top, got {list(nums)}"
        )
    left, top, right, bottom = (int(v) for v in nums)
    return left, top, right, bottom


#: A ``Rect`` field, checked by :func:`_rect`.
_Rect = Annotated[tuple[int, int, int, int], before(_rect)]


class AndroidCharacteristics(BaseModel):
    """One physical camera's ``CameraCharacteristics`` (keys under their Camera2 names)."""

    model_config = _STRICT

    intrinsic_calibration: Annotated[
        tuple[float, ...], _numbers_of(5, "[f_x, f_y, c_x, c_y, s]")
    ] = Field(alias="android.lens.intrinsicCalibration")
    distortion: Annotated[
        tuple[float, ...] | None, _numbers_of(5, "[k1, k2, k3, p1, p2]", optional=True)
    ] = Field(None, alias="android.lens.distortion")
    pose_rotation: tuple[float, ...] = Field(alias="android.lens.poseRotation")
    pose_translation: Annotated[
        tuple[float, ...], _numbers_of(3, "optical-centre position (x, y, z) in metres")
    ] = Field(alias="android.lens.poseTranslation")
    pose_reference: int = Field(alias="android.lens.poseReference")
    active_array: _Rect = Field(alias="android.sensor.info.activeArraySize")
    pre_correction_array: _Rect = Field(alias="android.sensor.info.preCorrectionActiveArraySize")
    sensor_orientation: Literal[0, 90, 180, 270] = Field(alias="android.sensor.orientation")
    facing: Literal[1] = Field(1, alias="android.lens.facing")
    minimum_focus_distance: float | None = Field(
        None, alias="android.lens.info.minimumFocusDistance", ge=0
    )
    available_focal_lengths: tuple[float, ...] | None = Field(
        None, alias="android.lens.info.availableFocalLengths"
    )

    @field_validator("available_focal_lengths", mode="before")
    @classmethod
    def _focal_lengths(cls, v: Any) -> tuple[float, ...] | None:
        if v is None:
            return None
        vals = [v] if isinstance(v, int | float) and not isinstance(v, bool) else v
        if not isinstance(vals, list | tuple) or not vals or not all(
            isinstance(x, int | float) and not isinstance(x, bool) and 0 < x < 100 for x in vals
        ):
            raise ValueError(f"must be focal lengths in millimetres (0–100), got {v!r}")
        return tuple(float(x) for x in vals)

    @field_validator("pose_rotation", mode="before")
    @classmethod
    def _q(cls, v: Any) -> tuple[float, ...]:
        q = _numbers(v, 4, "quaternion (x, y, z, w)")
        norm = math.sqrt(sum(c * c for c in q))
        if abs(norm - 1.0) > 1e-3:
            raise ValueError(f"must be a unit quaternion (x, y, z, w), got |q| = {norm:.6g}")
        return tuple(c / norm for c in q)

    @field_validator("pose_reference")
    @classmethod
    def _ref(cls, v: int) -> int:
        if v not in (0, 1):
            name = POSE_REFERENCES.get(v, "unknown")
            raise ValueError(
                f"poseReference {v} ({name}) cannot place the two cameras relative to each "
                "other; phonestereo accepts PRIMARY_CAMERA (0) or GYROSCOPE (1). Calibrate "
                "the rig yourself instead (`phonestereo calibrate`) and give that calibration"
            )
        return v


class AndroidSession(BaseModel):
    """``session.json``: the session's first frame and each physical camera's characteristics."""

    model_config = _STRICT

    format: Literal["phonestereo-android-session"]
    version: Literal[1]
    first_frame_timestamp_ns: int = Field(ge=0)
    cameras: dict[str, AndroidCharacteristics]

    @field_validator("cameras")
    @classmethod
    def _two(cls, v: dict[str, AndroidCharacteristics]) -> dict[str, AndroidCharacteristics]:
        if len(v) != 2:
            raise ValueError(
                f"needs exactly the two physical cameras of the stereo pair, got {sorted(v)}"
            )
        return v


class AndroidResult(BaseModel):
    """One physical camera's ``CaptureResult`` values for one capture, and its image."""

    model_config = _STRICT

    image: str
    sensor_timestamp: int = Field(alias="android.sensor.timestamp", ge=0)
    af_mode: int = Field(alias="android.control.afMode", ge=0, le=5)
    focus_distance: float | None = Field(None, alias="android.lens.focusDistance", ge=0)
    crop_region: Annotated[tuple[int, int, int, int] | None, before(_rect, optional=True)] = (
        Field(None, alias="android.scaler.cropRegion")
    )
    distortion_correction_mode: Literal[0, 1, 2] = Field(
        0, alias="android.distortionCorrection.mode"
    )


class AndroidCapture(CaptureLabels):
    """``captures/<name>.json``: one capture's results, accelerometer and app-level labels."""

    model_config = _STRICT

    format: Literal["phonestereo-android-capture"]
    accelerometer: tuple[float, float, float] | None = None
    cameras: dict[str, AndroidResult]
