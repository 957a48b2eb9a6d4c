"""``phonestereo import apple``: an AVFoundation dump to a capture set (docs/import-apple.md).

Conversions, each from Apple's AVFoundation / Core Motion documentation
(developer.apple.com/documentation/avfoundation/avcameracalibrationdata):

* ``intrinsicMatrix`` is a ``simd_float3x3`` stored column-major (``[fx, 0, 0, s, fy, 0, cx,
  cy, 1]``) "relative to ``intrinsicMatrixReferenceDimensions``", origin "the upper left of the
  frame" (the corner, as Core Graphics). An image of another size with the same aspect ratio
  is a resampling: ``f' = scale·f``, ``c' = scale·c − 0.5`` (common.py eq. 1); another aspect
  ratio is refused.
* ``extrinsicMatrix`` is a ``matrix_float4x3``, column-major: R's three columns, then t in
  millimetres. It is "the camera's pose with respect to a reference camera (camera-to-world
  view)", read as ``X_ref = R·X_cam + t`` — the same relation
  ``AVCaptureDevice.extrinsicMatrix(from:to:)`` documents for ``X_to`` from ``X_from``. So
  ``T_ref_cam = (R, t/1000)`` and ``T_tele_wide = T_ref_tele⁻¹ · T_ref_wide``. Rotations printed
  with float precision are snapped to the nearest rotation (SVD) and the note says so.
* ``lensDistortionLookupTable`` / ``lensDistortionCenter``: fitted to ``radial-odd``
  (apple_lut.py); the fit's max residual is reported per camera. The inverse table is checked
  against the forward one and its disagreement reported.
* ``pixelSize`` (mm) gives the physical focal length ``fx·pixelSize`` reported in the note.
* Which camera is the tele: the larger ``fx`` per reference width (narrower field of view).
* ``time_s`` = ``AVCapturePhoto.timestamp`` of the wide photo − the session's first frame time.
* ``focus_mode`` = "manual" for ``AVCaptureDevice.FocusMode.locked`` (0), else "auto";
  ``focus_position`` = the wide camera's ``lensPosition`` (0–1, unitless).
* Gravity: ``CMDeviceMotion.gravity`` (in g, pointing to the earth) in the Core Motion device
  frame (x right, y to the top, z out of the screen). The back cameras' buffers are delivered
  in the sensor's native landscape orientation (``AVCaptureVideoOrientation.landscapeRight``:
  image x along the device's −y, image y along −x, optical axis −z), so gravity in our
  device frame is ``g = R_back · gravity/|gravity|`` with ``R_back`` below.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Rig, Transform
from phonestereo.io.calibration import Calibration, CalibrationConditions
from phonestereo.io.importers.apple_lut import fit_radial_odd_centred, inverse_consistency
from phonestereo.io.importers.apple_schema import AppleCalibration, AppleCapture, AppleSession
from phonestereo.io.importers.common import (
    ImportResult,
    capture_entry,
    capture_gravity,
    image_size,
    nearest_rotation_checked,
    platform_K_to_image,
    read_json,
    validate_dump,
    write_set_atomically,
)
from phonestereo.io.manifest import CaptureEntry, Manifest

DOC = "docs/import-apple.md"
R_BACK = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def intrinsic_matrix(cal: AppleCalibration, source: str, camera: str) -> NDArray[np.float64]:
    """K (3, 3) from the column-major ``intrinsicMatrix``, checked upper-triangular."""
    K = np.asarray(cal.intrinsicMatrix, dtype=np.float64).reshape(3, 3).T
    if abs(K[1, 0]) + abs(K[2, 0]) + abs(K[2, 1]) > 1e-9 or abs(K[2, 2] - 1) > 1e-9:
        raise InputError(
            f"{source}: camera '{camera}' key 'intrinsicMatrix': not an upper-triangular camera "
            f"matrix when read column-major ({K.tolist()}); write the simd columns in order "
            "(fx, 0, 0), (s, fy, 0), (cx, cy, 1)"
        )
    return K


def extrinsic_transform(columns: Any, key: str, source: str, notes: list[str]) -> Transform:
    """``T_to_from`` in metres from a column-major 4×3 extrinsic matrix (R columns, t in mm).

    ``extrinsicMatrix(from: A, to: B)`` gives ``T_B_A``; a camera's ``extrinsicMatrix`` gives
    ``T_ref_cam``.

    Examples
    --------
    >>> T = extrinsic_transform([1, 0, 0, 0, 1, 0, 0, 0, 1, -14.0, 0, 0], "e", "doc", [])
    >>> T.t.tolist()
    [-0.014, 0.0, 0.0]
    """
    m = np.asarray(columns, dtype=np.float64).reshape(4, 3).T
    R = nearest_rotation_checked(m[:, :3], key, source, notes)
    return Transform(R, m[:, 3] * 1e-3)


def output_camera(
    cal: AppleCalibration, size: tuple[int, int], source: str, camera: str, notes: list[str]
) -> tuple[Camera, float]:
    """The camera of one output image and its lens-fit residual in output pixels."""
    K_ref = intrinsic_matrix(cal, source, camera)
    ref = (
        cal.intrinsicMatrixReferenceDimensions.width,
        cal.intrinsicMatrixReferenceDimensions.height,
    )
    w, h = size
    sx, sy = w / ref[0], h / ref[1]
    if abs(sx / sy - 1.0) > 1.0 / min(w, h):
        raise InputError(
            f"{source}: camera '{camera}' key 'image': size {w}×{h} does not have the aspect "
            f"ratio of intrinsicMatrixReferenceDimensions {ref[0]:g}×{ref[1]:g}; deliver the "
            "photo uncropped (or crop the dump's calibration to match)"
        )
    center = (cal.lensDistortionCenter.x, cal.lensDistortionCenter.y)
    lens, fit_px = fit_radial_odd_centred(K_ref, center, cal.lensDistortionLookupTable, ref)
    inv_px = inverse_consistency(center, cal.lensDistortionLookupTable,
                                 cal.inverseLensDistortionLookupTable, ref)
    notes.append(
        f"{camera}: lookup table fitted by radial-odd-centred to {fit_px * sx:.4f} px (max, image "
        f"pixels); inverse table agrees to {inv_px * sx:.3f} px; focal length "
        f"{K_ref[0, 0] * cal.pixelSize:.3f} mm"
    )
    k = K_ref
    K = platform_K_to_image([k[0, 0], k[1, 1], k[0, 2], k[1, 2], k[0, 1]], (0.0, 0.0), (sx, sy))
    return Camera.from_matrix((w, h), K, lens), fit_px * sx


def gravity_from_core_motion(gravity: Any) -> tuple[float, float, float]:
    """Unit gravity in our device frame from ``CMDeviceMotion.gravity`` (module docstring).

    Examples
    --------
    >>> [round(v, 6) for v in gravity_from_core_motion([-1.0, 0.0, 0.0])]  # landscapeRight
    [0.0, 1.0, 0.0]
    """
    g = np.asarray(gravity, dtype=np.float64)
    n = float(np.linalg.norm(g))
    if not np.isfinite(g).all() or n < 1e-6:
        raise InputError(f"key 'gravity': must be a finite non-zero vector in g, got {g.tolist()}")
    out = R_BACK @ (g / n)
    return float(out[0]), float(out[1]), float(out[2])


def import_apple(dump: str | os.PathLike[str], out: str | os.PathLike[str]) -> ImportResult:
    """Convert an Apple AVFoundation dump folder to a capture set in ``out`` (all-or-nothing).

    Raises
    ------
    InputError
        A missing key, wrong array length, non-finite value, a matrix in the wrong order, or an
        image whose aspect ratio fits not the reference dimensions, named with the fix.
    """
    root = Path(dump)
    if not root.is_dir():
        raise InputError(f"Apple dump folder '{root}' not found; give the folder with session.json")
    session = validate_dump(AppleSession, read_json(root / "session.json", "session file"),
                            "session.json", DOC)
    files = sorted((root / "captures").glob("*.json"))
    if not files:
        raise InputError(f"no capture JSON in '{root / 'captures'}'; see {DOC}")
    ids = list(session.cameras)
    notes: list[str] = []
    T_ref = {i: extrinsic_transform(session.cameras[i].extrinsicMatrix,
                                    f"cameras.{i}.extrinsicMatrix", "session.json", notes)
             for i in ids}
    focal = {}
    for i in ids:
        c = session.cameras[i]
        focal[i] = (
            intrinsic_matrix(c, "session.json", i)[0, 0]
            / c.intrinsicMatrixReferenceDimensions.width
        )
    wide_id, tele_id = sorted(ids, key=lambda i: focal[i])
    if focal[tele_id] < 1.01 * focal[wide_id]:
        raise InputError(
            f"session.json: cameras {ids} have the same field of view; a wide + tele pair needs "
            "different focal lengths (intrinsicMatrix)"
        )
    cams: dict[str, Camera] = {}
    fits: dict[str, float] = {}
    entries, images = [], []
    loaded = [(f, validate_dump(AppleCapture, read_json(f, "capture file"), f.name, DOC))
              for f in files]
    for f, cap in loaded:
        if sorted(cap.cameras) != sorted(ids):
            raise InputError(
                f"{f.name}: key 'cameras': has {sorted(cap.cameras)} but session.json has "
                f"{sorted(ids)}; give each capture both cameras"
            )
    # Captures in time order (the manifest's order), file name breaking ties.
    loaded.sort(key=lambda fc: (fc[1].cameras[wide_id].timestamp_s, fc[0].name))
    for f, cap in loaded:
        for i in ids:
            img = root / cap.cameras[i].image
            size = image_size(img, f"cameras.{i}.image", f.name)
            if i not in cams:
                role = "wide" if i == wide_id else "tele"
                cams[i], fits[role] = output_camera(session.cameras[i], size, f.name, i, notes)
            elif cams[i].size != size:
                raise InputError(
                    f"{f.name}: camera '{i}' key 'image': size {size} differs from the first "
                    f"capture's {cams[i].size}; one capture set holds one image size per camera"
                )
        entries.append(_entry(cap, f.name, wide_id, tele_id, session.first_frame_time_s))
        for role, i in (("wide", wide_id), ("tele", tele_id)):
            src = root / cap.cameras[i].image
            images.append((src, f"images/{cap.id}_{role}{src.suffix.lower()}"))
    T = T_ref[tele_id].inverse() @ T_ref[wide_id]
    rig = Rig(cams[wide_id], cams[tele_id], T)
    note = f"imported from Apple AVCameraCalibrationData (wide '{wide_id}', tele '{tele_id}')"
    cal = Calibration(rig, CalibrationConditions(note=note))
    manifest = Manifest(description=f"imported from Apple dump '{root.name}'", captures=entries)
    dest = write_set_atomically(out, cal, manifest, images)
    return ImportResult(dest, len(entries), {"wide": wide_id, "tele": tele_id}, fits, tuple(notes))


def _entry(cap: AppleCapture, source: str, wide_id: str, tele_id: str, t0: float) -> CaptureEntry:
    shot = cap.cameras[wide_id]
    dt = shot.timestamp_s - t0
    if dt < 0:
        raise InputError(
            f"{source}: key 'cameras.{wide_id}.timestamp_s': earlier than the session's "
            "first_frame_time_s; both must come from the same clock"
        )
    gravity = capture_gravity(
        source, "gravity", cap.gravity, gravity_from_core_motion, cap.orientation
    )
    sw = Path(shot.image).suffix.lower()
    st = Path(cap.cameras[tele_id].image).suffix.lower()
    return capture_entry(
        cap, source, (sw, st), dt, gravity, shot.focusMode == 0, shot.lensPosition
    )
