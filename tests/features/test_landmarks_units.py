"""Landmark backends: eyes, yaw, tiling, OpenFace CSV import and bad input (no MediaPipe here)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial.transform import Rotation

from phonestereo.errors import InputError, ShapeError
from phonestereo.features.landmarks import Face, OpenFaceCsvBackend, read_openface_csv
from phonestereo.features.landmarks.base import as_rgb, make_result
from phonestereo.features.landmarks.eyes import image_left_first, mediapipe_eyes
from phonestereo.features.landmarks.mediapipe_backend import (
    MediaPipeBackend,
    nms,
    tile_grid,
    unrotate,
)
from phonestereo.features.landmarks.openface import IBUG_SYMMETRIC_PAIRS, openface_columns
from phonestereo.features.landmarks.pose import (
    MP_SYMMETRIC_PAIRS,
    yaw_from_euler,
    yaw_from_landmarks,
)


def _ibug_face(ipd_px: float = 60.0, centre=(320.0, 240.0)) -> tuple[np.ndarray, np.ndarray]:
    """A frontal 68-point face (image-left = subject's right) and its 56 eye landmarks."""
    rng = np.random.default_rng(3)
    cx, cy = centre
    lm = np.column_stack([cx + rng.uniform(-60, 60, 68), cy + rng.uniform(-40, 80, 68)])
    half = ipd_px / 2
    ring = np.column_stack(
        [np.cos(np.arange(6) * np.pi / 3), 0.4 * np.sin(np.arange(6) * np.pi / 3)]
    )
    lm[36:42] = [cx - half, cy] + 12 * ring  # subject's right eye: image left
    lm[42:48] = [cx + half, cy] + 12 * ring
    iris = np.column_stack([np.cos(np.arange(8) * np.pi / 4), np.sin(np.arange(8) * np.pi / 4)])
    eye = np.zeros((56, 2))
    eye[0:8] = [cx - half + 1.0, cy] + 4 * iris  # pupils 1 px outward of the contour centres
    eye[8:28] = [cx - half, cy]
    eye[28:36] = [cx + half - 1.0, cy] + 4 * iris
    eye[36:56] = [cx + half, cy]
    return lm, eye


# --- eyes and pose --------------------------------------------------------------------------


def test_mediapipe_eyes_order_and_contours() -> None:
    lm = np.zeros((478, 3))
    lm[468] = [300, 100, 0]  # subject's right iris drawn on the image right (mirrored input)
    lm[473] = [200, 100, 0]
    out = mediapipe_eyes(lm)
    assert out[0].tolist() == [[200, 100], [300, 100]]  # image-left eye first, whatever the label
    with pytest.raises(ShapeError, match="refine_landmarks"):
        mediapipe_eyes(np.zeros((468, 2)))


def test_image_left_first_needs_pairs() -> None:
    with pytest.raises(ShapeError):
        image_left_first(np.zeros((3, 2)))


@pytest.mark.parametrize("yaw_deg", [-35.0, -10.0, 0.0, 12.0, 30.0])
@pytest.mark.parametrize("roll_deg", [0.0, 25.0, 180.0])
def test_yaw_from_symmetric_landmarks_any_roll(yaw_deg: float, roll_deg: float) -> None:
    # A mirror-symmetric head (MediaPipe pair indices), turned then rolled in the image plane.
    rng = np.random.default_rng(0)
    pts = np.zeros((478, 3))
    for a, b in MP_SYMMETRIC_PAIRS:
        p = rng.uniform([10, -60, -30], [70, 60, 0])
        pts[b], pts[a] = p, p * [-1, 1, 1]
    # turned first (subject's left eye farther for yaw > 0), then rolled in the image plane
    R = Rotation.from_euler("ZY", [roll_deg, -yaw_deg], degrees=True).as_matrix()
    turned = pts @ R.T
    toward = turned[263, :2] - turned[33, :2]  # eye 0 → eye 1 in the image
    if toward[0] < 0:  # image order: eye 0 is the one with the smaller x
        toward = -toward
        yaw_deg = -yaw_deg  # seen upside down, the farther eye is now eye 0
    yaw = yaw_from_landmarks(turned, toward=toward)
    assert np.degrees(yaw) == pytest.approx(yaw_deg, abs=1e-9)  # exact for a symmetric head


def test_yaw_from_openface_euler_matches_its_rotation() -> None:
    # OpenFace: R = Rx·Ry·Rz; a face axis along R[:, 0]; a pure pose_Ry = +0.2 turns the
    # image-right eye towards the camera → yaw −0.2 in our convention.
    assert yaw_from_euler(0.0, 0.2, 0.0) == pytest.approx(-0.2)
    a_z = np.sin(0.3) * np.sin(0.1) - np.cos(0.3) * np.sin(0.2) * np.cos(0.1)  # R[2, 0]
    assert yaw_from_euler(0.3, 0.2, 0.1) == pytest.approx(np.arcsin(a_z))


def test_face_validates_shapes_and_reports() -> None:
    with pytest.raises(ShapeError, match="pupils_px"):
        Face(np.zeros((3, 2)), np.zeros((2, 2)), np.zeros((5, 2)), 0.0, 1.0, np.zeros(4))
    f = Face([[0, 0], [60, 0]], [[1, 0], [59, 0]], np.zeros((5, 2)), np.pi / 3, 0.9, np.zeros(4))
    assert f.ipd_px == 60 and f.eye_centre_ipd_px == 58
    assert f.ipd_frontal_px == pytest.approx(120.0)  # cos 60° = 0.5
    assert f.to_dict()["yaw_deg"] == pytest.approx(60.0)


# --- tiling ----------------------------------------------------------------------------------


def test_tiles_cover_the_image_with_half_tile_overlap() -> None:
    tiles = tile_grid(2000, 1500, 256)
    for side in (1000, 500):
        level = [(x, y) for x, y, s in tiles if s == side]
        xs, ys = sorted({x for x, _ in level}), sorted({y for _, y in level})
        assert xs[0] == 0 and xs[-1] + side == 2000 and ys[0] == 0 and ys[-1] + side == 1500
        assert max(np.diff(xs)) <= side / 2 and max(np.diff(ys)) <= side / 2
    assert {s for *_, s in tiles} == {2000, 1000, 500}


def test_nms_keeps_the_best_of_overlapping_boxes() -> None:
    boxes = [(0, 0, 10, 10, 0.5), (0.5, 0, 10.5, 10, 0.9), (2, 2, 6, 6, 0.95), (20, 0, 30, 10, 0.1)]
    kept = nms(boxes)
    assert kept[0] == (2, 2, 6, 6, 0.95)  # the small box inside is kept (highest score) ...
    assert (0.5, 0, 10.5, 10, 0.9) in kept and (20, 0, 30, 10, 0.1) in kept
    assert (0, 0, 10, 10, 0.5) not in kept  # ... the duplicate of the 0.9 box is not


@pytest.mark.parametrize("k", [0, 1, 2, 3])
def test_unrotate_inverts_rot90(k: int) -> None:
    rng = np.random.default_rng(k)
    img = rng.integers(0, 1000, (7, 11))
    view = np.rot90(img, k)
    ys, xs = np.mgrid[: view.shape[0], : view.shape[1]]
    q = np.column_stack([xs.ravel(), ys.ravel()]).astype(float)
    back = unrotate(q, k, (11, 7)).astype(int)
    assert (view.ravel() == img[back[:, 1], back[:, 0]]).all()


def test_backend_rejects_bad_settings_and_images() -> None:
    with pytest.raises(InputError):
        MediaPipeBackend(min_detection_confidence=1.5)
    with pytest.raises(InputError):
        MediaPipeBackend(quarter_turns=(4,))
    with pytest.raises(InputError, match="8-bit"):
        as_rgb(np.zeros((50, 50), np.float32))
    with pytest.raises(ShapeError):
        as_rgb(np.zeros((50, 50, 2), np.uint8))
    with pytest.raises(InputError, match="not found"):
        as_rgb("/nonexistent/face.jpg")


def test_empty_result_says_why() -> None:
    res = make_result((), (640, 480), "x", empty_reason="no face found (3 tiles searched)")
    assert not res.found and res.reason == "no face found (3 tiles searched)"
    assert res.to_dict()["n_faces"] == 0


# --- OpenFace CSV ----------------------------------------------------------------------------


def _write_csv(path: Path, rows: list[dict], spaces: bool = False) -> Path:
    df = pd.DataFrame(rows)
    if spaces:  # OpenFace 2.0 writes ", x_0" style headers
        df.columns = [c if c in ("frame",) else " " + c for c in df.columns]
    df.to_csv(path, index=False)
    return path


def test_openface_csv_pupils_eye_centres_and_yaw(tmp_path: Path) -> None:
    lm, eye = _ibug_face(60.0)
    row = {"frame": 1, "face_id": 0, "confidence": 0.97, "success": 1}
    row |= openface_columns(lm, eye, pose=(0.0, 0.25, 0.0))
    res = read_openface_csv(_write_csv(tmp_path / "a.csv", [row], spaces=True), (640, 480))[1]
    (face,) = res.faces
    assert face.pupil_source == "iris" and face.yaw_reference == "image"
    assert face.ipd_px == pytest.approx(58.0)  # iris means, 1 px inward of each contour centre
    assert face.eye_centre_ipd_px == pytest.approx(60.0)
    assert face.yaw_rad == pytest.approx(-0.25) and face.score == pytest.approx(0.97)
    assert not res.notes


def test_openface_csv_without_eye_or_pose_columns_notes_it(tmp_path: Path) -> None:
    lm, _ = _ibug_face(50.0)
    res = read_openface_csv(_write_csv(tmp_path / "b.csv", [{"face": 0} | openface_columns(lm)]))
    (face,) = res[1].faces
    assert face.pupil_source == "eye-contour" and face.ipd_px == pytest.approx(50.0)
    assert np.isnan(face.yaw_rad) and face.ipd_frontal_px == pytest.approx(50.0)
    assert any("-gaze" in n for n in res[1].notes) and any("-pose" in n for n in res[1].notes)


def test_openface_csv_3d_landmarks_give_yaw(tmp_path: Path) -> None:
    lm, _ = _ibug_face(60.0)
    rng = np.random.default_rng(1)
    pts = np.zeros((68, 3))
    for a, b in IBUG_SYMMETRIC_PAIRS:
        p = rng.uniform([10, -60, 0], [70, 60, 30])
        pts[b], pts[a] = p, p * [-1, 1, 1]
    pts = pts @ Rotation.from_euler("y", -20, degrees=True).as_matrix().T + [0, 0, 600]
    row = openface_columns(lm)
    for k, axis in (("X_", 0), ("Y_", 1), ("Z_", 2)):
        row |= {f"{k}{i}": float(v) for i, v in enumerate(pts[:, axis])}
    (face,) = read_openface_csv(_write_csv(tmp_path / "c.csv", [row]))[1].faces
    assert np.degrees(face.yaw_rad) == pytest.approx(20.0, abs=1e-6)


def test_openface_csv_failed_rows_profiles_and_frames(tmp_path: Path) -> None:
    lm, eye = _ibug_face(60.0)
    base = openface_columns(lm, eye, pose=(0.0, 0.0, 0.0))
    rows = [
        {"frame": 1, "face_id": 0, "confidence": 0.9, "success": 1} | base,
        {"frame": 2, "face_id": 0, "confidence": 0.1, "success": 0} | base,
        {"frame": 3, "face_id": 0, "confidence": 0.9, "success": 1}
        | openface_columns(lm, eye, pose=(0.0, 1.2, 0.0)),
    ]
    res = read_openface_csv(_write_csv(tmp_path / "d.csv", rows))
    assert sorted(res) == [1, 2, 3] and res[1].found
    assert not res[2].found and "success = 0" in res[2].reason
    assert not res[3].found and "profile face" in res[3].reason


def test_openface_csv_missing_columns_is_a_clear_error(tmp_path: Path) -> None:
    lm, _ = _ibug_face()
    row = openface_columns(lm)
    del row["y_67"], row["x_3"]
    with pytest.raises(InputError, match=r"x_3, y_67.*-2Dfp"):
        read_openface_csv(_write_csv(tmp_path / "e.csv", [row]))
    with pytest.raises(InputError, match="not found"):
        read_openface_csv(tmp_path / "missing.csv")
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(InputError, match="not a readable CSV"):
        read_openface_csv(tmp_path / "empty.csv")


def test_openface_backend_reads_csv_named_after_the_image(tmp_path: Path) -> None:
    lm, eye = _ibug_face(60.0, centre=(40.0, 30.0))  # pupils near the left border
    lm[36:42, 0] -= 60.0  # image-left eye moved outside a 640-px image
    eye[0:8, 0] -= 60.0
    _write_csv(tmp_path / "shot.csv", [{"face": 0} | openface_columns(lm, eye)])
    from PIL import Image

    Image.new("L", (640, 480)).save(tmp_path / "shot.png")
    res = OpenFaceCsvBackend(tmp_path).detect(tmp_path / "shot.png")
    assert not res.found and "one eye outside the image" in res.reason
    with pytest.raises(InputError, match="image path"):
        OpenFaceCsvBackend(tmp_path).detect(np.zeros((10, 10), np.uint8))
