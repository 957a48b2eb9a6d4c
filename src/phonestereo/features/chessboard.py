"""Plain chessboard detection: OpenCV finds and orders the board, the saddle fit refines it.

Used for multi-pose calibration boards such as OpenCV's sample set (thesis §1.3.2). The
verification chart with circle pairs has its own detector; both share :func:`refine_saddle`.

OpenCV's search (``cv2.findChessboardCorners``) runs on a copy box-averaged by an integer
factor that keeps its longer side ≥ :data:`SEARCH_SIDE_PX` (2 for a 2000 × 1500 image, 4 for
12 MP); only the coarse corner positions come from it, the saddle fit on the full image gives
the final ones. On 2000 × 1500 renders this takes an image without a complete board from
2–29 s to 0.2–2.3 s and one with a board from ~1 s to ~0.1 s, and the refined corners are the
same (the fit converges to the same fixed point from either start). OpenCV's quick check
(``cv2.checkChessboard``) runs first: an image it rejects is searched with
``CALIB_CB_FAST_CHECK`` (~10 ms instead of 1–5 s), with the same detections on OpenCV's stereo
set and a rendered calibration set (docs/module-random.md, session 26).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import cv2
import numpy as np

from phonestereo.errors import InputError
from phonestereo.features.noise_level import estimate_noise_level
from phonestereo.features.saddle import SaddleCorners, refine_saddle

#: The search image keeps its longer side at least this long (px): a 9x6 board spanning a
#: third of it still has squares of ~30 px there, far above what OpenCV's search needs.
SEARCH_SIDE_PX = 1000


@dataclass(frozen=True, eq=False)
class ChessboardDetection:
    """Corners of a plain chessboard, or the reason there are none."""

    found: bool
    #: Empty when found; otherwise what went wrong, for the user.
    reason: str
    #: ndarray, shape (N, 2). Refined corners, row-major (id = row·cols + col) like OpenCV's object
    #: points.
    points: np.ndarray
    #: ndarray of int, shape (N,)
    ids: np.ndarray
    #: ndarray, shape (N,). Saddle strength per corner (intensity / px²).
    quality: np.ndarray
    #: ndarray, shape (N,). Predicted position σ per coordinate from the image noise
    #: (``SaddleCorners.sigma_px``).
    sigma_px: np.ndarray


def find_chessboard(image: np.ndarray, pattern: tuple[int, int]) -> ChessboardDetection:
    """Find a plain chessboard of ``pattern = (cols, rows)`` inner corners, refined to sub-pixel.

    Parameters
    ----------
    image : ndarray, shape (H, W), uint8
        Grayscale image.
    pattern : (int, int)
        Inner corners per row and per column (OpenCV's patternSize).

    Returns
    -------
    ChessboardDetection
        ``found=False`` with a reason when the board is not there (not an exception).
    """
    cols, rows = pattern
    if cols < 2 or rows < 2:
        raise InputError(f"board must have at least 2x2 inner corners, got {cols}x{rows}")
    corners = _search(image, (cols, rows))
    empty = np.zeros((0, 2))
    if corners is None:
        return ChessboardDetection(
            False,
            f"no complete {cols}x{rows} inner-corner chessboard found",
            empty,
            np.zeros(0, np.int64),
            np.zeros(0),
            np.zeros(0),
        )
    start = corners
    # Window: 0.35 of the smallest corner spacing keeps neighbours out of the fit.
    grid = start.reshape(rows, cols, 2)
    spacing = min(
        float(np.min(np.linalg.norm(np.diff(grid, axis=1), axis=2))),
        float(np.min(np.linalg.norm(np.diff(grid, axis=0), axis=2))),
    )
    radius = float(np.clip(0.35 * spacing, 2.0, 6.0))
    refine = _refiner(image, radius)
    res = refine(start)
    grid = res.points.reshape(rows, cols, 2)
    larger = _extends_beyond(image.shape, grid, res.saddle_strength, radius, refine)
    if larger:
        return ChessboardDetection(
            False,
            f"the board has more inner corners than {cols}x{rows} (it continues past the "
            f"{larger} edge); check --board (inner corners COLSxROWS)",
            res.points,
            np.arange(cols * rows),
            res.saddle_strength,
            res.sigma_px,
        )
    keep = res.ok
    bad = int(np.count_nonzero(~keep))
    ids = np.arange(cols * rows)
    if bad > keep.size // 2:
        return ChessboardDetection(
            False,
            f"{bad} of {keep.size} corners are not clean saddles (blur, glare, occlusion)",
            res.points,
            ids,
            res.saddle_strength,
            res.sigma_px,
        )
    note = f"{bad} corner(s) dropped: not clean saddles" if bad else ""
    return ChessboardDetection(
        True, note, res.points[keep], ids[keep], res.saddle_strength[keep], res.sigma_px[keep]
    )


def search_factor(shape: tuple[int, ...]) -> int:
    """Integer box-averaging factor of OpenCV's board search for an image of ``shape``.

    Examples
    --------
    >>> search_factor((1500, 2000)), search_factor((480, 640)), search_factor((3024, 4032))
    (2, 1, 4)
    """
    return max(1, int(max(shape[:2]) // SEARCH_SIDE_PX))


def _search(image: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """OpenCV's ordered corners (N, 2) in full-image pixels, or None (no complete board).

    Searched on the image box-averaged by :func:`search_factor` ``s``; the centre of coarse
    pixel i is full-image pixel s·i + (s − 1)/2 (pixel centres at integers).
    """
    s = search_factor(image.shape)
    small = image
    if s > 1:  # whole s × s blocks (a ragged last row/column dropped): exact box means
        h, w = image.shape[0] // s, image.shape[1] // s
        small = cv2.resize(image[: h * s, : w * s], (w, h), interpolation=cv2.INTER_AREA)
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    if not cv2.checkChessboard(small, pattern):
        # OpenCV's quick check (a few ms) says no board, and the full search of an image
        # without one takes 1–5 s: search with CALIB_CB_FAST_CHECK, whose own checks end it
        # in ~10 ms, so a board is missed only where that flag would miss it. An image the
        # quick check passes is searched without the flag (it makes found boards ~8× slower).
        flags |= cv2.CALIB_CB_FAST_CHECK
    ok, corners = cv2.findChessboardCorners(small, pattern, flags=flags)
    if not ok or corners is None:
        return None
    return corners.reshape(-1, 2).astype(np.float64) * s + (s - 1) / 2


def _refiner(image: np.ndarray, radius: float) -> Callable[[np.ndarray], SaddleCorners]:
    """``refine_saddle`` on ``image`` with window ``radius`` and pre-blur min(1.5, radius/3).

    The image is blurred, and its noise level and saddle-strength floor (refine_saddle's
    default: 0.2 % of the blurred image's 1–99 % range) computed, once for every call; the
    results are those of ``refine_saddle(image, points, radius_px=radius, blur_sigma_px=blur)``.
    """
    blur = min(1.5, radius / 3)
    noise = estimate_noise_level(image)
    f = cv2.GaussianBlur(np.asarray(image, dtype=np.float32), (0, 0), blur)
    lo, hi = np.percentile(f, [1, 99])
    return partial(
        refine_saddle,
        f,
        radius_px=radius,
        blur_sigma_px=0.0,
        min_strength=2e-3 * max(float(hi - lo), 1e-12),
        noise=noise,
        prefilter_sigma_px=blur,
    )


def _extends_beyond(
    shape: tuple[int, ...],
    grid: np.ndarray,
    strength: np.ndarray,
    radius: float,
    refine: Callable[[np.ndarray], SaddleCorners],
) -> str:
    """Name a side past which the chessboard continues (a sub-board was found), or ''.

    OpenCV's detector happily returns an 8×6 sub-board of a 9×6 board. One grid step beyond
    each side, a real board edge has no saddles; a larger board has a full row of them.
    """
    sides = {
        "top": 2 * grid[0] - grid[1],
        "bottom": 2 * grid[-1] - grid[-2],
        "left": 2 * grid[:, 0] - grid[:, 1],
        "right": 2 * grid[:, -1] - grid[:, -2],
    }
    h, w = shape[:2]
    typical = float(np.median(strength))
    for name, pts in sides.items():
        inside = (
            (pts[:, 0] > radius)
            & (pts[:, 1] > radius)
            & (pts[:, 0] < w - 1 - radius)
            & (pts[:, 1] < h - 1 - radius)
        )
        if inside.sum() < 2:
            continue
        r = refine(pts[inside])
        # A continuing board has full-strength saddles; where the outer squares meet the white
        # margin the fit still finds weak ones (0.3–0.47 of typical), so the bar is 0.6.
        strong = r.ok & (r.saddle_strength > 0.6 * typical)
        if strong.mean() >= 0.8:
            return name
    return ""
