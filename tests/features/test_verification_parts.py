"""The stages of verification-chart detection, each on inputs with a known answer."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from phonestereo.charts.export import raster
from phonestereo.charts.verification import VerificationChart
from phonestereo.features import labels as lb
from phonestereo.features._image import as_gray_float, base_to_level, level_to_base
from phonestereo.features.circles import find_circles
from phonestereo.features.lattice import crossing_check, seed_from_pair
from phonestereo.features.verification import detect_verification_chart

CHART = VerificationChart()
PX_PER_M = 600.0  # 15 px squares, circles of radius 4.5 px


@pytest.fixture(scope="module")
def board() -> np.ndarray:
    return as_gray_float(raster(CHART, PX_PER_M, supersample=4))


def _uv_to_px(uv: np.ndarray) -> np.ndarray:
    return uv * PX_PER_M - 0.5  # raster pixel centres sit at (k + ½) / px_per_m


def test_pyramid_coordinates_round_trip() -> None:
    p = np.array([[3.25, 7.5]])
    assert np.allclose(base_to_level(level_to_base(p, 3), 3), p)


def test_finds_the_four_pairs_with_their_centres(board: np.ndarray) -> None:
    c = find_circles(board, 0, 0.5)
    assert len(c.pairs) == 4
    truth = _uv_to_px(np.concatenate([p.centers_uv for p in CHART.circle_pairs]))
    found = c.centers[c.pairs.ravel()]
    d = np.linalg.norm(found[:, None] - truth[None], axis=2).min(axis=1)
    assert d.max() < 0.05  # centroids of anti-aliased discs
    assert np.allclose(c.radius[c.pairs.ravel()], 0.3 * 15.0, rtol=0.05)


def test_seed_from_a_pair_predicts_the_squares_around_it(board: np.ndarray) -> None:
    p = CHART.circle_pairs[0]  # h_dark: two columns apart
    c1, c2 = _uv_to_px(p.centers_uv)
    cov = np.eye(2) * (0.3 * 15.0) ** 2 / 4
    _, e2, seed = seed_from_pair(c1, c2, cov)
    r, c = p.square_ids[0]
    corners = _uv_to_px(CHART.corners_uv()).reshape(-1, CHART.pattern[0], 2)
    # lattice node (i, j) = chart corner (r + i, c + j) for this unrotated view
    assert np.allclose(seed, corners[r - 2 : r + 2, c - 2 : c + 4], atol=1e-9)
    assert np.allclose(e2, [0.0, 15.0])


def test_crossing_check_accepts_junctions_and_rejects_points_off_them(board: np.ndarray) -> None:
    corners = _uv_to_px(CHART.corners_uv())
    ids = CHART.corner_ids()
    e1 = np.tile([15.0, 0.0], (len(corners), 1))
    e2 = np.tile([0.0, 15.0], (len(corners), 1))
    tl_dark = ids.sum(axis=1) % 2 == 0  # square (r, c) is black iff r + c is even
    ok, c = crossing_check(board, corners, e1, e2, tl_dark, 0.5)
    assert ok.all() and c.min() > 100
    assert not crossing_check(board, corners, e1, e2, ~tl_dark, 0.5)[0].any()  # wrong parity
    off = corners + np.array([1.2, 0.4])  # 0.08 square off the junction
    assert not crossing_check(board, off, e1, e2, tl_dark, 0.5)[0].any()
    mid = corners + np.array([7.5, 0.0])  # on an edge, half a square away
    assert not crossing_check(board, mid, e1, e2, tl_dark, 0.5, strict=False)[0].any()


def test_colour_input_and_a_dropped_corner_near_an_occluding_blob(board: np.ndarray) -> None:
    img = np.clip(board, 0, 255).astype(np.uint8)
    r, c = 5, 30
    x, y = _uv_to_px(CHART.corners_uv()[r * CHART.pattern[0] + c])
    cv2.circle(img, (round(x + 4), round(y - 4)), 3, 128, -1)  # a grey blob on a corner
    det = detect_verification_chart(cv2.cvtColor(img, cv2.COLOR_GRAY2BGR))
    assert det.found
    kept = {tuple(v) for v in det.ids.tolist()}
    assert (r, c) not in kept and len(kept) >= len(CHART.corner_ids()) - 3


def test_local_residuals_flag_one_displaced_corner() -> None:
    ids = CHART.corner_ids()
    pts = _uv_to_px(CHART.corners_uv())
    pts = pts + 0.01 * np.random.default_rng(0).standard_normal(pts.shape)
    pts[200] += [0.3, 0.0]
    res = lb.local_residuals(ids, pts)
    assert res[200] > 0.25 and np.nanmax(np.delete(res, 200)) < 0.15
    assert np.isnan(res[0])  # a board corner has too few neighbours to judge


def test_hypotheses_need_two_circles_and_a_unique_fit() -> None:
    h = lb.Hypothesis(0, (0, 0), 0, 1)
    e1, e2 = np.array([15.0, 0.0]), np.array([0.0, 15.0])
    assert lb.choose([h], 100, e1, e2, 0.0)[0] is None  # one circle is not enough
    a, b = lb.Hypothesis(0, (0, 0), 0, 2), lb.Hypothesis(2, (5, 5), 1, 2)
    assert lb.choose([a, b], 100, e1, e2, 0.0)[0] == a  # the rival is 180° off the hint
    assert lb.choose([a, b], 100, -e1, -e2, 0.0)[0] is None  # now the best is implausible
    c = lb.Hypothesis(0, (2, 0), 1, 2)
    assert lb.choose([a, c], 100, e1, e2, 0.0)[0] is None  # same rotation, 1 square apart
    assert "contradicts" in lb.choose([lb.Hypothesis(0, (0, 0), 9, 8)], 100, e1, e2, 0.0)[1]
