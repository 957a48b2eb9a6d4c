"""``find_chessboard`` searches a box-averaged copy of large images (issue #19).

OpenCV's ``findChessboardCorners`` costs seconds on a 2000 × 1500 image, and up to ~30 s on
one without a complete board (the tele views of wide-only calibration poses); the product
searches at half size there and refines on the full image. These tests pin down that the
result is the full-resolution search's: the same corners, the same order.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

import phonestereo.features.chessboard as cb
from phonestereo.charts.verification import Chessboard


def _tilted_board(size: tuple[int, int] = (2000, 1500), seed: int = 0) -> np.ndarray:
    """A 9x6 board (50 mm squares) seen under a mild perspective, blurred, with noise; uint8."""
    board = Chessboard((9, 6), square_m=0.05, margin_m=0.05)
    w, h = size
    # image pixel → chart metres: the board's 0.6 × 0.45 m fill ~60 % of the width, tilted
    corners_px = np.float32([[420, 330], [1580, 390], [1540, 1180], [460, 1120]])
    corners_m = np.float32([[0, 0], [board.size_m[0], 0], list(board.size_m), [0, board.size_m[1]]])
    H = cv2.getPerspectiveTransform(corners_px, corners_m)
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    uv = cv2.perspectiveTransform(np.stack([xs, ys], -1).reshape(-1, 1, 2), H).reshape(h, w, 2)
    img = np.nan_to_num(board.intensity(uv), nan=0.6) * 200 + 20
    img = cv2.GaussianBlur(img, (0, 0), 1.2)
    img += np.random.default_rng(seed).normal(0, 2.0, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def test_search_factor_keeps_the_search_image_at_least_1000_px() -> None:
    assert cb.search_factor((1500, 2000)) == 2
    assert cb.search_factor((1499, 1999)) == 1  # 999 px on the long side would be too small
    assert cb.search_factor((3000, 4000)) == 4


def test_half_size_search_gives_the_full_resolution_corners(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    img = _tilted_board()
    coarse = cb.find_chessboard(img, (9, 6))
    monkeypatch.setattr(cb, "SEARCH_SIDE_PX", 10**9)  # the search on the full image
    full = cb.find_chessboard(img, (9, 6))
    assert coarse.found and full.found
    np.testing.assert_array_equal(coarse.ids, full.ids)  # same corners, same order
    # The saddle fit converges to one fixed point from either start (it stops when every
    # corner moves < 1e-4 px); measured 3e-5 px on the calibration renders.
    assert np.max(np.abs(coarse.points - full.points)) < 1e-3
