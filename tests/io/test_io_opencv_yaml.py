"""OpenCV FileStorage YAML: round trip, OpenCV's own names, and cv2.projectPoints agreement."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from phonestereo.errors import InputError, PhysicsError
from phonestereo.geometry import Camera, Rig, Transform, make_lens
from phonestereo.io import (
    Calibration,
    CalibrationConditions,
    export_opencv_yaml,
    import_opencv_yaml,
    lens_from_opencv,
)


def _cal(tele_model: str = "opencv8") -> Calibration:
    wide = Camera(
        (2000, 1500),
        1501.2345678912,
        1500.9876,
        1001.1 / 3,
        749.53,
        make_lens("opencv5", [-0.071, 0.0213, 3.1e-4, -2.2e-4, -0.0031]),
    )
    coeffs = (
        [0.02, -0.1, 1e-4, 2e-4, 0.05, 0.01, -0.02, 0.003]
        if tele_model == "opencv8"
        else [0.01, 0.02, 1e-4, 2e-4, 0.0]
    )
    tele = Camera((2000, 1500), 4500.5, 4499.75, 1003.2, 747.9, make_lens(tele_model, coeffs))
    T = Transform.from_rotvec([0.003, -0.004, 0.0021], [0.0002, -0.012, 0.0015])
    cond = CalibrationConditions(0.6, 24.5, "landscape", "factory")
    return Calibration(Rig(wide, tele, T), cond, rms_px=0.31)


def _assert_close(a: Calibration, b: Calibration, tol: float = 1e-12) -> None:
    for ca, cb in ((a.rig.wide, b.rig.wide), (a.rig.tele, b.rig.tele)):
        assert ca.size == cb.size and ca.lens.name == cb.lens.name
        np.testing.assert_allclose(cb.K, ca.K, rtol=tol, atol=0)
        np.testing.assert_allclose(cb.lens.coefficients, ca.lens.coefficients, rtol=tol, atol=0)
    np.testing.assert_allclose(b.rig.T_tele_wide.R, a.rig.T_tele_wide.R, rtol=0, atol=tol)
    np.testing.assert_allclose(b.rig.T_tele_wide.t, a.rig.T_tele_wide.t, rtol=0, atol=tol)


@pytest.mark.parametrize("tele_model", ["opencv5", "opencv8"])
def test_export_import_round_trip(tmp_path: Path, tele_model: str) -> None:
    cal = _cal(tele_model)
    p = export_opencv_yaml(tmp_path / "stereo.yml", cal)
    text = p.read_text()
    for name in (
        "image_width_wide",
        "image_height_tele",
        "camera_matrix_wide",
        "distortion_coefficients_tele",
        "\nR:",
        "\nT:",
    ):
        assert name in text
    back = import_opencv_yaml(p)
    # OpenCV writes doubles with 17 significant digits: the round trip is exact to 1e-12.
    _assert_close(cal, back)
    assert back.conditions == cal.conditions and back.rms_px == cal.rms_px
    # Deterministic bytes.
    assert export_opencv_yaml(tmp_path / "again.yml", back).read_bytes() == p.read_bytes()


@pytest.mark.parametrize("tele_model", ["opencv5", "opencv8"])
def test_opencv_project_points_matches_camera_project(tmp_path: Path, tele_model: str) -> None:
    """Independent reference: OpenCV projects with the exported K, D exactly as Camera does."""
    cal = _cal(tele_model)
    fs = cv2.FileStorage(str(export_opencv_yaml(tmp_path / "s.yml", cal)), cv2.FILE_STORAGE_READ)
    rng = np.random.default_rng(3)
    pts = np.column_stack(
        [rng.uniform(-0.6, 0.6, 200), rng.uniform(-0.45, 0.45, 200), rng.uniform(0.8, 4.0, 200)]
    )
    pts[:, :2] *= pts[:, 2:] / 1.5  # inside a ~±0.4 normalised field
    R = fs.getNode("R").mat()
    T = fs.getNode("T").mat()
    for name, cam, p_cam in (
        ("wide", cal.rig.wide, pts),
        ("tele", cal.rig.tele, cal.rig.T_tele_wide.apply(pts)),
    ):
        K = fs.getNode(f"camera_matrix_{name}").mat()
        D = fs.getNode(f"distortion_coefficients_{name}").mat()
        # wide: identity pose; tele: OpenCV's R, T applied to wide-frame points.
        rvec = np.zeros(3) if name == "wide" else cv2.Rodrigues(R)[0]
        tvec = np.zeros(3) if name == "wide" else T
        q_cv, _ = cv2.projectPoints(pts, rvec, tvec, K, D)
        q = cam.project(p_cam)
        # 1e-9 px: both evaluate the same polynomial in float64 (differences are rounding).
        np.testing.assert_allclose(q_cv.reshape(-1, 2), q, rtol=0, atol=1e-9)
    fs.release()


def _write_sample(path: Path, **mats: np.ndarray) -> Path:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for k, v in mats.items():
        fs.write(k, v)
    fs.release()
    return path


def test_import_opencv_sample_names(tmp_path: Path) -> None:
    """OpenCV's stereo_calib sample: intrinsics.yml (M1, D1, M2, D2) + extrinsics.yml (R, T)."""
    K1 = np.array([[536.1, 0, 342.2], [0, 536.0, 235.9], [0, 0, 1]])
    K2 = np.array([[542.3, 0, 328.1], [0, 542.2, 247.4], [0, 0, 1]])
    D1 = np.array([[-0.27, 0.1, 0.001, -0.002]])  # 4 coefficients → opencv5 with k3 = 0
    D2 = np.array([[-0.28, 0.12, 0.0, 0.001, -0.03]])
    R = cv2.Rodrigues(np.array([0.01, -0.02, 0.005]))[0]
    T = np.array([[-3.33], [0.04], [-0.01]])  # square units
    intr = _write_sample(tmp_path / "intrinsics.yml", M1=K1, D1=D1, M2=K2, D2=D2)
    extr = _write_sample(tmp_path / "extrinsics.yml", R=R, T=T, R1=np.eye(3))
    with pytest.raises(InputError, match="--wide-size WIDTHxHEIGHT"):
        import_opencv_yaml(intr, extr)
    cal = import_opencv_yaml(intr, extr, wide_size=(640, 480), tele_size=(640, 480), t_unit_m=0.025)
    assert cal.rig.wide.lens.coefficients == (-0.27, 0.1, 0.001, -0.002, 0.0)
    np.testing.assert_allclose(cal.rig.tele.K, K2, rtol=1e-15)
    np.testing.assert_allclose(cal.rig.T_tele_wide.t, T.ravel() * 0.025, rtol=1e-15)
    # Camera 1 = tele: R, T are inverted so T_tele_wide still maps wide into tele.
    flipped = import_opencv_yaml(
        intr, extr, wide_size=(640, 480), tele_size=(640, 480), first_camera="tele"
    )
    np.testing.assert_allclose(flipped.rig.wide.K, K2, rtol=1e-15)
    inv = Transform(R, T.ravel()).inverse()
    np.testing.assert_allclose(flipped.rig.T_tele_wide.t, inv.t, rtol=0, atol=1e-15)


def test_import_errors(tmp_path: Path) -> None:
    K = np.array([[536.1, 0, 342.2], [0, 536.0, 235.9], [0, 0, 1]])
    R, T = np.eye(3), np.array([[-3.3], [0.0], [0.0]])
    sizes = {"wide_size": (640, 480), "tele_size": (640, 480)}
    for n in (12, 14):
        p = _write_sample(
            tmp_path / f"d{n}.yml", M1=K, D1=np.zeros((1, n)), M2=K, D2=np.zeros((1, 5)), R=R, T=T
        )
        with pytest.raises(InputError, match=f"field 'D1': OpenCV distortion with {n} coeff.*not"):
            import_opencv_yaml(p, **sizes)
    neg = K.copy()
    neg[0, 0] = -536.0
    p = _write_sample(
        tmp_path / "neg.yml", M1=neg, D1=np.zeros((1, 5)), M2=K, D2=np.zeros((1, 5)), R=R, T=T
    )
    with pytest.raises(PhysicsError, match=r"neg.yml: field 'M1': camera fx must be"):
        import_opencv_yaml(p, **sizes)
    p = _write_sample(
        tmp_path / "zero.yml",
        M1=K,
        D1=np.zeros((1, 5)),
        M2=K,
        D2=np.zeros((1, 5)),
        R=R,
        T=np.zeros((3, 1)),
    )
    with pytest.raises(PhysicsError, match=r"zero.yml: field 'T': rig baseline"):
        import_opencv_yaml(p, **sizes)
    p = _write_sample(
        tmp_path / "refl.yml",
        M1=K,
        D1=np.zeros((1, 5)),
        M2=K,
        D2=np.zeros((1, 5)),
        R=np.diag([1.0, 1.0, -1.0]),
        T=T,
    )
    with pytest.raises(InputError, match=r"refl.yml: field 'R': R must be a rotation"):
        import_opencv_yaml(p, **sizes)
    p = _write_sample(tmp_path / "nor.yml", M1=K, D1=np.zeros((1, 5)), M2=K, D2=np.zeros((1, 5)))
    with pytest.raises(InputError, match="no rotation R"):
        import_opencv_yaml(p, **sizes)
    with pytest.raises(InputError, match="not found"):
        import_opencv_yaml(tmp_path / "missing.yml")
    garbage = tmp_path / "garbage.yml"
    garbage.write_text("%YAML:1.0\n---\nM1: [unclosed\n")
    with pytest.raises(InputError, match=r"garbage.yml: not a readable.*Parsing error"):
        import_opencv_yaml(garbage)
    with pytest.raises(InputError, match="has no OpenCV equivalent"):
        cal = _cal()
        odd = cal.rig.with_cameras(tele=cal.rig.tele.with_lens(make_lens("radial-odd")))
        export_opencv_yaml(tmp_path / "odd.yml", Calibration(odd))


def test_lens_from_opencv_counts() -> None:
    assert lens_from_opencv(np.arange(8) * 0.01).name == "opencv8"
    with pytest.raises(InputError, match="4, 5 or 8"):
        lens_from_opencv([0.1, 0.2, 0.3])
