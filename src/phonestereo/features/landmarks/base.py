"""The landmark backend interface: one image in, a :class:`FaceResult` out (thesis §1.2.3).

Every backend (MediaPipe Face Mesh, OpenFace CSV import, ...) returns the same
:class:`Face` records, in the pixel convention of docs/conventions.md ((0, 0) is the centre of the
top-left pixel, coordinates (x, y)). Eye 0 is always the eye on the image left (the
subject's right eye on a frontal face).

A face that was found but cannot serve as a ruler (profile, one eye outside the image, ...)
is listed in :attr:`FaceResult.rejected` with its reason; an image without usable faces is a
:class:`FaceResult` with ``faces == ()`` and a ``reason`` — never an exception.
"""

from __future__ import annotations

import os
from abc import ABC, abstractmethod
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Protocol

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]
ImageLike = Any  # (H, W) / (H, W, 3) uint8 array (BGR, OpenCV order) or an image path


def _frozen(a: Any, shape: tuple[int | None, ...], name: str) -> F64:
    arr = np.array(a, dtype=np.float64)
    if arr.ndim != len(shape) or any(
        s is not None and s != n for s, n in zip(shape, arr.shape, strict=False)
    ):
        want = "(" + ", ".join("K" if s is None else str(s) for s in shape) + ")"
        raise ShapeError(f"{name} must have shape {want}, got {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Face:
    """One face measured in one image."""

    #: ndarray, shape (2, 2). Pupil centres (x, y), pixels; row 0 is the eye on the image left.
    pupils_px: F64
    #: ndarray, shape (2, 2). The thesis's eye centres: centroid of each eye's contour landmarks,
    #: same order.
    eye_centres_px: F64
    #: ndarray, shape (K, 2). All landmarks of the backend (MediaPipe: K = 478, OpenFace: K = 68),
    #: pixels.
    landmarks_px: F64
    #: Head yaw: the eye axis's angle out of the frontal plane, positive when eye 1 (image right) is
    #: farther from the camera than eye 0. NaN when unknown.
    yaw_rad: float
    #: Detection confidence in [0, 1].
    score: float
    #: ndarray, shape (4,). Landmark bounding box (x0, y0, x1, y1), pixels.
    box_px: F64
    #: ``"iris"`` (iris landmarks) or ``"eye-contour"`` (no iris landmarks: pupils are the eye
    #: centres).
    pupil_source: str = "iris"
    #: What the yaw is measured from: ``"sight"`` (the plane perpendicular to the line of sight;
    #: appearance-based landmarks such as MediaPipe's) or ``"image"`` (the image plane; OpenFace's
    #: head pose in camera coordinates). See :func:`phonestereo.learning.ipd.face_depth`.
    yaw_reference: str = "sight"

    def __post_init__(self) -> None:
        object.__setattr__(self, "pupils_px", _frozen(self.pupils_px, (2, 2), "pupils_px"))
        object.__setattr__(
            self, "eye_centres_px", _frozen(self.eye_centres_px, (2, 2), "eye_centres_px")
        )
        object.__setattr__(
            self, "landmarks_px", _frozen(self.landmarks_px, (None, 2), "landmarks_px")
        )
        object.__setattr__(self, "box_px", _frozen(self.box_px, (4,), "box_px"))
        object.__setattr__(self, "yaw_rad", float(self.yaw_rad))
        object.__setattr__(self, "score", float(self.score))
        if self.yaw_reference not in ("sight", "image"):
            raise InputError(
                f"yaw_reference must be 'sight' or 'image', got {self.yaw_reference!r}"
            )

    @property
    def ipd_px(self) -> float:
        """Pupil-to-pupil distance in the image, pixels (foreshortened by the yaw)."""
        return float(np.linalg.norm(self.pupils_px[1] - self.pupils_px[0]))

    @property
    def eye_centre_ipd_px(self) -> float:
        """Distance between the eye-contour centroids, pixels."""
        return float(np.linalg.norm(self.eye_centres_px[1] - self.eye_centres_px[0]))

    @property
    def ipd_frontal_px(self) -> float:
        """``ipd_px / cos(yaw)``: the pixel IPD the face would have facing the camera (eq. 11).

        An unknown yaw (NaN) is taken as frontal.
        """
        yaw = self.yaw_rad if np.isfinite(self.yaw_rad) else 0.0
        return self.ipd_px / float(np.cos(yaw))

    @property
    def midpoint_px(self) -> F64:
        """Midpoint of the two pupils (x, y), pixels."""
        return np.asarray(self.pupils_px.mean(axis=0))

    def to_dict(self, landmarks: bool = False) -> dict[str, Any]:
        """JSON-friendly record (pixels rounded to 1e-3 px, yaw in degrees too)."""
        yaw = None if not np.isfinite(self.yaw_rad) else round(self.yaw_rad, 5)
        out: dict[str, Any] = {
            "pupils_px": np.round(self.pupils_px, 3).tolist(),
            "eye_centres_px": np.round(self.eye_centres_px, 3).tolist(),
            "ipd_px": round(self.ipd_px, 3),
            "eye_centre_ipd_px": round(self.eye_centre_ipd_px, 3),
            "ipd_frontal_px": round(self.ipd_frontal_px, 3),
            "yaw_rad": yaw,
            "yaw_deg": None if yaw is None else round(float(np.degrees(yaw)), 2),
            "score": round(self.score, 4),
            "box_px": np.round(self.box_px, 2).tolist(),
            "pupil_source": self.pupil_source,
            "yaw_reference": self.yaw_reference,
        }
        if landmarks:
            out["landmarks_px"] = np.round(self.landmarks_px, 3).tolist()
        return out


@dataclass(frozen=True)
class Rejected:
    """A face candidate that was found but not used, and why (box (x0, y0, x1, y1), px)."""

    box_px: tuple[float, float, float, float]
    reason: str


@dataclass(frozen=True, eq=False)
class FaceResult:
    """The faces of one image, image-left first (by pupil midpoint x).

    ``reason`` is empty when at least one face was found; otherwise it says why none was
    (no face detected, or every candidate rejected and why). ``notes`` hold caveats that do
    not stop the measurement (e.g. a CSV without head-pose columns).
    """

    faces: tuple[Face, ...]
    image_size: tuple[int, int]
    backend: str
    reason: str = ""
    rejected: tuple[Rejected, ...] = ()
    notes: tuple[str, ...] = field(default=())

    @property
    def found(self) -> bool:
        """True when at least one usable face was found."""
        return len(self.faces) > 0

    def __len__(self) -> int:
        return len(self.faces)

    def __iter__(self) -> Iterator[Face]:
        return iter(self.faces)

    def to_dict(self, landmarks: bool = False) -> dict[str, Any]:
        """JSON-friendly summary (see :meth:`Face.to_dict`)."""
        return {
            "backend": self.backend,
            "image_size": list(self.image_size),
            "found": self.found,
            "reason": self.reason,
            "n_faces": len(self.faces),
            "faces": [f.to_dict(landmarks) for f in self.faces],
            "rejected": [
                {"box_px": [round(v, 2) for v in r.box_px], "reason": r.reason}
                for r in self.rejected
            ],
            "notes": list(self.notes),
        }


def make_result(
    faces: Iterable[Face],
    image_size: tuple[int, int],
    backend: str,
    *,
    rejected: Iterable[Rejected] = (),
    notes: Iterable[str] = (),
    empty_reason: str = "no face found",
) -> FaceResult:
    """Sort ``faces`` image-left first and fill ``reason`` when none is usable."""
    ordered = tuple(sorted(faces, key=lambda f: (float(f.midpoint_px[0]), float(f.midpoint_px[1]))))
    rej = tuple(rejected)
    reason = ""
    if not ordered:
        reason = empty_reason
        if rej:
            why = "; ".join(sorted({r.reason for r in rej}))
            reason = f"{len(rej)} face candidate(s) found but none usable: {why}"
    return FaceResult(ordered, image_size, backend, reason, rej, tuple(notes))


class LandmarkBackend(ABC):
    """A facial-landmark backend: ``detect(image) -> FaceResult``.

    Subclasses set :attr:`name` and implement :meth:`detect`; :meth:`detect_many` may share
    expensive state (models) over a batch.
    """

    name: str = "backend"

    @abstractmethod
    def detect(self, image: ImageLike) -> FaceResult:
        """Faces of one image: an array (H, W) gray or (H, W, 3) BGR uint8, or a path."""

    def detect_many(self, images: Iterable[ImageLike]) -> list[FaceResult]:
        """:meth:`detect` on each image, in order."""
        return [self.detect(im) for im in images]

    def detect_in_boxes(self, image: ImageLike, boxes: Sequence[BoxPx]) -> FaceResult:
        """Faces of ``image`` whose pupil midpoint lies in one of ``boxes`` (x0, y0, x1, y1) px.

        A backend with a costly face search overrides this to look only there; this default
        runs :meth:`detect` and keeps the faces inside a box.
        """
        res = self.detect(image)

        def inside(f: Face) -> bool:
            x, y = f.midpoint_px
            return any(b[0] <= x <= b[2] and b[1] <= y <= b[3] for b in boxes)

        kept = [f for f in res.faces if inside(f)]
        why = "no face found in the given boxes"
        return make_result(
            kept, res.image_size, res.backend, rejected=res.rejected, notes=res.notes,
            empty_reason=why,
        )

    def detect_pair(
        self, wide: ImageLike, tele: ImageLike, guide: TeleGuide | None = None
    ) -> tuple[FaceResult, FaceResult]:
        """Faces of a wide/tele pair: (wide result, tele result).

        With a ``guide`` (a wide face → the raw-tele box where the same face is), the wide is
        searched and the tele measured only in the guided boxes (:meth:`detect_in_boxes`):
        the tele sees a part of the wide's view, three times larger, so searching it again
        is wasted work.
        """
        if guide is None:
            fw, ft = self.detect_many([wide, tele])
            return fw, ft
        return guided_pair(self, self, wide, tele, guide)


def guided_pair(
    wide_backend: LandmarkBackend,
    tele_backend: LandmarkBackend,
    wide: ImageLike,
    tele: ImageLike,
    guide: TeleGuide | None,
) -> tuple[FaceResult, FaceResult]:
    """:meth:`LandmarkBackend.detect_pair` with one backend per camera: the wide first, then
    the tele in the boxes ``guide`` maps the wide's faces to (everywhere without a guide)."""
    fw = wide_backend.detect(wide)
    if guide is None:
        return fw, tele_backend.detect(tele)
    boxes = [b for b in (guide(f) for f in fw.faces) if b is not None]
    if not boxes:
        why = f"no wide face to look for in the tele ({fw.reason or 'none maps into it'})"
        return fw, make_result([], _size(tele), tele_backend.name, empty_reason=why)
    return fw, tele_backend.detect_in_boxes(tele, boxes)


#: A face box in pixels: (x0, y0, x1, y1).
BoxPx = tuple[float, float, float, float]


class TeleGuide(Protocol):
    """Where a wide face is in the raw tele image (see :meth:`LandmarkBackend.detect_pair`)."""

    @property
    def key(self) -> str:
        """Identifies the mapping (equal keys → equal boxes), for caches."""

    def __call__(self, wide_face: Face) -> BoxPx | None:
        """The raw-tele box of the same face, or None when it is not in the tele's view."""


def _size(image: ImageLike) -> tuple[int, int]:
    """(W, H) of an image array or file."""
    a = image if isinstance(image, np.ndarray) else as_rgb(image)
    return int(a.shape[1]), int(a.shape[0])


def read_color(path: str | os.PathLike[str]) -> U8:
    """Read an image file as (H, W, 3) uint8 BGR (OpenCV order).

    Raises
    ------
    InputError
        Missing file or not an image OpenCV decodes.
    """
    p = Path(path)
    if p.is_dir():
        raise InputError(f"'{p}' is a folder, not an image file; give the image's path")
    if not p.is_file():
        raise InputError(f"image file not found: '{p}'; check the path")
    data = np.fromfile(p, dtype=np.uint8)
    img = cv2.imdecode(data, cv2.IMREAD_COLOR) if data.size else None
    if img is None or img.size == 0:
        raise InputError(f"cannot decode image file '{p}'; use PNG or JPEG")
    return np.ascontiguousarray(img, dtype=np.uint8)


def as_rgb(image: ImageLike) -> U8:
    """An (H, W, 3) uint8 RGB copy of ``image`` (path, gray, BGR or BGRA array).

    Raises
    ------
    ShapeError
        Not (H, W), (H, W, 3) or (H, W, 4).
    InputError
        Empty or not 8-bit.

    >>> as_rgb(np.zeros((40, 50), np.uint8)).shape
    (40, 50, 3)
    """
    img = as_gray_or_rgb(image)
    return cv2.cvtColor(img, cv2.COLOR_GRAY2RGB) if img.ndim == 2 else img


def as_gray_or_rgb(image: ImageLike) -> U8:
    """:func:`as_rgb`, except that a gray (H, W) array stays gray (no copy).

    For backends that convert only the parts they pass to a model (a 12 MP gray image costs
    ~30 ms to turn into RGB, the tiles and crops actually used a fraction of it); a gray
    crop resized and then replicated to RGB equals the RGB crop resized.

    >>> as_gray_or_rgb(np.zeros((40, 50), np.uint8)).shape
    (40, 50)
    """
    if isinstance(image, str | os.PathLike):
        image = read_color(image)
    img = np.asarray(image)
    if img.size == 0:
        raise InputError(f"image is empty (shape {img.shape}); pass a real image")
    if img.dtype != np.uint8:
        raise InputError(f"image must be 8-bit (uint8), got {img.dtype}; convert it first")
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    if img.ndim == 3 and img.shape[2] == 4:
        return cv2.cvtColor(img, cv2.COLOR_BGRA2RGB)
    raise ShapeError(f"image must be (H, W) gray or (H, W, 3) BGR, got shape {img.shape}")
