"""OpenFace 2.0 CSV import: the thesis's landmark tool as a backend (thesis §1.2.3).

OpenFace (``FaceLandmarkImg`` for images, ``FeatureExtraction`` for videos) writes one CSV row
per face and frame. This module reads:

- ``x_0 … x_67``, ``y_0 … y_67`` (required): the 68 2-D landmarks, pixels. OpenFace uses
  OpenCV's pixel convention ((0, 0) = centre of the top-left pixel), as docs/conventions.md does;
- ``eye_lmk_x_0 … eye_lmk_x_55``, ``eye_lmk_y_*`` (optional, ``-gaze``): 28 eye-region
  landmarks per eye; the mean of each eye's 8 iris points is its pupil. Without them the
  pupils are the eye-contour centres (``pupil_source = "eye-contour"``);
- ``pose_Rx, pose_Ry, pose_Rz`` (optional, ``-pose``): head rotation (R = Rx · Ry · Rz, camera
  frame) → yaw relative to the image plane; else ``X_*, Y_*, Z_*`` (3-D landmarks, mm) → the
  symmetric-pair axis; else the yaw is unknown (NaN, noted in the result);
- ``frame`` / ``face_id`` (videos) or ``face`` (images), ``confidence``, ``success``.

Column names may carry OpenFace 2.0's leading spaces (``" x_0"``). A file without the 2-D
landmark columns raises :class:`~phonestereo.errors.InputError` naming them and the OpenFace
flag that writes them; a row whose tracking failed (``success = 0``) is a rejected candidate.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from phonestereo.errors import InputError
from phonestereo.features.landmarks.base import (
    Face,
    FaceResult,
    ImageLike,
    LandmarkBackend,
    Rejected,
    make_result,
)
from phonestereo.features.landmarks.eyes import ibug68_eyes
from phonestereo.features.landmarks.pose import MAX_YAW_RAD, yaw_from_euler, yaw_from_landmarks

#: Left/right-symmetric points of the 68-point model (subject's right first): jaw, eye
#: corners, nostrils, mouth corners, brow ends.
IBUG_SYMMETRIC_PAIRS = (
    (0, 16), (1, 15), (2, 14), (3, 13), (4, 12), (36, 45), (39, 42), (31, 35), (48, 54),
    (17, 26), (21, 22),
)
N_FACE, N_EYE = 68, 56


def _cols(prefix: str, n: int) -> list[str]:
    return [f"{prefix}{i}" for i in range(n)]


def _has(df: pd.DataFrame, names: list[str]) -> bool:
    return all(c in df.columns for c in names)


def read_openface_csv(
    path: str | os.PathLike[str], image_size: tuple[int, int] = (0, 0)
) -> dict[int, FaceResult]:
    """Read an OpenFace 2.0 CSV into one :class:`FaceResult` per frame.

    Parameters
    ----------
    path : path
        The CSV OpenFace wrote.
    image_size : (int, int)
        (width, height) of the image(s), pixels, to reject eyes outside it; (0, 0) = unknown.

    Returns
    -------
    dict of int → FaceResult
        Keyed by OpenFace's ``frame`` (1 for a single-image CSV).

    Raises
    ------
    InputError
        Missing/unreadable file, or no 2-D landmark columns (the message lists the missing
        ones and the OpenFace flag that writes them).
    """
    p = Path(path)
    if not p.is_file():
        raise InputError(f"OpenFace CSV not found: '{p}'; check the path")
    try:
        df = pd.read_csv(p, skipinitialspace=True)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as exc:
        raise InputError(f"'{p}' is not a readable CSV: {exc}") from exc
    df.columns = [str(c).strip() for c in df.columns]
    need = _cols("x_", N_FACE) + _cols("y_", N_FACE)
    missing = [c for c in need if c not in df.columns]
    if missing:
        shown = ", ".join(missing[:6]) + (f" … ({len(missing)} in all)" if len(missing) > 6 else "")
        raise InputError(
            f"'{p}' lacks OpenFace's 2-D landmark columns ({shown}); run OpenFace with "
            "-2Dfp (and -gaze -pose for pupils and head pose), or pass its full CSV"
        )
    notes = []
    eye_cols = _cols("eye_lmk_x_", N_EYE) + _cols("eye_lmk_y_", N_EYE)
    has_eyes = _has(df, eye_cols)
    if not has_eyes:
        notes.append("no eye_lmk_* columns (OpenFace -gaze): pupils are the eye-contour centres")
    has_pose = _has(df, ["pose_Rx", "pose_Ry", "pose_Rz"])
    has_3d = _has(df, _cols("X_", N_FACE) + _cols("Y_", N_FACE) + _cols("Z_", N_FACE))
    if not (has_pose or has_3d):
        notes.append("no pose_R* or X_/Y_/Z_ columns (OpenFace -pose): yaw unknown")
    frames = df["frame"].to_numpy(dtype=np.int64) if "frame" in df.columns else np.ones(len(df))
    out: dict[int, FaceResult] = {}
    for frame in sorted({int(f) for f in frames}):
        rows = df[frames == frame]
        faces: list[Face] = []
        rejected: list[Rejected] = []
        for _, row in rows.iterrows():
            item = _row_face(row, has_eyes, has_pose, has_3d, image_size)
            if isinstance(item, Face):
                faces.append(item)
            else:
                rejected.append(item)
        out[frame] = make_result(
            faces, image_size, "openface", rejected=rejected, notes=notes,
            empty_reason="the CSV has no face rows for this frame",
        )
    return out


def _row_face(
    row: pd.Series, has_eyes: bool, has_pose: bool, has_3d: bool, size: tuple[int, int]
) -> Face | Rejected:
    """One CSV row → a Face, or a Rejected candidate with the reason."""
    xy = np.column_stack(
        [row[_cols("x_", N_FACE)].to_numpy(float), row[_cols("y_", N_FACE)].to_numpy(float)]
    )
    lo, hi = np.nanmin(xy, axis=0), np.nanmax(xy, axis=0)
    box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
    if "success" in row.index and not int(row["success"]):
        return Rejected(box, "OpenFace tracking failed on this face (success = 0)")
    if not np.isfinite(xy).all():
        return Rejected(box, "landmarks are missing (empty cells) in the CSV row")
    eye = None
    if has_eyes:
        eye = np.column_stack(
            [row[_cols("eye_lmk_x_", N_EYE)].to_numpy(float),
             row[_cols("eye_lmk_y_", N_EYE)].to_numpy(float)]
        )
        if not np.isfinite(eye).all():
            eye = None
    pupils, centres, source = ibug68_eyes(xy, eye)
    yaw = float("nan")
    if has_pose:
        rx, ry, rz = (float(row[c]) for c in ("pose_Rx", "pose_Ry", "pose_Rz"))
        yaw = yaw_from_euler(rx, ry, rz, toward=pupils[1] - pupils[0])
    elif has_3d:
        pts = np.column_stack([row[_cols(k, N_FACE)].to_numpy(float) for k in ("X_", "Y_", "Z_")])
        yaw = yaw_from_landmarks(pts, IBUG_SYMMETRIC_PAIRS, toward=pupils[1] - pupils[0])
    w, h = size
    if w > 0 and h > 0:
        inside = (pupils >= -0.5).all(axis=1) & (pupils <= [w - 0.5, h - 0.5]).all(axis=1)
        if not inside.all():
            return Rejected(box, "one eye outside the image (face cut by the border)")
    if np.isfinite(yaw) and abs(yaw) > MAX_YAW_RAD:
        return Rejected(
            box,
            f"profile face (yaw {np.degrees(yaw):+.0f}°, limit ±{np.degrees(MAX_YAW_RAD):.0f}°): "
            "the far eye is not measurable",
        )
    score = float(row["confidence"]) if "confidence" in row.index else 1.0
    return Face(pupils, centres, xy, yaw, score, np.array(box), source, "image")


@dataclass(frozen=True)
class OpenFaceCsvBackend(LandmarkBackend):
    """Landmarks precomputed by OpenFace: ``detect(image_path)`` reads ``csv_dir/<stem>.csv``.

    OpenFace's ``FaceLandmarkImg -fdir IMAGES -out_dir CSV_DIR`` writes one CSV per image,
    named after it; this backend feeds those to anything that takes a
    :class:`~phonestereo.features.landmarks.base.LandmarkBackend`. Only the first frame of
    each CSV is used.
    """

    csv_dir: Path
    name: str = "openface"

    def detect(self, image: ImageLike) -> FaceResult:
        """The faces OpenFace found in ``image`` (a path: its stem names the CSV)."""
        if not isinstance(image, str | os.PathLike):
            raise InputError(
                "the OpenFace backend reads precomputed CSVs: pass the image path, not pixels"
            )
        img = Path(image)
        csv = Path(self.csv_dir) / f"{img.stem}.csv"
        size = _image_size(img)
        results = read_openface_csv(csv, size)
        if not results:
            return make_result((), size, self.name, empty_reason=f"'{csv}' has no rows")
        return results[min(results)]


def _image_size(path: Path) -> tuple[int, int]:
    """(width, height) from the image header, or (0, 0) if it cannot be read."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            return int(im.size[0]), int(im.size[1])
    except (OSError, UnidentifiedImageError):
        return 0, 0


def openface_columns(landmarks: Any, eye_landmarks: Any = None, pose: Any = None) -> dict:
    """The OpenFace CSV columns of one face (for tests and for writing compatible files).

    Parameters
    ----------
    landmarks : array_like, shape (68, 2)
    eye_landmarks : array_like, shape (56, 2), optional
    pose : (rx, ry, rz), optional
        Radians.

    >>> cols = openface_columns(np.zeros((68, 2)), pose=(0.0, 0.1, 0.0))
    >>> len(cols), cols["pose_Ry"]
    (139, 0.1)
    """
    lm = np.asarray(landmarks, dtype=np.float64)
    out: dict[str, float] = {}
    if eye_landmarks is not None:
        eye = np.asarray(eye_landmarks, dtype=np.float64)
        out |= dict(zip(_cols("eye_lmk_x_", N_EYE), eye[:, 0].tolist(), strict=True))
        out |= dict(zip(_cols("eye_lmk_y_", N_EYE), eye[:, 1].tolist(), strict=True))
    if pose is not None:
        out |= {"pose_Rx": float(pose[0]), "pose_Ry": float(pose[1]), "pose_Rz": float(pose[2])}
    out |= dict(zip(_cols("x_", N_FACE), lm[:, 0].tolist(), strict=True))
    out |= dict(zip(_cols("y_", N_FACE), lm[:, 1].tolist(), strict=True))
    return out
