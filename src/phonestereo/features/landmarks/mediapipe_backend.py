"""MediaPipe Face Mesh with iris landmarks as a landmark backend (thesis §1.2.3).

MediaPipe's detectors shrink the whole frame to 128 or 192 px, so a face a few percent of a
2000-px image is never found on the full frame. The search therefore runs in two stages:

1. **Find**: the full-range face detector on square tiles of an image pyramid — tile sides
   ``max(W, H)``, half of it, a quarter, ... down to ``min_tile_px``, overlapping by half a
   tile — then non-maximum suppression of the boxes (mapped to full-image pixels).
2. **Measure**: for each box, a square crop ``crop_scale`` times the box side, centred on
   it (padded with black past the image border), resampled to between ``crop_px`` pixels
   a side (area interpolation down, cubic up), and Face Mesh (static images,
   ``refine_landmarks=True``) on it. The mesh nearest the crop centre is mapped back:
   MediaPipe's normalised ``x`` has 0 at the crop's left *edge*, so a crop starting at pixel
   ``X0`` with side ``S`` maps it to ``X0 − 0.5 + x·S`` (docs/conventions.md); ``z`` scales
   by ``S`` too.

Faces found twice (overlapping tiles, neighbouring crops) are merged by pupil midpoint.
Each face gets its pupils (iris centres), the thesis's eye centres
(:mod:`~phonestereo.features.landmarks.eyes`) and its yaw from the 3-D mesh
(:mod:`~phonestereo.features.landmarks.pose`). Profiles (|yaw| > ``max_yaw_rad``), faces with
an eye outside the image and faces too small to measure are rejected with the reason.

MediaPipe 0.10.21 ships its models in the wheel (no download). The model objects are created
once per :meth:`MediaPipeBackend.detect` / :meth:`~MediaPipeBackend.detect_many` call.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from phonestereo.errors import InputError
from phonestereo.features.landmarks.base import (
    F64,
    U8,
    BoxPx,
    Face,
    FaceResult,
    ImageLike,
    LandmarkBackend,
    Rejected,
    as_gray_or_rgb,
    make_result,
)
from phonestereo.features.landmarks.eyes import mediapipe_eyes
from phonestereo.features.landmarks.pose import MAX_YAW_RAD, yaw_from_landmarks
from phonestereo.features.landmarks.quiet import native_stderr_silenced, quiet_env
from phonestereo.features.landmarks.tiles import Box, crop_square, nms, tile_grid, unrotate

__all__ = ["MediaPipeBackend", "nms", "tile_grid", "unrotate"]


def _solutions() -> Any:
    """``mediapipe.solutions`` (imported lazily: it is slow to import and logs to stderr)."""
    quiet_env()
    import mediapipe as mp

    return mp.solutions


@dataclass(frozen=True)
class MediaPipeBackend(LandmarkBackend):
    """Faces, pupils and yaw with MediaPipe Face Mesh (iris landmarks), any face size.

    Examples
    --------
    >>> res = MediaPipeBackend().detect(np.full((240, 320), 128, np.uint8))   # blank image
    >>> res.found, res.reason
    (False, 'no face found (1 tile(s) of 320 px searched)')
    """

    #: Face-detector score threshold in (0, 1).
    min_detection_confidence: float = 0.5
    #: Smallest search tile side, pixels. The full-range detector finds faces down to about 6 % of a
    #: tile; the smallest tile side is the first of max(W, H) / 2^k at or above ``min_tile_px`` (500
    #: px for a 2000-px image: faces from ~30 px wide, IPD ~13 px).
    min_tile_px: int = 256
    #: Side of the landmark crop relative to the detected face box.
    crop_scale: float = 2.2
    #: Range of the crop side after resampling, pixels (small faces are upsampled).
    crop_px: tuple[int, int] = (256, 768)
    #: At most this many candidates get landmarks (highest detector score first).
    max_faces: int = 64
    #: Faces turned further are rejected as profiles.
    max_yaw_rad: float = MAX_YAW_RAD
    #: Faces with a smaller pixel IPD are rejected as too small to measure.
    min_ipd_px: float = 8.0
    #: Also run Face Mesh on the mirrored crop and average pupils, eye centres and yaw (halves the
    #: network's left/right bias: mirrored images give the same IPD).
    mirror_average: bool = True
    #: tuple of int. Also search the image turned by these many quarter turns counter-clockwise
    #: (MediaPipe misses faces rolled by more than ~45°); ``(0, 1, 2, 3)`` for any orientation, at
    #: 4× the time. Results are in the original image's pixels.
    quarter_turns: tuple[int, ...] = (0,)
    #: Search the whole image and one level of tiles (:func:`tile_grid`'s ``two_level``) instead of
    #: the pyramid down to ``min_tile_px``: ~3× fewer detector runs.
    two_level_tiles: tuple[float, float] | None = None
    #: Tiles larger than this are shrunk by a whole factor (area average, to at most this side)
    #: before the face detector, which sees them at 192 px anyway; the landmarks are still measured
    #: on full-resolution crops. None: the tiles as they are (a 12 MP image's whole-image tile costs
    #: MediaPipe ~30 ms to take in and resize).
    detector_max_px: int | None = None
    name: str = "mediapipe"

    def __post_init__(self) -> None:
        if not 0 < self.min_detection_confidence < 1:
            raise InputError(
                f"min_detection_confidence must be in (0, 1), got {self.min_detection_confidence}"
            )
        if self.min_tile_px < 64:
            raise InputError(f"min_tile_px must be >= 64, got {self.min_tile_px}")
        if self.crop_scale < 1.2:
            raise InputError(f"crop_scale must be >= 1.2 (whole face), got {self.crop_scale}")
        lo, hi = self.crop_px
        if not 128 <= lo <= hi:
            raise InputError(f"crop_px must be (lo, hi) with 128 <= lo <= hi, got {self.crop_px}")
        if not self.quarter_turns or any(k not in (0, 1, 2, 3) for k in self.quarter_turns):
            raise InputError(f"quarter_turns must be values in 0..3, got {self.quarter_turns}")
        if self.max_faces < 1:
            raise InputError(f"max_faces must be >= 1, got {self.max_faces}")
        if self.detector_max_px is not None and self.detector_max_px < 192:
            raise InputError(
                f"detector_max_px must be >= 192 (the detector's input) or None, got "
                f"{self.detector_max_px}"
            )

    @contextlib.contextmanager
    def _models(self) -> Iterator[tuple[Any, Any]]:
        # The models are built once per backend and kept (building them costs ~50 ms, more
        # than a face mesh); static-image mode carries no state from one image to the next.
        # MediaPipe's C++ log lines (graph creation, first runs) are dropped unless verbose.
        with native_stderr_silenced():
            yield self._open()

    def _open(self) -> tuple[Any, Any]:
        cached = self.__dict__.get("_open_models")
        if cached is None:
            sol = _solutions()
            det = sol.face_detection.FaceDetection(
                model_selection=1, min_detection_confidence=self.min_detection_confidence
            )
            mesh = sol.face_mesh.FaceMesh(
                static_image_mode=True,
                max_num_faces=3,
                refine_landmarks=True,
                min_detection_confidence=0.3,
            )
            cached = (det, mesh)
            object.__setattr__(self, "_open_models", cached)
        return cached

    def __getstate__(self) -> dict[str, Any]:
        """Pickle without the open models (they are rebuilt where the copy runs)."""
        return {k: v for k, v in self.__dict__.items() if k != "_open_models"}

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    def close(self) -> None:
        """Release the MediaPipe models (rebuilt on the next call)."""
        cached = self.__dict__.pop("_open_models", None)
        if cached is not None:
            with native_stderr_silenced():
                for m in cached:
                    m.close()

    def detect(self, image: ImageLike) -> FaceResult:
        """Faces of one image (array (H, W) gray / (H, W, 3) BGR uint8, or a path)."""
        rgb = as_gray_or_rgb(image)
        with self._models() as (det, mesh):
            return self._detect(rgb, det, mesh)

    def detect_many(self, images: Iterable[ImageLike]) -> list[FaceResult]:
        """Faces of each image, sharing one set of MediaPipe models."""
        with self._models() as (det, mesh):
            return [self._detect(as_gray_or_rgb(im), det, mesh) for im in images]

    def _detect(self, rgb: U8, det: Any, mesh: Any) -> FaceResult:
        h, w = rgb.shape[:2]
        faces: list[Face] = []
        rejected: list[Rejected] = []
        n_tiles, sides = 0, set()
        for k in self.quarter_turns:
            view = np.ascontiguousarray(np.rot90(rgb, k))
            tiles = tile_grid(view.shape[1], view.shape[0], self.min_tile_px, self.two_level_tiles)
            n_tiles += len(tiles)
            sides |= {t[2] for t in tiles}
            boxes = nms(_find_boxes(view, tiles, det, self.detector_max_px))[: self.max_faces]
            self._measure(view, boxes, k, mesh, faces, rejected)
        faces = _dedupe(faces)
        rejected = [r for r in rejected if not _covered(r, faces)]
        searched = f"{n_tiles} tile(s) of {', '.join(str(s) for s in sorted(sides)[::-1])} px"
        if len(self.quarter_turns) > 1:
            searched += f" in {len(self.quarter_turns)} orientations"
        return make_result(
            faces,
            (w, h),
            self.name,
            rejected=rejected,
            empty_reason=f"no face found ({searched} searched)",
        )

    def detect_in_boxes(self, image: ImageLike, boxes: Sequence[BoxPx]) -> FaceResult:
        """Faces in the given face boxes (x0, y0, x1, y1) px, measured without the tiled search.

        Each box is treated as a face detection: Face Mesh runs on the crop around it (the
        *measure* stage of the module docstring). On a 2000 × 1500 image with a few faces this
        is ~4× faster than :meth:`detect`, whose tiled search is most of the cost.
        """
        rgb = as_gray_or_rgb(image)
        h, w = rgb.shape[:2]
        faces: list[Face] = []
        rejected: list[Rejected] = []
        cand: list[Box] = [
            (float(b[0]), float(b[1]), float(b[2]), float(b[3]), 1.0) for b in boxes
        ][: self.max_faces]
        with self._models() as (_det, mesh):
            self._measure(rgb, cand, 0, mesh, faces, rejected)
        faces = _dedupe(faces)
        rejected = [r for r in rejected if not _covered(r, faces)]
        why = f"no face found in the {len(cand)} given box(es)"
        return make_result(faces, (w, h), self.name, rejected=rejected, empty_reason=why)

    def _measure(
        self,
        view: U8,
        boxes: list[Box],
        k: int,
        mesh: Any,
        faces: list[Face],
        rejected: list[Rejected],
    ) -> None:
        """Face Mesh on each candidate box of ``view`` (the image turned ``k`` quarter turns);
        appends to ``faces`` / ``rejected`` in the original image's pixels."""
        h, w = view.shape[:2] if k % 2 == 0 else view.shape[1::-1]
        for box in boxes:
            runs = [unrotate(r, k, (w, h)) for r in self._mesh(view, box, mesh)]
            if not runs:
                corners = unrotate(np.array([box[:2], box[2:4]]), k, (w, h))
                lo, hi = corners.min(axis=0), corners.max(axis=0)
                why = "face detected but Face Mesh found no landmarks"
                rejected.append(Rejected((lo[0], lo[1], hi[0], hi[1]), why))
                continue
            item = self._face(runs, box[4], (w, h))
            if isinstance(item, Face):
                faces.append(item)
            else:
                rejected.append(item)

    def _mesh(self, rgb: U8, box: Box, mesh: Any) -> list[F64]:
        """Face Mesh on the crop around ``box`` and, with ``mirror_average``, on its mirror
        image: per run that found the face, landmarks (478, 3) in image pixels (the mirrored
        run's eye labels are swapped)."""
        x0, y0, x1, y1 = box[:4]
        side = max(round(self.crop_scale * max(x1 - x0, y1 - y0)), 16)
        lo, hi = self.crop_px
        if side > hi:
            # Shrink by a whole factor k (the crop grown by < k px to a multiple of it):
            # OpenCV's area interpolation is ~20× faster at integer ratios.
            k = -(-side // hi)
            side = k * -(-side // k)
            n = side // k
        else:
            n = max(side, lo)
        cx, cy = 0.5 * (x0 + x1), 0.5 * (y0 + y1)
        X0, Y0 = round(cx - 0.5 * (side - 1)), round(cy - 0.5 * (side - 1))
        crop = crop_square(rgb, X0, Y0, side)
        if n != side:
            interp = cv2.INTER_AREA if n < side else cv2.INTER_CUBIC
            crop = cv2.resize(crop, (n, n), interpolation=interp)
        crop = _to_rgb(crop)  # a gray image is turned into RGB only here, after the resize
        runs = []
        for flip in (False, True) if self.mirror_average else (False,):
            img = np.ascontiguousarray(crop[:, ::-1]) if flip else crop
            xyz = _central_mesh(mesh.process(img))
            if xyz is None:
                continue
            if flip:
                xyz[:, 0] = 1.0 - xyz[:, 0]  # back into the crop's frame
            x, y, z = (X0 - 0.5 + xyz[:, 0] * side, Y0 - 0.5 + xyz[:, 1] * side, xyz[:, 2] * side)
            runs.append(np.column_stack([x, y, z]))
        return runs

    def _face(self, runs: list[F64], score: float, size: tuple[int, int]) -> Face | Rejected:
        """A face from one or two mesh runs: pupils, eye centres and yaw averaged (each run's
        face axis is oriented from eye 0 to eye 1, so a mirrored run's swapped labels cancel)."""
        pts = runs[0]
        eyes = [mediapipe_eyes(r) for r in runs]
        pupils = np.mean([e[0] for e in eyes], axis=0)
        centres = np.mean([e[1] for e in eyes], axis=0)
        toward = pupils[1] - pupils[0]
        yaw = float(np.mean([yaw_from_landmarks(r, toward=toward) for r in runs]))
        lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
        box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        w, h = size
        inside = (pupils >= -0.5).all(axis=1) & (pupils <= [w - 0.5, h - 0.5]).all(axis=1)
        ipd = float(np.linalg.norm(pupils[1] - pupils[0]))
        if not inside.all():
            return Rejected(box, "one eye outside the image (face cut by the border)")
        if abs(yaw) > self.max_yaw_rad:
            return Rejected(
                box,
                f"profile face (yaw {np.degrees(yaw):+.0f}°, limit "
                f"±{np.degrees(self.max_yaw_rad):.0f}°): the far eye is not measurable",
            )
        if ipd < self.min_ipd_px:
            return Rejected(box, f"face too small (ipd {ipd:.1f} px < {self.min_ipd_px:g} px)")
        return Face(pupils, centres, pts[:, :2], yaw, score, np.array(box))


def _shrunk(tile: U8, k: int) -> U8:
    """``tile`` (sides multiples of ``k``) area-averaged over k × k blocks (OpenCV's fast
    integer-ratio path); its normalised coordinates are unchanged (edge to edge)."""
    if k <= 1:
        return np.ascontiguousarray(tile)
    h, w = tile.shape[:2]
    return cv2.resize(tile, (w // k, h // k), interpolation=cv2.INTER_AREA)


def _to_rgb(image: U8) -> U8:
    """An (H, W, 3) RGB view of a gray (H, W) or RGB image (the models take RGB)."""
    return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB) if image.ndim == 2 else image


def _central_mesh(res: Any) -> F64 | None:
    """Normalised landmarks (478, 3) of the mesh nearest the crop centre, or None."""
    best, best_d = None, np.inf
    for lm in res.multi_face_landmarks or ():
        xyz = np.array([(p.x, p.y, p.z) for p in lm.landmark], dtype=np.float64)
        d = float(np.hypot(*(xyz[:, :2].mean(axis=0) - 0.5)))
        if d < best_d:
            best, best_d = xyz, d
    return best


def _find_boxes(
    rgb: U8, tiles: list[tuple[int, int, int]], det: Any, max_px: int | None = None
) -> list[Box]:
    """Face-detector boxes over all tiles, in full-image pixels (x0, y0, x1, y1, score);
    tiles larger than ``max_px`` are shrunk first (:func:`_shrunk`)."""
    out: list[Box] = []
    for x0, y0, side in tiles:
        tile = rgb[y0 : y0 + side, x0 : x0 + side]
        k = 1 if max_px is None else -(-max(tile.shape[:2]) // max_px)
        th, tw = (tile.shape[0] // k) * k, (tile.shape[1] // k) * k
        res = det.process(_to_rgb(_shrunk(tile[:th, :tw], k)))
        for d in res.detections or ():
            b = d.location_data.relative_bounding_box
            bx0 = x0 - 0.5 + b.xmin * tw
            by0 = y0 - 0.5 + b.ymin * th
            bx1, by1 = bx0 + b.width * tw, by0 + b.height * th
            if bx1 - bx0 < 4 or by1 - by0 < 4:
                continue
            out.append((bx0, by0, bx1, by1, float(d.score[0])))
    return out


def _dedupe(faces: list[Face]) -> list[Face]:
    """Drop faces whose pupil midpoint is within half an IPD of a higher-scoring one."""
    kept: list[Face] = []
    for f in sorted(faces, key=lambda f: -f.score):
        if all(np.linalg.norm(f.midpoint_px - k.midpoint_px) > 0.5 * k.ipd_px for k in kept):
            kept.append(f)
    return kept


def _covered(r: Rejected, faces: list[Face]) -> bool:
    """True when a rejected candidate's box holds an accepted face's pupils (a duplicate)."""
    x0, y0, x1, y1 = r.box_px
    for f in faces:
        mx, my = f.midpoint_px
        if x0 <= mx <= x1 and y0 <= my <= y1:
            return True
    return False
