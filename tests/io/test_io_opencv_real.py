"""Import a real OpenCV stereo calibration (the stereo_calib sample) and check the conventions.

OpenCV calibrates the 13 left/right pairs of its sample (strong barrel distortion, k1 ≈ −0.27);
the result is written the way OpenCV's sample writes it (intrinsics.yml: M1, D1, M2, D2;
extrinsics.yml: R, T) and imported with camera 1 = left = "wide". Then our model must agree with
OpenCV on the same numbers: the fundamental matrix, undistortion, and the epipolar geometry of
the detected corners.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from phonestereo.io import import_opencv_yaml

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "opencv_stereo"
pytestmark = pytest.mark.skipif(not DATA.exists(), reason="shared/data not beside the clone")
IDS = ["01", "02", "03", "04", "05", "06", "07", "08", "09", "11", "12", "13", "14"]


def _corners() -> tuple[list[np.ndarray], list[np.ndarray], list[np.ndarray]]:
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    objs, left, right = [], [], []
    for i in IDS:
        found = []
        for side in ("left", "right"):
            img = cv2.imread(str(DATA / f"{side}{i}.jpg"), cv2.IMREAD_GRAYSCALE)
            ok, c = cv2.findChessboardCorners(img, (9, 6))
            found.append(cv2.cornerSubPix(img, c, (11, 11), (-1, -1), crit) if ok else None)
        if found[0] is not None and found[1] is not None:
            objs.append(obj)
            left.append(found[0])
            right.append(found[1])
    return objs, left, right


def test_opencv_stereo_sample_round_trip(tmp_path: Path) -> None:
    objs, left, right = _corners()
    assert len(objs) == 13
    size = (640, 480)
    _, K1, D1, _, _ = cv2.calibrateCamera(objs, left, size, None, None)
    _, K2, D2, _, _ = cv2.calibrateCamera(objs, right, size, None, None)
    rms, K1, D1, K2, D2, R, T, _, F_cv = cv2.stereoCalibrate(
        objs, left, right, K1, D1, K2, D2, size, flags=cv2.CALIB_FIX_INTRINSIC
    )
    for name, mats in (
        ("intrinsics.yml", {"M1": K1, "D1": D1, "M2": K2, "D2": D2}),
        ("extrinsics.yml", {"R": R, "T": T}),
    ):
        fs = cv2.FileStorage(str(tmp_path / name), cv2.FILE_STORAGE_WRITE)
        for k, v in mats.items():
            fs.write(k, v)
        fs.release()
    # The sample's square size is undefined: T stays in square units (t_unit_m = 1).
    cal = import_opencv_yaml(
        tmp_path / "intrinsics.yml", tmp_path / "extrinsics.yml", wide_size=size, tele_size=size
    )
    rig = cal.rig
    assert rig.wide.lens.name == "opencv5" and rig.wide.lens.coefficients[0] < -0.2
    # Same R, T convention (camera 1 → camera 2): F equals OpenCV's up to scale and sign.
    F = rig.fundamental()
    a, b = F / np.linalg.norm(F), F_cv / np.linalg.norm(F_cv)
    np.testing.assert_allclose(a * np.sign(np.sum(a * b)), b, atol=1e-12)
    # Undistortion agrees with OpenCV's iterative one run to convergence.
    q = np.vstack(left).reshape(-1, 2).astype(np.float64)
    ours = rig.wide.pixel_to_normalized(q)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    theirs = cv2.undistortPointsIter(q.reshape(-1, 1, 2), K1, D1, None, None, crit).reshape(-1, 2)
    assert np.max(np.abs(ours - theirs)) * rig.wide.f < 1e-9  # px; 1.2e-13 seen
    # Detected corners obey eq. (5) to the calibration's accuracy (stereo RMS 0.45 px per point;
    # epipolar distance RMS 0.28 px seen).
    qt = np.vstack(right).reshape(-1, 2).astype(np.float64)
    uw = rig.wide.normalized_to_pixel(ours)
    ut = rig.tele.normalized_to_pixel(rig.tele.pixel_to_normalized(qt))
    lines = np.column_stack([uw, np.ones(len(uw))]) @ F.T
    dist = np.abs(np.sum(np.column_stack([ut, np.ones(len(ut))]) * lines, axis=1))
    dist /= np.hypot(lines[:, 0], lines[:, 1])
    assert rms < 1.0 and float(np.sqrt(np.mean(dist**2))) < 0.5
