"""The Apple dump format (docs/import-apple.md) as pydantic schemas.

``DUMP/session.json`` holds each camera's ``AVCameraCalibrationData`` (from
``AVCapturePhoto.cameraCalibrationData`` of a constituent-photo delivery) under its
AVFoundation property names and the session's first frame time; ``DUMP/captures/<name>.json``
holds one capture: per camera the image, ``AVCapturePhoto.timestamp`` and the device's
``focusMode`` / ``lensPosition``, plus ``CMDeviceMotion.gravity``. simd matrices are given as
their flat column-major float lists, exactly as they lie in memory.
"""

from __future__ import annotations

import math
from typing import Annotated, Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, field_validator

from phonestereo.io.importers.dump_schema import CaptureLabels, before

FORMAT_SESSION = "phonestereo-apple-session"
FORMAT_CAPTURE = "phonestereo-apple-capture"
_STRICT = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)


def _floats(value: Any, n: int | None, what: str) -> tuple[float, ...]:
    if not isinstance(value, list | tuple):
        raise ValueError(f"must be a list of numbers ({what}), got {value!r}")
    if n is not None and len(value) != n:
        raise ValueError(f"needs {n} numbers ({what}), got {len(value)}")
    for v in value:
        if isinstance(v, bool) or not isinstance(v, int | float):
            raise ValueError(f"{v!r} is not a number ({what})")
        if not math.isfinite(v):
            raise ValueError(f"non-finite value {v!r} ({what}); re-export the dump")
    return tuple(float(v) for v in value)


def _floats_of(n: int, what: str) -> BeforeValidator:
    """A field's check: :func:`_floats` of ``n`` numbers (``what``)."""
    return before(lambda v: _floats(v, n, what))


def _lut(value: Any) -> tuple[float, ...]:
    out = _floats(value, None, "Float magnifications at radii 0 … r_max")
    if len(out) < 2:
        raise ValueError(f"needs at least 2 values, got {len(out)}")
    return out


#: A distortion lookup table: >= 2 finite magnifications (:func:`_lut`).
_Lut = Annotated[tuple[float, ...], before(_lut)]


class Size(BaseModel):
    """A ``CGSize`` in pixels."""

    model_config = _STRICT
    width: float = Field(gt=0)
    height: float = Field(gt=0)


class Point(BaseModel):
    """A ``CGPoint`` in pixels (origin: the top-left corner of the image)."""

    model_config = _STRICT
    x: float
    y: float


class AppleCalibration(BaseModel):
    """One camera's ``AVCameraCalibrationData``."""

    model_config = _STRICT

    intrinsicMatrix: Annotated[
        tuple[float, ...], _floats_of(9, "simd_float3x3, 9 numbers column-major")
    ]
    intrinsicMatrixReferenceDimensions: Size
    extrinsicMatrix: Annotated[
        tuple[float, ...],
        _floats_of(12, "matrix_float4x3, 12 numbers column-major: R's 3 columns, then t"),
    ]
    pixelSize: float = Field(gt=0)
    lensDistortionCenter: Point
    lensDistortionLookupTable: _Lut
    inverseLensDistortionLookupTable: _Lut


class AppleSession(BaseModel):
    """``session.json``."""

    model_config = _STRICT

    format: Literal["phonestereo-apple-session"]
    version: Literal[1]
    first_frame_time_s: float
    cameras: dict[str, AppleCalibration]

    @field_validator("cameras")
    @classmethod
    def _two(cls, v: dict[str, AppleCalibration]) -> dict[str, AppleCalibration]:
        if len(v) != 2:
            raise ValueError(f"needs exactly the two cameras of the stereo pair, got {sorted(v)}")
        return v


class AppleShot(BaseModel):
    """One camera's photo of a capture."""

    model_config = _STRICT

    image: str
    timestamp_s: float
    focusMode: Literal[0, 1, 2]
    lensPosition: float | None = Field(None, ge=0, le=1)


class AppleCapture(CaptureLabels):
    """``captures/<name>.json``."""

    model_config = _STRICT

    format: Literal["phonestereo-apple-capture"]
    gravity: tuple[float, float, float] | None = None
    cameras: dict[str, AppleShot]
