"""Textured plane: deterministic, band-limited, in the printable range."""

from __future__ import annotations

import numpy as np
import pytest

from phonestereo.charts import Chart, TexturedPlane
from phonestereo.errors import InputError


def grid(plane: TexturedPlane, step_m: float) -> np.ndarray:
    w, h = plane.size_m
    u, v = np.meshgrid(np.arange(0.0, w, step_m), np.arange(0.0, h, step_m))
    return plane.intensity(np.stack([u, v], axis=-1))


def test_deterministic_per_seed() -> None:
    a = grid(TexturedPlane((0.2, 0.1), seed=7, feature_m=0.005), 0.001)
    b = grid(TexturedPlane((0.2, 0.1), seed=7, feature_m=0.005), 0.001)
    c = grid(TexturedPlane((0.2, 0.1), seed=8, feature_m=0.005), 0.001)
    np.testing.assert_array_equal(a, b)
    assert np.corrcoef(a.ravel(), c.ravel())[0, 1] < 0.1  # independent textures


def test_band_limited_and_in_range() -> None:
    plane = TexturedPlane((0.3, 0.3), seed=1, feature_m=0.01)
    assert isinstance(plane, Chart)
    img = grid(plane, 0.0005)  # 20 samples per feature
    assert 0.05 <= img.min() and img.max() <= 0.95  # printable range
    assert 0.12 < img.std() < 0.25  # contrast ≈ 0.2 (tanh compresses the tails)
    win = np.outer(np.hanning(img.shape[0]), np.hanning(img.shape[1]))  # no edge leakage
    spec = np.abs(np.fft.rfft2((img - img.mean()) * win)) ** 2
    f = np.hypot(*np.meshgrid(np.fft.rfftfreq(img.shape[1]), np.fft.fftfreq(img.shape[0])))
    f_per_m = f / 0.0005
    # Gaussian low-pass σ = feature/4 = 2.5 mm: the power above f is exp(-4π²σ²f²) of the
    # total, 8.5 % above 1/feature (100 /m), 2e-10 above 3/feature; measured 1.4e-5 there
    # (tanh map and spline), so 1e-4 bounds it.
    assert spec[f_per_m > 300].sum() < 1e-4 * spec.sum()
    assert 0.05 < spec[f_per_m > 100].sum() / spec.sum() < 0.12


def test_smooth_between_samples() -> None:
    plane = TexturedPlane((0.1, 0.1), seed=2, feature_m=0.01)
    u = np.linspace(0.02, 0.08, 6001)
    line = plane.intensity(np.stack([u, np.full_like(u, 0.05)], axis=-1))
    # Second differences at 10 µm steps are tiny: a C² texture, no texel kinks.
    assert np.abs(np.diff(line, 2)).max() < 1e-5


def test_outside_nan_and_keypoints() -> None:
    plane = TexturedPlane((0.2, 0.1))
    vals = plane.intensity([[0.1, 0.05], [0.21, 0.05], [0.1, -0.01]])
    assert np.isfinite(vals[0]) and np.isnan(vals[1:]).all()
    kp = plane.keypoints()["corners"]
    assert kp.uv.tolist() == [[0, 0], [0.2, 0], [0.2, 0.1], [0, 0.1]]


def test_bad_parameters() -> None:
    with pytest.raises(InputError, match="feature_m"):
        TexturedPlane(feature_m=0.0)
    with pytest.raises(InputError, match="texels"):
        TexturedPlane((10.0, 10.0), feature_m=0.0001)
