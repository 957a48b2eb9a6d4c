"""Shared parts of the phone importers: pixel-frame conversion, rotations, value checks and the
all-or-nothing writer of a capture set (docs/import-android.md, docs/import-apple.md).

Pixel conventions. Android Camera2 and Apple AVFoundation put ``(0, 0)`` at the *top-left
corner* of the top-left pixel, so the centre of pixel ``(i, j)`` is at ``(i + 0.5, j + 0.5)``
(Android: ``CameraCharacteristics.LENS_INTRINSIC_CALIBRATION``, "the center of pixel (x,y) is
located at coordinate (x + 0.5, y + 0.5)"; Apple: ``AVCameraCalibrationData.intrinsicMatrix``,
"the origin is the upper left of the frame"). phonestereo puts ``(0, 0)`` at the *centre* of
the top-left pixel. A platform point ``u`` inside a region whose top-left corner is at
``left`` and that is resampled by ``scale`` to the output image therefore lands at::

    x = scale · (u − left) − 0.5                                             (1)

so a camera matrix K becomes ``f' = scale·f``, ``s' = scale·s``, ``c' = scale·(c − left) − 0.5``
(:func:`platform_K_to_image`). The lens model acts on normalised coordinates and is unchanged.

Examples
--------
>>> platform_K_to_image([2000.0, 2000.0, 1000.0, 750.0, 0.0], (0.0, 0.0), (0.5, 0.5)).tolist()[0]
[1000.0, 0.0, 499.5]
"""

from __future__ import annotations

import os
import shutil
import uuid
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError
from phonestereo.geometry.transform import (
    ORTHONORMAL_TOLERANCE,
    nearest_rotation,
    orthonormality_error,
)
from phonestereo.io import json_text
from phonestereo.io.calibration import Calibration, save_calibration
from phonestereo.io.manifest import CaptureEntry, Manifest, write_manifest

STANDARD_GRAVITY = 9.80665  # m/s², the accelerometer's 1 g


@dataclass(frozen=True)
class ImportResult:
    """What an importer wrote and how it converted."""

    #: The capture-set folder.
    out: Path
    #: Number of captures written.
    captures: int
    #: dict. Which platform camera became ``wide`` and which ``tele`` (decided by focal length).
    tele_role: dict[str, str]
    #: dict. Per camera, the max residual in pixels of a lens-model fit (Apple lookup tables); empty
    #: when the platform's model is ours exactly (Android).
    lens_fit_px: dict[str, float] = field(default_factory=dict)
    #: tuple of str. Every conversion decision worth telling the user (re-orthonormalised rotations,
    #: ...).
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary."""
        return {
            "out": str(self.out),
            "captures": self.captures,
            "cameras": self.tele_role,
            "lens_fit_px": self.lens_fit_px,
            "notes": list(self.notes),
        }


def platform_K_to_image(
    intrinsics: Sequence[float], left_top: Sequence[float], scale: Sequence[float]
) -> NDArray[np.float64]:
    """Camera matrix in output-image pixels (our centre convention) from platform intrinsics.

    Parameters
    ----------
    intrinsics : (5,) [f_x, f_y, c_x, c_y, s]
        In platform pixels with (0, 0) at the top-left *corner* of the reference array.
    left_top : (2,)
        Top-left corner of the region the output image shows, platform pixels.
    scale : (2,)
        Output pixels per platform pixel along x and y.

    Returns
    -------
    ndarray, shape (3, 3)
        K by eq. (1) of the module docstring.
    """
    fx, fy, cx, cy, s = (float(v) for v in intrinsics)
    sx, sy = (float(v) for v in scale)
    lx, ty = (float(v) for v in left_top)
    return np.array(
        [
            [sx * fx, sx * s, sx * (cx - lx) - 0.5],
            [0.0, sy * fy, sy * (cy - ty) - 0.5],
            [0.0, 0.0, 1.0],
        ]
    )


def image_to_platform_K(K: Any, left_top: Sequence[float], scale: Sequence[float]) -> list[float]:
    """Inverse of :func:`platform_K_to_image`: ``[f_x, f_y, c_x, c_y, s]`` in platform pixels."""
    k = np.asarray(K, dtype=np.float64)
    sx, sy = (float(v) for v in scale)
    lx, ty = (float(v) for v in left_top)
    return [
        float(k[0, 0] / sx),
        float(k[1, 1] / sy),
        float((k[0, 2] + 0.5) / sx + lx),
        float((k[1, 2] + 0.5) / sy + ty),
        float(k[0, 1] / sx),
    ]


def image_size(path: Path, key: str, source: str) -> tuple[int, int]:
    """(width, height) of an image file from its header (no EXIF rotation is applied)."""
    from PIL import Image, UnidentifiedImageError

    if not path.is_file():
        raise InputError(
            f"{source}: key '{key}': image file not found: '{path}'; put the image beside the "
            "dump JSON or fix the path (relative to the dump folder)"
        )
    try:
        with Image.open(path) as im:
            return int(im.size[0]), int(im.size[1])
    except (OSError, UnidentifiedImageError) as exc:
        raise InputError(f"{source}: key '{key}': cannot read image '{path}': {exc}") from exc


def nearest_rotation_checked(
    R: Any, key: str, source: str, notes: list[str]
) -> NDArray[np.float64]:
    """A printed rotation snapped to the nearest rotation (SVD) when orthonormal to 1e-6."""
    r = np.asarray(R, dtype=np.float64)
    err = orthonormality_error(r)
    if err > ORTHONORMAL_TOLERANCE or np.linalg.det(r) <= 0:
        raise InputError(
            f"{source}: key '{key}': not a rotation (orthonormal only to {err:.2g}, det "
            f"{np.linalg.det(r):.6g}); check the column order (the platform stores columns)"
        )
    if err > 1e-12:
        notes.append(f"{key}: orthonormal to {err:.2g}; snapped to the nearest rotation (SVD)")
        return nearest_rotation(r)
    return r


def write_set_atomically(
    out: str | os.PathLike[str],
    calibration: Calibration,
    manifest: Manifest,
    images: Iterable[tuple[Path, str]],
) -> Path:
    """Write a capture set all-or-nothing: into a temporary folder beside ``out``, renamed at
    the end, so an error leaves nothing half-written.

    Parameters
    ----------
    out : path
        The capture-set folder; must not exist, or be an empty folder.
    calibration, manifest
        What to write as calibration.json and manifest.json.
    images : iterable of (source path, relative destination)
        Images copied (hard-linked when the file system allows) into the set.
    """
    dest = Path(out)
    if dest.exists() and (not dest.is_dir() or any(dest.iterdir())):
        raise InputError(
            f"output '{dest}' exists and is not an empty folder; choose a new --out (importers "
            "never overwrite a capture set)"
        )
    dest.parent.mkdir(parents=True, exist_ok=True)
    tmp = dest.parent / f".{dest.name}.importing-{uuid.uuid4().hex[:8]}"
    tmp.mkdir()
    try:
        for src, rel in images:
            target = tmp / rel
            target.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.link(src, target)
            except OSError:
                shutil.copy2(src, target)
        save_calibration(tmp / manifest.calibration, calibration)
        write_manifest(tmp, manifest)
        if dest.exists():
            dest.rmdir()
        os.replace(tmp, dest)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return dest


def validate_dump(model: Any, data: Any, source: str, doc: str) -> Any:
    """Validate a dump JSON object against its pydantic schema; :class:`InputError` naming the
    first bad keys (dotted path) and the document that lists them otherwise."""
    import pydantic

    try:
        return model.model_validate(data)
    except pydantic.ValidationError as exc:
        lines = []
        for err in exc.errors()[:5]:
            key = ".".join(str(p) for p in err["loc"]) or "(document)"
            msg = str(err["msg"]).removeprefix("Value error, ")
            if err["type"] == "missing":
                msg = "required key is missing"
            elif err["type"] == "extra_forbidden":
                msg = "unknown key (check the spelling)"
            lines.append(f"{source}: key '{key}': {msg}")
        more = f" (and {len(exc.errors()) - 5} more)" if len(exc.errors()) > 5 else ""
        raise InputError("\n".join(lines) + more + f"; the dump format is in {doc}") from None


def capture_entry(
    cap: Any,
    source: str,
    suffixes: tuple[str, str],
    time_s: float,
    gravity: tuple[float, float, float] | None,
    manual_focus: bool,
    focus_position: float | None,
) -> CaptureEntry:
    """The manifest entry of one dumped capture (both platforms' dumps share these fields).

    ``cap`` carries the dump's ``id``, ``orientation``, ``kind``, ``focus_group``,
    ``focus_attempt``, ``temperature_c`` and ``roi``; the images are
    ``images/<id>_{wide,tele}<suffix>``. A value the manifest refuses is an InputError naming
    the dump file ``source``.
    """
    try:
        return CaptureEntry(
            id=cap.id,
            wide=f"images/{cap.id}_wide{suffixes[0]}",
            tele=f"images/{cap.id}_tele{suffixes[1]}",
            time_s=round(time_s, 9),
            gravity=gravity,
            orientation=cap.orientation,
            kind=cap.kind,
            focus_group=cap.focus_group,
            focus_attempt=cap.focus_attempt,
            focus_mode="manual" if manual_focus else "auto",
            focus_position=focus_position,
            temperature_c=cap.temperature_c,
            roi=cap.roi,
        )
    except ValueError as exc:
        raise InputError(f"{source}: {exc}") from exc


def capture_gravity(
    source: str,
    key: str,
    raw: Any,
    to_gravity: Callable[[Any], Any],
    orientation: str | None,
) -> tuple[float, float, float] | None:
    """Gravity of one dumped capture (unit vector, wide camera frame) from its motion record.

    ``raw`` is the record under ``key`` (None: not in the dump), ``to_gravity`` the platform's
    conversion; without a record the capture must name its ``orientation`` bucket instead
    (then None). InputError prefixed with ``source`` otherwise.
    """
    if raw is None:
        if orientation is None:
            raise InputError(
                f"{source}: key '{key}': required key is missing (or give 'orientation', one of "
                "the orientation buckets); without it the orientation fix cannot be used"
            )
        return None
    try:
        g = to_gravity(raw)
    except InputError as exc:
        raise InputError(f"{source}: {exc}") from exc
    return (round(g[0], 9), round(g[1], 9), round(g[2], 9))


def read_json(path: Path, what: str) -> Any:
    """A JSON document (NaN/Infinity tokens are parsed and then refused by the schemas)."""
    if not path.is_file():
        raise InputError(f"{what} '{path}' not found; check the DUMP folder")
    return json_text.read_json(path, what)
