"""Calibrate from image files: glob → detect boards → solve (the `phonestereo calibrate` job)."""

from __future__ import annotations

import glob
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from phonestereo.calibration.solve import (
    CalibrationOptions,
    CalibrationResult,
    calibrate_camera,
    calibrate_stereo,
)
from phonestereo.calibration.views import BoardView, chessboard_object_points
from phonestereo.errors import InputError
from phonestereo.features.chessboard import find_chessboard
from phonestereo.io import read_gray


@dataclass(frozen=True)
class ImageReport:
    """What detection made of one image.

    ``corner_sigma_px`` is the median predicted σ of its corners per coordinate, from the
    image noise (NaN when no board was found); ``camera`` is ``wide`` or ``tele``.
    """

    path: str
    found: bool
    n_corners: int
    reason: str
    corner_sigma_px: float = float("nan")
    camera: str = "wide"


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` → (9, 6) inner corners (cols, rows).

    Examples
    --------
    >>> parse_board("9x6")
    (9, 6)
    """
    try:
        cols, rows = (int(v) for v in text.lower().replace("×", "x").split("x"))
    except ValueError as exc:
        raise InputError(
            f"--board must be COLSxROWS inner corners, e.g. 9x6, got '{text}'"
        ) from exc
    if cols < 2 or rows < 2:
        raise InputError(f"--board needs at least 2x2 inner corners, got '{text}'")
    return cols, rows


def _paths(pattern: str, who: str) -> list[Path]:
    paths = sorted(Path(p) for p in glob.glob(pattern))
    if not paths:
        raise InputError(
            f"no {who} images match '{pattern}'; quote the glob so the shell "
            "does not expand it, and check the folder"
        )
    return paths


def _detect(
    paths: list[Path],
    pattern: tuple[int, int],
    obj: np.ndarray,
    progress: Callable[[str], None] | None,
    camera: str = "wide",
) -> tuple[list[BoardView | None], tuple[int, int], list[ImageReport]]:
    views: list[BoardView | None] = []
    reports = []
    size: tuple[int, int] | None = None
    for p in paths:
        img = read_gray(p)
        s = (img.shape[1], img.shape[0])
        if size is None:
            size = s
        elif s != size:
            raise InputError(
                f"{p} is {s[0]}x{s[1]} but earlier images are {size[0]}x{size[1]}; "
                "one camera's images must share a size"
            )
        det = find_chessboard(img, pattern)
        sd = float(np.median(det.sigma_px)) if det.found else float("nan")
        reports.append(ImageReport(str(p), det.found, len(det.ids), det.reason, sd, camera))
        views.append(BoardView(obj[det.ids], det.points, det.ids, str(p)) if det.found else None)
        if progress:
            progress(str(p))
    assert size is not None
    return views, size, reports


def _require_views(reports: list[ImageReport], name: str, minimum: int = 3) -> None:
    found = sum(r.found for r in reports)
    if found >= minimum:
        return
    reasons = Counter(r.reason for r in reports if not r.found)
    why = "; ".join(f"{n}x: {reason}" for reason, n in reasons.most_common(2))
    raise InputError(
        f"only {found} of {len(reports)} images gave a {name} chessboard (need >= {minimum}); "
        f"{why}. Check --board (inner corners COLSxROWS, e.g. 9x6 for 10x7 squares)"
    )


def calibrate_from_images(
    wide_glob: str,
    tele_glob: str | None,
    board: tuple[int, int],
    square_m: float,
    options: CalibrationOptions,
    progress: Callable[[str], None] | None = None,
) -> tuple[CalibrationResult, list[ImageReport]]:
    """Detect a plain chessboard in every image and calibrate (mono, or stereo with tele).

    Stereo pairs are matched by sorted file name: the i-th wide image with the i-th tele image.

    Raises
    ------
    InputError
        No images, different image sizes within a camera, unequal pair counts, no board found,
        or too few views for the model.
    """
    obj = chessboard_object_points(board, square_m)
    wide_paths = _paths(wide_glob, "wide")
    wv, wsize, reports = _detect(wide_paths, board, obj, progress)
    name = f"{board[0]}x{board[1]}"
    _require_views(reports, name)
    if tele_glob is None:
        return calibrate_camera([v for v in wv if v is not None], wsize, options), reports
    tele_paths = _paths(tele_glob, "tele")
    if len(tele_paths) != len(wide_paths):
        raise InputError(
            f"{len(wide_paths)} wide vs {len(tele_paths)} tele images; stereo "
            "pairs are matched by sorted file name, so the counts must agree"
        )
    tv, tsize, treports = _detect(tele_paths, board, obj, progress, "tele")
    _require_views(treports, name)
    if not any(a is not None and b is not None for a, b in zip(wv, tv, strict=True)):
        raise InputError(
            f"no pair with a {name} chessboard found in both images; "
            "check --board (inner corners COLSxROWS)"
        )
    return calibrate_stereo(wv, tv, (wsize, tsize), options), reports + treports
