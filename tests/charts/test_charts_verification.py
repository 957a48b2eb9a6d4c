"""Verification chart and plain chessboard: layout, circle pairs, intensity (thesis §1.2.2)."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.charts import Chart, Chessboard, VerificationChart
from phonestereo.errors import InputError, ShapeError


def test_default_corners_count_and_spacing() -> None:
    chart = VerificationChart()
    ids, uv = chart.corner_ids(), chart.corners_uv()
    assert chart.squares == (40, 28) and chart.pattern == (39, 27)
    assert ids.shape == (39 * 27, 2) and uv.shape == (39 * 27, 2)
    # Row-major, (row, col); a 25 mm grid starting one square inside the 25 mm margin.
    assert ids[:2].tolist() == [[0, 0], [0, 1]] and ids[-1].tolist() == [26, 38]
    np.testing.assert_allclose(uv[0], [0.05, 0.05], atol=1e-12)
    grid = uv.reshape(27, 39, 2)
    np.testing.assert_allclose(np.diff(grid[..., 0], axis=1), 0.025, atol=1e-12)
    np.testing.assert_allclose(np.diff(grid[..., 1], axis=0), 0.025, atol=1e-12)
    assert chart.size_m == (1.05, 0.75)
    assert isinstance(chart, Chart)


def test_corners_are_where_four_squares_meet() -> None:
    chart = VerificationChart()
    eps = 1e-4  # 0.1 mm diagonally off each corner: inside the four surrounding squares
    uv = chart.corners_uv()
    tl = chart.intensity(uv + np.array([-eps, -eps]))
    tr = chart.intensity(uv + np.array([eps, -eps]))
    br = chart.intensity(uv + np.array([eps, eps]))
    # No circle touches a corner, so every corner is a clean chessboard X junction.
    assert np.all(tl == br) and np.all(tl != tr)
    i, j = chart.corner_ids().T
    np.testing.assert_array_equal(tl == 0.05, (i + j) % 2 == 0)


def test_circle_pairs_clear_of_corners() -> None:
    chart = VerificationChart()
    s = chart.square_m
    corners = chart.corners_uv()
    for pair in chart.circle_pairs:
        assert pair.radius_m == pytest.approx(0.3 * s)
        d = np.linalg.norm(corners[:, None, :] - pair.centers_uv[None], axis=-1) - pair.radius_m
        # brief: circle edge >= 0.15 square from every corner; geometry gives sqrt(2)/2 - 0.3
        assert d.min() >= 0.15 * s
        assert d.min() == pytest.approx((np.sqrt(0.5) - 0.3) * s)


def test_circle_pairs_unique_and_central() -> None:
    chart = VerificationChart()
    pairs = chart.circle_pairs
    assert len(pairs) == 4
    assert len({(p.axis, p.polarity) for p in pairs}) == 4  # each pair identifiable alone
    centre_sq = np.array([14, 20])  # the board's centre square (row, col)
    for p in pairs:
        sq = p.square_ids
        step = sq[1] - sq[0]
        assert step.tolist() == ([0, 2] if p.axis == "h" else [2, 0])
        # dark circles sit in white squares ((r + c) odd), light circles in black ones
        assert np.all((sq.sum(axis=1) % 2 == 1) == (p.polarity == "dark"))
        off = sq - centre_sq
        assert np.all((off[:, 0] >= -3) & (off[:, 0] < 3) & (off[:, 1] >= -4) & (off[:, 1] < 4))
    # Pairs stay apart: any two circles of different pairs are >= 3 squares apart (> 2 within).
    centers = np.array([p.centers_uv for p in pairs])
    for a in range(4):
        for b in range(a + 1, 4):
            d = np.linalg.norm(centers[a][:, None] - centers[b][None], axis=-1)
            assert d.min() >= 3 * chart.square_m - 1e-12


def test_intensity_known_points() -> None:
    chart = VerificationChart()
    s, m = chart.square_m, chart.margin_m
    pts = {
        "black square (0, 0)": ([m + 0.5 * s, m + 0.5 * s], 0.05),
        "white square (0, 1)": ([m + 1.5 * s, m + 0.5 * s], 0.95),
        "margin": ([0.5 * m, 0.3], 0.95),
        "last square (27, 39) black": ([m + 39.5 * s, m + 27.5 * s], 0.05),
    }
    for pair in chart.circle_pairs:
        cu, cv = pair.centers_uv[0]
        inside = 0.05 if pair.polarity == "dark" else 0.95
        pts[f"{pair.name} centre"] = ([cu, cv], inside)
        pts[f"{pair.name} inside edge"] = ([cu + 0.29 * s, cv], inside)
        pts[f"{pair.name} outside edge"] = ([cu + 0.31 * s, cv], 1.0 - inside)
    uv = np.array([p for p, _ in pts.values()])
    np.testing.assert_allclose(chart.intensity(uv), [v for _, v in pts.values()], atol=1e-12)
    off = chart.intensity([[-1e-6, 0.1], [0.1, 0.75 + 1e-6], [np.nan, 0.1], [1.05, 0.75]])
    assert np.isnan(off[:3]).all() and off[3] == 0.95  # the far corner is still paper


def test_intensity_broadcasts_and_checks_shape() -> None:
    chart = VerificationChart()
    uv = np.random.default_rng(0).uniform(0, 0.7, (3, 5, 2))
    out = chart.intensity(uv)
    assert out.shape == (3, 5)
    np.testing.assert_array_equal(out.ravel(), chart.intensity(uv.reshape(-1, 2)))
    # blockwise evaluation (> 65536 points) gives the same values as small calls
    big = np.random.default_rng(1).uniform(-0.01, 1.06, (70_000, 2))
    np.testing.assert_array_equal(chart.intensity(big)[-100:], chart.intensity(big[-100:]))
    with pytest.raises(ShapeError):
        chart.intensity(np.zeros((4, 3)))


def test_area_fraction_of_black_matches_layout() -> None:
    # Monte Carlo over the board area: half black, plus dark circles minus light circles
    # (equal counts, so they cancel): black fraction 0.5 within 3 sigma of 200k samples.
    chart = VerificationChart()
    rng = np.random.default_rng(2)
    uv = chart.margin_m + rng.uniform(0, 1, (200_000, 2)) * [1.0, 0.7]
    frac = np.mean(chart.intensity(uv) == 0.05)
    assert abs(frac - 0.5) < 3 * np.sqrt(0.25 / 200_000)


def test_keypoints() -> None:
    kp = VerificationChart().keypoints()
    assert set(kp) == {"corners", "circles"}
    assert len(kp["corners"]) == 1053 and kp["circles"].ids.shape == (8, 2)
    assert not kp["corners"].uv.flags.writeable


def test_chessboard_matches_opencv_pattern() -> None:
    board = Chessboard((9, 6), square_m=0.03, margin_m=0.0)
    assert board.squares == (10, 7)
    obj = board.object_points()
    assert obj.shape == (54, 3)
    # OpenCV's object points: objp[i * cols + j] = (j * s, i * s, 0)
    j, i = np.meshgrid(np.arange(9), np.arange(6))
    expected = np.stack([j.ravel() * 0.03, i.ravel() * 0.03, np.zeros(54)], axis=1)
    np.testing.assert_allclose(obj, expected, atol=1e-12)
    assert board.intensity([0.015, 0.015]) == 0.05 and board.intensity([0.045, 0.015]) == 0.95


def test_bad_parameters_raise() -> None:
    with pytest.raises(InputError, match="10 × 8"):
        VerificationChart(squares=(8, 6))
    with pytest.raises(InputError, match="square_m"):
        VerificationChart(square_m=-0.01)
    with pytest.raises(InputError, match="reflectance"):
        Chessboard(black=1.5)


def test_odd_centre_keeps_polarity() -> None:
    chart = VerificationChart(squares=(41, 29))  # centre square (14, 20) white -> shifted left
    for p in chart.circle_pairs:
        assert np.all((p.square_ids.sum(axis=1) % 2 == 1) == (p.polarity == "dark"))
        for cu, cv in p.centers_uv:
            expect = 0.05 if p.polarity == "dark" else 0.95
            assert chart.intensity([cu, cv]) == expect
