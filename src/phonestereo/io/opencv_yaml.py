"""OpenCV FileStorage YAML import/export of a stereo calibration (docs/calibration.md).

Export writes the names OpenCV's calibration samples use, with a ``_wide`` / ``_tele`` suffix::

    image_width_wide, image_height_wide, camera_matrix_wide, distortion_coefficients_wide,
    image_width_tele, image_height_tele, camera_matrix_tele, distortion_coefficients_tele,
    R, T                                     (T in metres)

``R``, ``T`` are those of :func:`cv2.stereoCalibrate` with camera 1 = wide: they map wide-frame
points into the tele frame, p_tele = R·p_wide + T, which is our ``T_tele_wide``. Import also
reads the names of OpenCV's ``stereo_calib`` sample (``M1``, ``D1``, ``M2``, ``D2`` from
intrinsics.yml and ``R``, ``T`` from extrinsics.yml, given as a second file), with the image
sizes given as arguments. Distortion vectors of 4 or 5 coefficients map to ``opencv5``
(k3 = 0 for 4) and of 8 to ``opencv8``; OpenCV's 12- and 14-coefficient models (thin prism,
tilted sensor) are not supported.

Examples
--------
>>> import tempfile, pathlib
>>> from phonestereo.geometry import Camera, Rig, Transform
>>> wide = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
>>> cal = Calibration(Rig(wide, wide.scaled(3.0), Transform.from_rotvec([0, 0, 0], [0, -0.012, 0])))
>>> with tempfile.TemporaryDirectory() as d:
...     back = import_opencv_yaml(export_opencv_yaml(pathlib.Path(d) / "stereo.yml", cal))
>>> back.rig.tele.fx, back.rig.T_tele_wide.t.tolist()
(4500.0, [0.0, -0.012, 0.0])
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError
from phonestereo.geometry import Camera, LensModel, Rig, Transform, make_lens
from phonestereo.geometry.transform import SNAP_TOLERANCE, orthonormality_error
from phonestereo.io.calibration import Calibration, CalibrationConditions, _field

_CAMS = ("wide", "tele")
_SAMPLE_NAMES = {"wide": ("M1", "D1"), "tele": ("M2", "D2")}


# --- export -----------------------------------------------------------------------------------
def _opencv_distortion(lens: LensModel, name: str) -> NDArray[np.float64]:
    if lens.name in ("opencv5", "opencv8"):
        return np.asarray(lens.coefficients, dtype=np.float64).reshape(1, -1)
    raise InputError(
        f"the {name} lens model '{lens.name}' has no OpenCV equivalent; refit it as 'opencv5' "
        "or 'opencv8' before exporting to OpenCV YAML (the JSON calibration keeps it)"
    )


def export_opencv_yaml(path: str | os.PathLike[str], cal: Calibration) -> Path:
    """Write ``cal`` as an OpenCV FileStorage YAML file.

    Parameters
    ----------
    path : path
        Destination (``.yml``/``.yaml``; ``.xml``/``.json`` also work, by OpenCV's rules).
    cal : Calibration
        Both lenses must be ``opencv5`` or ``opencv8``.

    Returns
    -------
    Path
        The written path. Conditions and ``rms_px`` are written as extra scalar nodes; the
        covariance is not exported (keep the JSON for it).
    """
    if not isinstance(cal, Calibration):
        raise InputError(f"export_opencv_yaml needs a Calibration, got {type(cal).__name__}")
    cams = {"wide": cal.rig.wide, "tele": cal.rig.tele}
    dists = {n: _opencv_distortion(c.lens, n) for n, c in cams.items()}
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.stem}.{os.getpid()}.tmp{p.suffix}")
    fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
    if not fs.isOpened():
        raise InputError(f"cannot write OpenCV FileStorage '{p}'")
    try:
        for n, cam in cams.items():
            fs.write(f"image_width_{n}", int(cam.width))
            fs.write(f"image_height_{n}", int(cam.height))
            fs.write(f"camera_matrix_{n}", np.asarray(cam.K))
            fs.write(f"distortion_coefficients_{n}", dists[n])
        fs.write("R", np.asarray(cal.rig.T_tele_wide.R))
        fs.write("T", np.asarray(cal.rig.T_tele_wide.t).reshape(3, 1))
        c = cal.conditions
        if c.focus_distance_m is not None:
            fs.write("focus_distance_m", c.focus_distance_m)
        if c.temperature_c is not None:
            fs.write("temperature_c", c.temperature_c)
        if c.orientation is not None:
            fs.write("orientation", c.orientation)
        if c.note:
            fs.write("note", c.note)
        if cal.rms_px is not None:
            fs.write("rms_px", cal.rms_px)
    finally:
        fs.release()
    os.replace(tmp, p)
    return p


# --- import -----------------------------------------------------------------------------------
def lens_from_opencv(dist: Any) -> LensModel:
    """Map an OpenCV distortion vector to a lens model.

    4 → ``opencv5`` with k3 = 0, 5 → ``opencv5``, 8 → ``opencv8``; 12 and 14 (thin prism,
    tilted sensor) raise :class:`InputError`.

    Examples
    --------
    >>> lens_from_opencv([-0.27, 0.1, 0.001, -0.002]).to_dict()
    {'model': 'opencv5', 'coefficients': [-0.27, 0.1, 0.001, -0.002, 0.0]}
    """
    d = np.asarray(dist, dtype=np.float64).ravel()
    if d.size == 4:
        return make_lens("opencv5", np.append(d, 0.0))
    if d.size == 5:
        return make_lens("opencv5", d)
    if d.size == 8:
        return make_lens("opencv8", d)
    if d.size in (12, 14):
        raise InputError(
            f"OpenCV distortion with {d.size} coefficients (thin prism / tilted sensor) is not "
            "supported; recalibrate without CALIB_THIN_PRISM_MODEL / CALIB_TILTED_MODEL"
        )
    raise InputError(f"an OpenCV distortion vector has 4, 5 or 8 coefficients here, got {d.size}")


class _Reader:
    """Read nodes from one or two FileStorage files, naming the file on errors."""

    def __init__(self, paths: list[Path]) -> None:
        self.files: list[tuple[Path, Any]] = []
        for p in paths:
            if not p.is_file():
                raise InputError(f"OpenCV calibration file '{p}' not found; check the path")
            try:
                fs = cv2.FileStorage(str(p), cv2.FILE_STORAGE_READ)
            except (cv2.error, SystemError) as exc:
                cause = exc.__cause__ or exc.__context__ or exc  # SystemError wraps cv2.error
                msg = str(cause).strip().splitlines()[-1].split("error: ")[-1]
                raise InputError(
                    f"{p.name}: not a readable OpenCV FileStorage file: {msg}"
                ) from exc
            if not fs.isOpened():
                raise InputError(f"{p.name}: not a readable OpenCV FileStorage file")
            self.files.append((p, fs))

    def close(self) -> None:
        for _, fs in self.files:
            fs.release()

    def node(self, *names: str) -> tuple[str, str, Any] | None:
        """First (file name, node name, node) found for any of ``names``."""
        for name in names:
            for p, fs in self.files:
                n = fs.getNode(name)
                if not n.empty() and not n.isNone():
                    return p.name, name, n
        return None

    def matrix(self, names: tuple[str, ...], what: str) -> tuple[str, str, NDArray[np.float64]]:
        """(file name, node name, matrix) of the first of ``names`` present."""
        found = self.node(*names)
        if found is None:
            files = ", ".join(p.name for p, _ in self.files)
            raise InputError(
                f"{files}: no {what} (looked for {' or '.join(names)}); export it with "
                "cv2.FileStorage or use export_opencv_yaml"
            )
        src, name, n = found
        try:
            m = n.mat()
        except cv2.error as exc:  # e.g. rows × cols differs from the number of data elements
            raise InputError(
                f"{src}: field '{name}': not a readable opencv-matrix (rows × cols must equal "
                f"the number of data elements): {str(exc).strip().splitlines()[-1]}"
            ) from exc
        if m is None:
            raise InputError(f"{src}: field '{name}': must be an opencv-matrix")
        return src, name, np.asarray(m, dtype=np.float64)

    def scalar(self, name: str) -> float | str | None:
        found = self.node(name)
        if found is None:
            return None
        _, _, n = found
        return str(n.string()) if n.isString() else float(n.real())


def _size(reader: _Reader, cam: str, given: tuple[int, int] | None) -> tuple[int, int]:
    if given is not None:
        return int(given[0]), int(given[1])
    w, h = reader.scalar(f"image_width_{cam}"), reader.scalar(f"image_height_{cam}")
    if isinstance(w, float) and isinstance(h, float) and w.is_integer() and h.is_integer():
        return int(w), int(h)
    raise InputError(
        f"no image size for the {cam} camera in the file (image_width_{cam}, image_height_{cam}); "
        f"give it: --{cam}-size WIDTHxHEIGHT on the command line "
        f"(in Python: {cam}_size=(width, height))"
    )


@dataclass(frozen=True)
class YamlImport:
    """An imported OpenCV calibration and what the import changed."""

    calibration: Calibration
    #: max |R·Rᵀ − I| of the file's R as printed (before it was snapped to the nearest rotation;
    #: OpenCV prints 8 decimals, so ~1e-8 is normal).
    r_deviation: float

    @property
    def r_reorthonormalised(self) -> bool:
        """True when R was replaced by the nearest rotation (SVD)."""
        return self.r_deviation > SNAP_TOLERANCE

    @property
    def notes(self) -> tuple[str, ...]:
        """What the import changed, one sentence each (for the user)."""
        if not self.r_reorthonormalised:
            return ()
        return (
            f"R was orthonormal only to {self.r_deviation:.2g} (max |R·Rᵀ − I|, as printed in "
            "the file); it was replaced by the nearest rotation (SVD)",
        )


def import_opencv_yaml(
    path: str | os.PathLike[str],
    extrinsics_path: str | os.PathLike[str] | None = None,
    **options: Any,
) -> Calibration:
    """Read a stereo calibration from OpenCV FileStorage YAML (or XML/JSON).

    The same as :func:`read_opencv_yaml` (which also says whether R was re-orthonormalised;
    ``options`` are its keyword arguments ``wide_size``, ``tele_size``, ``t_unit_m``,
    ``first_camera``), returning only the calibration.
    """
    return read_opencv_yaml(path, extrinsics_path, **options).calibration


def read_opencv_yaml(
    path: str | os.PathLike[str],
    extrinsics_path: str | os.PathLike[str] | None = None,
    *,
    wide_size: tuple[int, int] | None = None,
    tele_size: tuple[int, int] | None = None,
    t_unit_m: float = 1.0,
    first_camera: Literal["wide", "tele"] = "wide",
) -> YamlImport:
    """Read a stereo calibration from OpenCV FileStorage YAML (or XML/JSON), with notes.

    Parameters
    ----------
    path : path
        The file written by :func:`export_opencv_yaml`, or OpenCV's ``intrinsics.yml``
        (``M1``, ``D1``, ``M2``, ``D2``).
    extrinsics_path : path, optional
        A second file holding ``R`` and ``T`` (OpenCV's ``extrinsics.yml``).
    wide_size, tele_size : (int, int), optional
        Image (width, height) when the file does not hold ``image_width_*``/``image_height_*``.
    t_unit_m : float
        Metres per unit of T (1 for our files; e.g. the chessboard square size when T came from
        a calibration in square units, 0.001 for millimetres).
    first_camera : {"wide", "tele"}
        Which camera is OpenCV's camera 1 (M1, ``camera_matrix_wide`` is always wide). R, T
        map camera-1 points into camera 2; with "tele" they are inverted.

    Returns
    -------
    YamlImport
        The calibration and the deviation of R from a rotation before it was snapped.

    Raises
    ------
    InputError
        A missing file or node, an unsupported distortion model, or a non-physical value
        (as :class:`~phonestereo.errors.PhysicsError`) naming the file and field.
    """
    if not np.isfinite(t_unit_m) or t_unit_m <= 0:
        raise InputError(
            f"--t-unit-m (Python: t_unit_m) must be a positive number of metres per unit of T, "
            f"got {t_unit_m}"
        )
    paths = [Path(path)] + ([Path(extrinsics_path)] if extrinsics_path is not None else [])
    reader = _Reader(paths)
    try:
        sizes = {"wide": wide_size, "tele": tele_size}
        order = _CAMS if first_camera == "wide" else _CAMS[::-1]
        cams: dict[str, Camera] = {}
        for idx, cam in enumerate(_CAMS):
            sample = _SAMPLE_NAMES[order[idx]]
            k_file, k_name, K = reader.matrix(
                (f"camera_matrix_{cam}", sample[0]), f"{cam} camera matrix"
            )
            d_file, d_name, D = reader.matrix(
                (f"distortion_coefficients_{cam}", sample[1]), f"{cam} distortion coefficients"
            )
            with _field(d_file, d_name):
                lens = lens_from_opencv(D)
            with _field(k_file, k_name):
                if K.shape != (3, 3):
                    raise ShapeError(f"must be a 3×3 camera matrix, got shape {K.shape}")
                cams[cam] = Camera.from_matrix(_size(reader, cam, sizes[cam]), K, lens)
        r_file, _, R = reader.matrix(("R",), "rotation R")
        t_file, _, T = reader.matrix(("T",), "translation T")
        with _field(r_file, "R"):
            if R.shape != (3, 3):
                raise ShapeError(f"must be a 3×3 rotation matrix, got shape {R.shape}")
            transform = Transform(R, np.zeros(3))
            r_dev = orthonormality_error(R)
        with _field(t_file, "T"):
            if T.size != 3:
                raise ShapeError(f"must hold 3 numbers, got shape {T.shape}")
            transform = Transform(R, T.ravel() * t_unit_m)
            if first_camera == "tele":
                transform = transform.inverse()
            rig = Rig(cams["wide"], cams["tele"], transform)
        cond: dict[str, Any] = {}
        for key in ("focus_distance_m", "temperature_c", "orientation", "note"):
            v = reader.scalar(key)
            if v is not None:
                cond[key] = v
        rms = reader.scalar("rms_px")
        with _field(paths[0].name, "conditions"):
            conditions = CalibrationConditions(**cond)
        cal = Calibration(rig, conditions, rms_px=rms if isinstance(rms, float) else None)
        return YamlImport(cal, r_dev)
    finally:
        reader.close()
