"""Android Camera2 importer: the real Pixel vector, round trips through the exporter on three
scenarios, gravity per device orientation, and bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from phonestereo.fixes.orientation import capture_bucket, orientation_bucket
from phonestereo.io import load_calibration, load_capture_set
from phonestereo.io.importers.android import (
    camera_to_device,
    gravity_from_accelerometer,
    import_android,
    output_camera,
    quaternion_to_matrix,
)
from phonestereo.io.importers.android_schema import AndroidCharacteristics, AndroidResult
from phonestereo.sim.export_android import write_android_dump

PIXEL = Path(__file__).resolve().parents[4] / "shared" / "data" / "phone_metadata"
PIXEL_JSON = PIXEL / "pixel_main_camera2.json"
# The Pixel main camera's quaternion (x, y, z, w) = (−0.7071, 0.7071, 0, 0) is a 180° turn
# about (−1, 1, 0)/√2: R = 2nnᵀ − I. Worked out by hand from the LENS_POSE_ROTATION formula:
R_PIXEL = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


def _pixel_characteristics() -> AndroidCharacteristics:
    src = json.loads(PIXEL_JSON.read_text())["camera_characteristics"]
    chars = {f"android.{k}": v for k, v in src.items() if k in (
        "lens.intrinsicCalibration", "lens.distortion", "lens.poseRotation",
        "lens.poseTranslation", "lens.poseReference", "sensor.orientation", "lens.facing",
        "lens.info.minimumFocusDistance", "lens.info.availableFocalLengths")}
    # Not in the source file: the array size. The Pixel main sensor is 4032×3024 (12.2 MP);
    # its printed c_x, c_y = 2019.8, 1542.3 sit 4 and 30 px from that array's centre.
    chars["android.sensor.info.activeArraySize"] = [0, 0, 4032, 3024]
    chars["android.sensor.info.preCorrectionActiveArraySize"] = [0, 0, 4032, 3024]
    return AndroidCharacteristics.model_validate(chars)


@pytest.mark.skipif(not PIXEL_JSON.exists(), reason="shared/data not beside the clone")
def test_real_pixel_camera2_vector_imports_under_the_documented_conventions() -> None:
    chars = _pixel_characteristics()
    res = AndroidResult.model_validate({"image": "x.jpg", "android.sensor.timestamp": 0,
                                        "android.control.afMode": 1})
    full = output_camera(chars, res, (4032, 3024), "pixel", "0")
    # Hand-derived: f unchanged at full size; c − 0.5 (Android: pixel centre at x + 0.5).
    assert full.fx == pytest.approx(2775.4246, abs=1e-4)  # float32 print: 8 digits
    assert full.cx == pytest.approx(2019.7947 - 0.5, abs=1e-4)
    assert full.cy == pytest.approx(1542.3264 - 0.5, abs=1e-4)
    # LENS_DISTORTION [κ1, κ2, κ3, κ4, κ5] → opencv5 (k1, k2, p1, p2, k3).
    assert full.lens.name == "opencv5"
    assert full.lens.coefficients == pytest.approx((0.08679182, -0.113809735, 0, 0, 0.053207975))
    half = output_camera(chars, res, (2016, 1512), "pixel", "0")  # a half-size stream
    assert half.fx == pytest.approx(2775.4246 / 2, abs=1e-4)
    assert half.cx == pytest.approx(0.5 * 2019.7947 - 0.5, abs=1e-4)  # 1009.397
    T = camera_to_device(chars)
    np.testing.assert_allclose(T.R, R_PIXEL, atol=1e-7)  # 8 printed digits of 1/√2
    np.testing.assert_allclose(T.t, 0.0, atol=0)  # the primary camera: position (0, 0, 0)
    # Sensor orientation 90 (back camera): the image x axis runs along the device's −y.
    np.testing.assert_allclose(T.R.T[:, 0], [0.0, -1.0, 0.0], atol=1e-7)
    assert chars.sensor_orientation == 90
    assert chars.available_focal_lengths == (6.81,)  # the Pixel main camera's lens, mm


def test_quaternion_formula_matches_scipy() -> None:
    from scipy.spatial.transform import Rotation

    q = Rotation.from_rotvec([0.3, -0.2, 0.9]).as_quat()  # scipy: (x, y, z, w)
    np.testing.assert_allclose(quaternion_to_matrix(q), Rotation.from_quat(q).as_matrix(),
                               atol=1e-15)


# Accelerometer at rest reads +9.81 m/s² *up* in the Android device frame (x right, y to
# the top of the phone, z out of the screen). With the Pixel-like pose above:
@pytest.mark.parametrize(
    ("accelerometer", "bucket"),
    [
        ((9.81, 0.0, 0.0), "landscape"),  # turned left: right edge up → image upright
        ((-9.81, 0.0, 0.0), "landscape-flipped"),
        ((0.0, 9.81, 0.0), "portrait"),  # held upright
        ((0.0, -9.81, 0.0), "portrait-flipped"),
    ],
)
def test_gravity_lands_in_the_right_bucket(accelerometer: tuple[float, ...], bucket: str) -> None:
    noisy = np.asarray(accelerometer) + np.array([0.4, -0.3, 1.5])  # tilt and hand shake
    g = gravity_from_accelerometer(noisy, R_PIXEL)
    assert orientation_bucket(g) == bucket
    assert math.isclose(np.linalg.norm(g), 1.0, abs_tol=1e-12)


def test_round_trip_reproduces_calibration_and_manifest(sim_set: Path, tmp_path: Path) -> None:
    native_cal = load_calibration(sim_set / "calibration.json")
    native = load_capture_set(sim_set)
    write_android_dump(tmp_path / "android", native_cal, native.manifest, sim_set)
    result = import_android(tmp_path / "android", tmp_path / "set")
    assert result.tele_role == {"wide": "2", "tele": "4"}
    cal = load_calibration(tmp_path / "set" / "calibration.json")
    for a, b in ((native_cal.rig.wide, cal.rig.wide), (native_cal.rig.tele, cal.rig.tele)):
        assert a.size == b.size
        assert np.abs(a.K - b.K).max() <= 1e-9 * a.fx  # K within 1e-9 relative
        assert a.lens.name == b.lens.name
        # Android holds opencv5 exactly: the lens mapping is equal (0.01 px asked).
        assert np.abs(np.subtract(a.lens.coefficients, b.lens.coefficients)).max() <= 1e-15
    Ta, Tb = native_cal.rig.T_tele_wide, cal.rig.T_tele_wide
    assert np.abs(Ta.R - Tb.R).max() <= 1e-9 and np.abs(Ta.t - Tb.t).max() <= 1e-9
    # LENS_INFO_AVAILABLE_FOCAL_LENGTHS carries the wide's focal length (the focus breathing's
    # input); the calibration focus is not in Camera2, so it is not invented.
    wide_f = native_cal.conditions.wide_focal_length_mm
    assert wide_f is not None and cal.conditions.wide_focal_length_mm == wide_f
    assert cal.conditions.focus_distance_m is None
    got = load_capture_set(tmp_path / "set")
    assert [c.id for c in got.captures()] == [c.id for c in native.captures()]
    for a, b in zip(native.captures(), got.captures(), strict=True):
        assert abs(a.time_s - b.time_s) <= 1e-9
        assert (a.focus_mode, a.focus_position, a.kind, a.roi) == (
            b.focus_mode, b.focus_position, b.kind, b.roi)
        assert (a.focus_group, a.focus_attempt, a.temperature_c) == (
            b.focus_group, b.focus_attempt, b.temperature_c)
        assert capture_bucket(a.gravity, a.orientation) == capture_bucket(b.gravity, b.orientation)
        assert np.abs(np.subtract(a.gravity, b.gravity)).max() <= 2e-9  # 9 printed digits


def test_distortion_corrected_stream_is_pinhole_in_active_array_pixels() -> None:
    chars = AndroidCharacteristics.model_validate({
        "android.lens.intrinsicCalibration": [3000.0, 3000.0, 2000.0, 1500.0, 0.0],
        "android.lens.distortion": [0.1, -0.05, 0.0, 0.001, 0.0],
        "android.lens.poseRotation": [-0.70710678, 0.70710678, 0.0, 0.0],
        "android.lens.poseTranslation": [0.0, 0.0, 0.0],
        "android.lens.poseReference": 0,
        "android.sensor.info.activeArraySize": [8, 6, 3992, 2994],
        "android.sensor.info.preCorrectionActiveArraySize": [0, 0, 4000, 3000],
        "android.sensor.orientation": 90,
    })
    res = AndroidResult.model_validate({
        "image": "x.png", "android.sensor.timestamp": 0, "android.control.afMode": 0,
        "android.distortionCorrection.mode": 2,
        "android.scaler.cropRegion": [0, 0, 3984, 2988],  # active-array coordinates
    })
    cam = output_camera(chars, res, (1992, 1494), "t", "0")
    assert cam.lens.is_identity()  # the ISP removed the distortion
    # Intrinsics are pre-correction pixels; the active array starts at (8, 6) of them:
    assert cam.cx == pytest.approx(0.5 * (2000.0 - 8) - 0.5, abs=1e-12)
    assert cam.cy == pytest.approx(0.5 * (1500.0 - 6) - 0.5, abs=1e-12)
    assert cam.fx == pytest.approx(1500.0, abs=1e-12)
