"""``phonestereo import android``: a Camera2 dump to a capture set (docs/import-android.md).

Every conversion follows the Android ``CameraCharacteristics`` / ``CaptureResult``
documentation (developer.android.com/reference/android/hardware/camera2/):

* **Intrinsics** (``LENS_INTRINSIC_CALIBRATION`` = [f_x, f_y, c_x, c_y, s]) are in pixels of
  ``SENSOR_INFO_PRE_CORRECTION_ACTIVE_ARRAY_SIZE`` "where (0,0) is the top-left of the
  preCorrectionActiveArraySize rectangle" and "the center of pixel (x,y) is located at
  coordinate (x + 0.5, y + 0.5)". The output image shows ``SCALER_CROP_REGION`` (in
  pre-correction array coordinates when ``DISTORTION_CORRECTION_MODE`` is OFF, else in
  active-array coordinates; the whole array when absent) resampled to the image size, so
  ``f' = scale·f``, ``s' = scale·s``, ``c' = scale·(c − crop_left) − 0.5`` (common.py eq. 1).
  The image must show the crop with its aspect ratio (to one pixel), otherwise the import
  stops: a silently assumed extra crop would shift the principal point.
* **Distortion** (``LENS_DISTORTION`` = [κ1, κ2, κ3, κ4, κ5]) is the Brown–Conrady model
  ``x_c = x_i(1 + κ1 r² + κ2 r⁴ + κ3 r⁶) + κ4·2x_i y_i + κ5(r² + 2x_i²)`` mapping ideal to
  distorted normalised coordinates: OpenCV's model with (k1, k2, p1, p2, k3) =
  (κ1, κ2, κ4, κ5, κ3). With distortion correction FAST/HIGH_QUALITY the images are already
  corrected: the lens is the identity and the pixels are active-array pixels.
* **Pose** (``LENS_POSE_ROTATION`` (x, y, z, w), ``LENS_POSE_TRANSLATION`` in m): the
  quaternion rotates "from the Android sensor coordinate system to a camera-aligned coordinate
  system", ``p' = R p``; the translation is the camera's optical centre ``c`` in the sensor
  axes relative to ``LENS_POSE_REFERENCE`` (PRIMARY_CAMERA or GYROSCOPE; UNDEFINED and
  AUTOMOTIVE are refused). So ``T_cam_dev = (R, −R·c)`` and
  ``T_tele_wide = T_tele_dev · T_wide_dev⁻¹``: ``R = R_t R_wᵀ``, ``t = R_t (c_w − c_t)``.
  The camera axes (x along the sensor's long side, y down, z out of the lens) are ours.
  ``SENSOR_ORIENTATION`` must agree with the rotation (the camera x axis points along
  (cos θ, −sin θ, 0) of the device for a back camera) to 45°.
* **Which camera is the tele**: the larger focal length in output pixels per output width
  (the narrower field of view).
* ``time_s`` = (``SENSOR_TIMESTAMP`` of the wide image − the session's first frame's) / 1e9.
* ``conditions.wide_focal_length_mm`` = the wide's ``LENS_INFO_AVAILABLE_FOCAL_LENGTHS`` when it
  lists one focal length (mm); Camera2 does not say at which focus the intrinsics hold, so the
  focus breathing correction needs ``conditions.focus_distance_m`` added by hand.
* ``focus_mode`` = "manual" when ``CONTROL_AF_MODE`` is OFF (0), else "auto";
  ``focus_position`` = the wide camera's ``LENS_FOCUS_DISTANCE`` in dioptres.
* **Gravity**: ``SensorEvent.values`` of ``TYPE_ACCELEROMETER`` is the specific force (at
  rest: +9.81 m/s² *up*), in the device frame (x right, y up, z out of the screen), the same
  axes as the pose. Gravity in our device frame (the wide camera's frame, landscape = +y) is
  ``g = R_wide · (−a / |a|)``.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Rig, Transform, make_lens
from phonestereo.io.calibration import Calibration, CalibrationConditions
from phonestereo.io.importers.android_schema import (
    AndroidCapture,
    AndroidCharacteristics,
    AndroidResult,
    AndroidSession,
)
from phonestereo.io.importers.common import (
    ImportResult,
    capture_entry,
    capture_gravity,
    image_size,
    platform_K_to_image,
    read_json,
    validate_dump,
    write_set_atomically,
)
from phonestereo.io.manifest import CaptureEntry, Manifest

DOC = "docs/import-android.md"
SESSION_NAME = "session.json"
CAPTURE_DIR = "captures"


def quaternion_to_matrix(q: Any) -> NDArray[np.float64]:
    """Rotation matrix of a Camera2 quaternion (x, y, z, w), by the LENS_POSE_ROTATION formula.

    Examples
    --------
    >>> (quaternion_to_matrix([-0.70710678, 0.70710678, 0.0, 0.0]).round(6) + 0.0).tolist()
    [[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]]
    """
    x, y, z, w = (float(v) for v in q)
    return np.array(
        [
            [1 - 2 * y * y - 2 * z * z, 2 * x * y - 2 * z * w, 2 * x * z + 2 * y * w],
            [2 * x * y + 2 * z * w, 1 - 2 * x * x - 2 * z * z, 2 * y * z - 2 * x * w],
            [2 * x * z - 2 * y * w, 2 * y * z + 2 * x * w, 1 - 2 * x * x - 2 * y * y],
        ]
    )


def camera_to_device(chars: AndroidCharacteristics, source: str = "session.json") -> Transform:
    """``T_cam_dev`` from the pose keys (see the module docstring), checked against
    ``android.sensor.orientation``."""
    R = quaternion_to_matrix(chars.pose_rotation)
    theta = math.radians(chars.sensor_orientation)
    expected_x = np.array([math.cos(theta), -math.sin(theta), 0.0])
    cos_angle = float(R.T[:, 0] @ expected_x)
    if cos_angle < math.cos(math.radians(45.0)):
        raise InputError(
            f"{source}: key 'android.lens.poseRotation': puts the camera x axis at "
            f"{math.degrees(math.acos(max(-1.0, min(1.0, cos_angle)))):.0f}° from where "
            f"android.sensor.orientation = {chars.sensor_orientation} puts it; check the "
            "quaternion order (x, y, z, w) and that the camera faces back"
        )
    c = np.asarray(chars.pose_translation, dtype=np.float64)
    return Transform(R, -R @ c)


def output_camera(
    chars: AndroidCharacteristics,
    result: AndroidResult,
    size: tuple[int, int],
    source: str,
    camera_id: str,
) -> Camera:
    """The camera of one output image: intrinsics through crop and scale, and the lens."""
    corrected = result.distortion_correction_mode != 0
    ref = chars.active_array if corrected else chars.pre_correction_array
    pre = chars.pre_correction_array
    # cropRegion is in the reference array's coordinates (relative to its top-left).
    crop_in_ref = result.crop_region or (0, 0, ref[2] - ref[0], ref[3] - ref[1])
    cw, ch = crop_in_ref[2] - crop_in_ref[0], crop_in_ref[3] - crop_in_ref[1]
    w, h = size
    sx, sy = w / cw, h / ch
    if abs(sx / sy - 1.0) > 1.0 / min(w, h):
        what = "android.scaler.cropRegion" if result.crop_region else "the reference array"
        raise InputError(
            f"{source}: camera '{camera_id}' key 'image': size {w}×{h} matches neither the "
            f"active array ({chars.active_array[2] - chars.active_array[0]}×"
            f"{chars.active_array[3] - chars.active_array[1]}) nor {what} ({cw}×{ch}) in "
            "aspect ratio; record the crop the output stream really used in "
            "android.scaler.cropRegion (the stream crops the region to its aspect ratio)"
        )
    # Intrinsics are in pre-correction array pixels; the crop's top-left in those pixels:
    left = crop_in_ref[0] + (ref[0] - pre[0])
    top = crop_in_ref[1] + (ref[1] - pre[1])
    K = platform_K_to_image(chars.intrinsic_calibration, (left, top), (sx, sy))
    if corrected:
        lens = make_lens("opencv5")
    else:
        if chars.distortion is None:
            raise InputError(
                f"{source}: camera '{camera_id}' key 'android.lens.distortion': required key "
                "is missing for images taken with distortion correction OFF; add it, or "
                "capture with android.distortionCorrection.mode FAST/HIGH_QUALITY"
            )
        k1, k2, k3, p1, p2 = chars.distortion
        lens = make_lens("opencv5", (k1, k2, p1, p2, k3))
    try:
        return Camera.from_matrix((w, h), K, lens)
    except InputError as exc:
        raise InputError(
            f"{source}: camera '{camera_id}' key 'android.lens.intrinsicCalibration': {exc}"
        ) from exc


def gravity_from_accelerometer(a: Any, R_cam_dev: Any) -> tuple[float, float, float]:
    """Unit gravity in our device frame (the wide camera's) from an Android accelerometer
    sample (m/s², specific force, device frame): ``g = R · (−a/|a|)``.

    Examples
    --------
    >>> R = quaternion_to_matrix([-0.70710678, 0.70710678, 0.0, 0.0])
    >>> g = gravity_from_accelerometer([9.81, 0.0, 0.0], R)  # right edge up
    >>> [round(v, 6) + 0.0 for v in g]
    [0.0, 1.0, 0.0]
    """
    acc = np.asarray(a, dtype=np.float64)
    norm = float(np.linalg.norm(acc))
    if not np.isfinite(acc).all() or norm < 1e-6:
        raise InputError(
            f"key 'accelerometer': must be a finite non-zero sample in m/s², got {acc.tolist()}"
        )
    g = np.asarray(R_cam_dev, dtype=np.float64) @ (-acc / norm)
    g = g / np.linalg.norm(g)
    return float(g[0]), float(g[1]), float(g[2])


def _load_dump(dump: Path) -> tuple[AndroidSession, list[tuple[Path, AndroidCapture]]]:
    session_path = dump / SESSION_NAME
    session = validate_dump(AndroidSession, read_json(session_path, "session file"),
                            SESSION_NAME, DOC)
    files = sorted((dump / CAPTURE_DIR).glob("*.json"))
    if not files:
        raise InputError(f"no capture JSON in '{dump / CAPTURE_DIR}'; see {DOC}")
    captures = []
    for f in files:
        cap = validate_dump(AndroidCapture, read_json(f, "capture file"), f.name, DOC)
        if sorted(cap.cameras) != sorted(session.cameras):
            raise InputError(
                f"{f.name}: key 'cameras': has cameras {sorted(cap.cameras)} but session.json "
                f"has {sorted(session.cameras)}; give each capture both physical cameras"
            )
        captures.append((f, cap))
    # Captures in time order (the manifest's order), file name breaking ties.
    wide_first = {
        i: min(c.cameras[i].sensor_timestamp for _, c in captures) for i in session.cameras
    }
    key_id = min(wide_first, key=lambda i: (wide_first[i], i))
    captures.sort(key=lambda fc: (fc[1].cameras[key_id].sensor_timestamp, fc[0].name))
    return session, captures


def import_android(dump: str | os.PathLike[str], out: str | os.PathLike[str]) -> ImportResult:
    """Convert an Android Camera2 dump folder to a capture set (calibration.json +
    manifest.json + images) in ``out``, written all-or-nothing.

    Raises
    ------
    InputError
        A missing key, wrong array length, non-finite value, unknown poseReference or an
        image whose size fits neither the array nor the crop, named with the fix.
    """
    root = Path(dump)
    if not root.is_dir():
        raise InputError(
            f"Android dump folder '{root}' not found; give the folder with {SESSION_NAME}"
        )
    session, captures = _load_dump(root)
    ids = list(session.cameras)
    pose_refs = {c.pose_reference for c in session.cameras.values()}
    if len(pose_refs) != 1:
        raise InputError(
            f"{SESSION_NAME}: key 'android.lens.poseReference': the two cameras use different "
            f"references {sorted(pose_refs)}; their positions cannot be compared"
        )
    T_dev = {i: camera_to_device(session.cameras[i]) for i in ids}
    entries: list[CaptureEntry] = []
    images: list[tuple[Path, str]] = []
    cams: dict[str, Camera] = {}
    for path, cap in captures:
        here = {}
        for i in ids:
            res = cap.cameras[i]
            img = root / res.image
            size = image_size(img, f"cameras.{i}.image", path.name)
            cam = output_camera(session.cameras[i], res, size, path.name, i)
            if i in cams and not np.allclose(cams[i].K, cam.K, rtol=0, atol=1e-9):
                raise InputError(
                    f"{path.name}: camera '{i}': image size or crop differs from the first "
                    "capture's; one capture set holds one output configuration per camera"
                )
            cams[i], here[i] = cam, (res, img)
        if not entries:
            focal = {i: cams[i].fx / cams[i].width for i in ids}
            wide_id, tele_id = sorted(ids, key=lambda i: focal[i])
            if focal[tele_id] < 1.01 * focal[wide_id]:
                raise InputError(
                    f"{SESSION_NAME}: cameras {ids} have the same field of view; a wide + tele "
                    "pair needs different focal lengths (android.lens.intrinsicCalibration)"
                )
        entries.append(_entry(cap, path.name, here, wide_id, tele_id, session, T_dev))
        for role, i in (("wide", wide_id), ("tele", tele_id)):
            src = here[i][1]
            images.append((src, f"images/{cap.id}_{role}{src.suffix.lower()}"))
    T = T_dev[tele_id] @ T_dev[wide_id].inverse()
    sync_ms = max(
        abs(c.cameras[tele_id].sensor_timestamp - c.cameras[wide_id].sensor_timestamp) * 1e-6
        for _, c in captures
    )
    ref = {0: "PRIMARY_CAMERA", 1: "GYROSCOPE"}[session.cameras[wide_id].pose_reference]
    notes = (
        f"poses relative to {ref}; baseline {np.linalg.norm(T.t) * 1e3:.3f} mm",
        f"time_s from the wide camera's android.sensor.timestamp; the tele's differs by up "
        f"to {sync_ms:.3f} ms",
    )
    rig = Rig(cams[wide_id], cams[tele_id], T)
    note = f"imported from Android Camera2 characteristics (wide '{wide_id}', tele '{tele_id}')"
    # A fixed-focal-length camera lists one focal length: the wide's, for its focus breathing
    # (fixes/breathing.py; a no-op until the calibration's focus distance is given).
    f_mm = session.cameras[wide_id].available_focal_lengths
    wide_f_mm = f_mm[0] if f_mm is not None and len(f_mm) == 1 else None
    cal = Calibration(rig, CalibrationConditions(note=note, wide_focal_length_mm=wide_f_mm))
    manifest = Manifest(description=f"imported from Android dump '{root.name}'", captures=entries)
    dest = write_set_atomically(out, cal, manifest, images)
    return ImportResult(dest, len(entries), {"wide": wide_id, "tele": tele_id}, notes=notes)


def _entry(
    cap: AndroidCapture,
    source: str,
    here: dict[str, tuple[AndroidResult, Path]],
    wide_id: str,
    tele_id: str,
    session: AndroidSession,
    T_dev: dict[str, Transform],
) -> CaptureEntry:
    res = here[wide_id][0]
    dt_ns = res.sensor_timestamp - session.first_frame_timestamp_ns
    if dt_ns < 0:
        raise InputError(
            f"{source}: key 'cameras.{wide_id}.android.sensor.timestamp': earlier than the "
            "session's first_frame_timestamp_ns; both must come from the same session clock"
        )
    gravity = capture_gravity(
        source,
        "accelerometer",
        cap.accelerometer,
        lambda acc: gravity_from_accelerometer(acc, T_dev[wide_id].R),
        cap.orientation,
    )
    suffix = {r: here[i][1].suffix.lower() for r, i in (("wide", wide_id), ("tele", tele_id))}
    return capture_entry(
        cap,
        source,
        (suffix["wide"], suffix["tele"]),
        dt_ns * 1e-9,
        gravity,
        res.af_mode == 0,
        res.focus_distance,
    )
