"""Fast tests of the calibration-on-renders support (``tests/_support/calib_sim.py``)."""

from __future__ import annotations

import numpy as np

from _support.calib_sim import detect_board


def _synthetic_board(turn: int) -> tuple[np.ndarray, np.ndarray]:
    """A fronto-parallel 9x6 board image (40 px squares) turned by ``turn`` × 90°, + its grid."""
    from phonestereo.charts.verification import Chessboard

    board = Chessboard((9, 6), square_m=1.0, margin_m=1.0)
    s, size = 40.0, (560, 560)
    ys, xs = np.mgrid[0 : size[1], 0 : size[0]].astype(float)
    uv = np.stack([xs, ys], axis=-1) / s - 0.5 * (np.array(size) / s - np.array(board.size_m))
    ang = turn * np.pi / 2
    c, sn = np.cos(ang), np.sin(ang)
    mid = np.array(board.size_m) / 2
    d = uv - mid
    uv = mid + np.stack([c * d[..., 0] + sn * d[..., 1], -sn * d[..., 0] + c * d[..., 1]], -1)
    img = np.nan_to_num(board.intensity(uv), nan=0.5)
    corners = board.corners_uv() - mid
    inv = np.stack(
        [c * corners[:, 0] - sn * corners[:, 1], sn * corners[:, 0] + c * corners[:, 1]], -1
    )
    px = (inv + mid + 0.5 * (np.array(size) / s - np.array(board.size_m))) * s
    return (img * 255).astype(np.uint8), px


def test_shipped_detector_gives_the_canonical_order_at_any_turn() -> None:
    for turn in range(4):
        img, truth = _synthetic_board(turn)
        found = detect_board(img, (9, 6))
        assert found is not None, turn
        q, ids = found
        # Canonical order whatever the board's turn in the image (cols + rows odd: OpenCV's
        # order starts at the same corner): ids name the same corners (point-sampled edges
        # sit 0.5 px off the drawn ones; a wrong order is ≥ 40 px off).
        assert np.max(np.linalg.norm(q - truth[ids], axis=1)) < 1.0, turn
