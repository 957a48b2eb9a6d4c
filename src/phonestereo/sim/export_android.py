"""Export a simulated capture set as an Android Camera2 dump (docs/import-android.md).

The inverse of :mod:`phonestereo.io.importers.android`, so the importer can be tested on every
scenario with known truth. The virtual phone is laid out like a real one:

* both cameras face back with ``android.sensor.orientation`` 90, the wide one being the
  primary camera (``poseReference`` PRIMARY_CAMERA, its position (0, 0, 0)); its rotation from
  the Android sensor frame is ``R0`` below, the Pixel main camera's (quaternion
  (−0.7071, 0.7071, 0, 0));
* the tele's rotation is ``R_tele_wide · R0`` and its position ``R0ᵀ · c`` with ``c`` the tele
  optical centre in the wide frame;
* each output image is a half-size resampling of a sensor array twice its size: the wide one
  of the whole pre-correction array, the tele one of a ``android.scaler.cropRegion`` offset
  by (40, 30) pixels, so the crop-and-scale conversion is exercised;
* timestamps are ``first_frame + time_s``; the accelerometer reads ``−9.80665 · R0ᵀ g``.
"""

from __future__ import annotations

import os
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from phonestereo.errors import InputError
from phonestereo.io import Calibration, CaptureEntry, Manifest
from phonestereo.io.importers.android_schema import FORMAT_CAPTURE, FORMAT_SESSION
from phonestereo.io.importers.common import STANDARD_GRAVITY, image_to_platform_K
from phonestereo.sim.export_common import capture_docs, write_dump

R0 = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
FIRST_FRAME_NS = 5_000_000_000
IDS = {"wide": "2", "tele": "4"}
TELE_CROP_OFFSET = (40, 30)


def _quat(R: Any) -> list[float]:
    return [float(v) for v in Rotation.from_matrix(np.asarray(R)).as_quat()]  # (x, y, z, w)


def _characteristics(cal: Calibration, role: str) -> dict[str, Any]:
    cam = cal.rig.wide if role == "wide" else cal.rig.tele
    if cam.lens.name != "opencv5":
        raise InputError(
            f"the {role} lens model is '{cam.lens.name}'; Android's android.lens.distortion "
            "holds only the 5-coefficient Brown–Conrady model (opencv5)"
        )
    w, h = cam.size
    ox, oy = (0, 0) if role == "wide" else TELE_CROP_OFFSET
    pre = [4, 4, 4 + 2 * w + 2 * ox, 4 + 2 * h + 2 * oy]
    active = [pre[0] + 8, pre[1] + 8, pre[2] - 8, pre[3] - 8]
    k1, k2, p1, p2, k3 = cam.lens.coefficients
    f_mm = cal.conditions.wide_focal_length_mm if role == "wide" else None
    if role == "wide":
        R, c = R0, np.zeros(3)
    else:
        T = cal.rig.T_tele_wide
        R = T.R @ R0
        c = R0.T @ (-T.R.T @ T.t)
    return {
        "android.lens.facing": 1,
        "android.lens.intrinsicCalibration": image_to_platform_K(cam.K, (ox, oy), (0.5, 0.5)),
        "android.lens.distortion": [k1, k2, k3, p1, p2],
        "android.lens.poseRotation": _quat(R),
        "android.lens.poseTranslation": [float(v) for v in c],
        "android.lens.poseReference": 0,
        "android.lens.info.minimumFocusDistance": 10.0,
        **({"android.lens.info.availableFocalLengths": [f_mm]} if f_mm is not None else {}),
        "android.sensor.info.activeArraySize": active,
        "android.sensor.info.preCorrectionActiveArraySize": pre,
        "android.sensor.orientation": 90,
    }


def android_dump(cal: Calibration, manifest: Manifest) -> tuple[dict[str, Any], dict[str, Any]]:
    """The dump documents: (session.json, {capture file name: capture JSON})."""
    session = {
        "format": FORMAT_SESSION,
        "version": 1,
        "first_frame_timestamp_ns": FIRST_FRAME_NS,
        "cameras": {IDS["tele"]: _characteristics(cal, "tele"),
                    IDS["wide"]: _characteristics(cal, "wide")},
    }
    return session, capture_docs(
        FORMAT_CAPTURE, manifest, "a Camera2 dump", _accelerometer, partial(_result, cal), IDS
    )


def _accelerometer(g: Any) -> dict[str, list[float]]:
    return {"accelerometer": [float(v) for v in -STANDARD_GRAVITY * (R0.T @ g)]}


def _result(cal: Calibration, c: CaptureEntry, role: str, time_s: float) -> dict[str, Any]:
    res: dict[str, Any] = {
        "android.sensor.timestamp": FIRST_FRAME_NS + round(time_s * 1e9),
        "android.control.afMode": 0 if c.focus_mode == "manual" else 1,
        "android.distortionCorrection.mode": 0,
    }
    if role == "wide" and c.focus_position is not None:
        res["android.lens.focusDistance"] = c.focus_position
    if role == "tele":
        ox, oy = TELE_CROP_OFFSET
        w, h = cal.rig.tele.size
        res["android.scaler.cropRegion"] = [ox, oy, ox + 2 * w, oy + 2 * h]
    return res


def write_android_dump(
    folder: str | os.PathLike[str], cal: Calibration, manifest: Manifest, set_root: Path
) -> Path:
    """Write the dump into ``folder`` (session.json, captures/, images/ linked from the set)."""
    return write_dump(folder, *android_dump(cal, manifest), manifest, set_root, IDS)
