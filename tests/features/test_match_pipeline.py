"""match_rectified end to end on exact synthetic shifts: values, ROI, stages, typed errors."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.errors import InputError, ShapeError
from phonestereo.features.match_filters import histogram_filter, row_error_filter
from phonestereo.features.matching import MatchConfig, MatchResult, match_rectified

H, W = 180, 260


def pair(d: float, e: float, seed: int = 0, noise: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    spec = np.fft.fft2(rng.standard_normal((H, W)))
    fy, fx = np.fft.fftfreq(H)[:, None], np.fft.fftfreq(W)[None, :]
    spec *= np.exp(-2 * np.pi**2 * 1.3**2 * (fx**2 + fy**2))
    spec *= 40 / np.real(np.fft.ifft2(spec)).std()
    left = 128 + np.real(np.fft.ifft2(spec))
    right = 128 + np.real(np.fft.ifft2(spec * np.exp(2j * np.pi * (fx * d + fy * e))))
    left += noise * rng.standard_normal(left.shape)
    right += noise * rng.standard_normal(left.shape)
    return left, right


def test_recovers_disparity_and_row_error() -> None:
    left, right = pair(17.6, -0.4, noise=1.0)
    res = match_rectified(left, right, max_disparity=32)
    assert len(res) > 200
    # noise 1 DN: σ_d ≈ 0.01 px per match
    assert abs(np.median(res.d) - 17.6) < 0.005
    assert abs(np.median(res.e) + 0.4) < 0.005
    assert np.all(res.sigma_d > 0) and np.median(res.sigma_d) < 0.03
    z = np.abs(res.d - 17.6) / res.sigma_d
    assert 0.58 <= np.mean(z <= 1) <= 0.78  # honest: 68 % ± 10 %
    counts = list(res.counts.values())
    assert counts == sorted(counts, reverse=True)  # every stage only removes
    assert res.counts["matches"] == len(res)
    assert res.reason == ""


def test_negative_disparity_range_and_integer_keypoints() -> None:
    left, right = pair(-5.3, 0.0)
    res = match_rectified(left, right, min_disparity=-12, max_disparity=0)
    assert len(res) > 100 and abs(np.median(res.d) + 5.3) < 0.005
    assert np.array_equal(res.xy, np.rint(res.xy))


def test_roi_limits_the_keypoints() -> None:
    left, right = pair(10.0, 0.0)
    roi = (60, 40, 120, 80)
    res = match_rectified(left, right, max_disparity=20, roi=roi)
    assert len(res) > 20
    x, y = res.xy[:, 0], res.xy[:, 1]
    assert x.min() >= 60 and x.max() < 180 and y.min() >= 40 and y.max() < 120
    assert res.roi == roi
    full = match_rectified(left, right, max_disparity=20)
    inside = (full.xy[:, 0] >= 60) & (full.xy[:, 0] < 180)
    inside &= (full.xy[:, 1] >= 40) & (full.xy[:, 1] < 120)
    # the ROI result is the full result restricted to the ROI (same crop-independent maths)
    assert abs(len(res) - inside.sum()) <= 0.1 * inside.sum()


def test_sift_detector_and_dict() -> None:
    left, right = pair(8.2, 0.1)
    res = match_rectified(left, right, max_disparity=16, config=MatchConfig(detector="sift"))
    assert len(res) > 30 and abs(np.median(res.d) - 8.2) < 0.01
    out = res.to_dict()
    assert set(out) >= {"matches", "seconds", "counts"}
    assert set(out["matches"][0]) >= {"x", "y", "d", "e", "sigma_d"}


def test_color_and_uint8_inputs() -> None:
    left, right = pair(6.0, 0.0)
    lc = np.repeat(np.clip(left, 0, 255).astype(np.uint8)[..., None], 3, axis=2)
    rc = np.repeat(np.clip(right, 0, 255).astype(np.uint8)[..., None], 3, axis=2)
    res = match_rectified(lc, rc, max_disparity=12)
    assert len(res) > 100 and abs(np.median(res.d) - 6.0) < 0.02


def test_no_texture_is_a_result_with_a_reason() -> None:
    flat = np.full((100, 120), 90.0)
    res = match_rectified(flat, flat, max_disparity=10)
    assert isinstance(res, MatchResult) and len(res) == 0
    assert "no keypoints" in res.reason
    assert res.to_dict()["matches"] == []


@pytest.mark.parametrize(
    ("kwargs", "error", "match"),
    [
        ({"roi": (250, 10, 50, 50)}, InputError, "not inside"),
        ({"roi": (-1, 0, 10, 10)}, InputError, "not inside"),
        ({"roi": (0, 0, 0, 10)}, InputError, "width and height"),
        ({"roi": "a,b"}, InputError, "x,y,w,h"),
        ({"max_disparity": 0}, InputError, "max_disparity > min_disparity"),
        ({"max_disparity": 4.5}, InputError, "integers"),
    ],
)
def test_bad_arguments_raise_typed_errors(kwargs: dict, error: type, match: str) -> None:
    left, right = pair(5.0, 0.0)
    args = {"max_disparity": 10, **kwargs}
    with pytest.raises(error, match=match):
        match_rectified(left, right, **args)


@pytest.mark.parametrize(
    ("left", "right", "error", "match"),
    [
        (None, np.zeros((50, 50)), InputError, "missing"),
        (np.zeros((0, 0)), np.zeros((50, 50)), InputError, "empty"),
        (np.zeros((50, 50)), np.zeros((50, 60)), ShapeError, "differ in size"),
        (np.zeros((50, 50, 2)), np.zeros((50, 50, 2)), ShapeError, "gray"),
        (np.full((50, 50), np.nan), np.zeros((50, 50)), InputError, "NaN"),
        (np.zeros((12, 12)), np.zeros((12, 12)), InputError, "too small"),
        (np.array([["a"]]), np.array([["a"]]), InputError, "real numbers"),
    ],
)
def test_bad_images_raise_typed_errors(left, right, error: type, match: str) -> None:
    with pytest.raises(error, match=match):
        match_rectified(left, right, max_disparity=10)


def test_config_is_validated() -> None:
    with pytest.raises(InputError, match="detector"):
        MatchConfig(detector="orb")
    with pytest.raises(InputError, match="radius"):
        MatchConfig(radius=1)


def test_global_filters() -> None:
    xy = np.stack([np.linspace(0, 500, 50), np.linspace(0, 300, 50)], 1)
    e = 0.2 + 0.0005 * xy[:, 0]
    e[[3, 30]] += [1.5, -2.0]
    keep = row_error_filter(xy, e)
    assert keep.sum() == 48 and not keep[3] and not keep[30]
    d = np.r_[np.linspace(10, 20, 40), 45.0]
    assert histogram_filter(d).tolist() == [True] * 40 + [False]
