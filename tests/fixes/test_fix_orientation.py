"""Orientation buckets and per-bucket disparity offsets (thesis §3.4, fixes/orientation.py)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from phonestereo.errors import InputError, ShapeError
from phonestereo.fixes.orientation import (
    BUCKETS,
    OrientationOffsets,
    capture_bucket,
    orientation_bucket,
)
from phonestereo.sim.effects import orientation_label


@pytest.mark.parametrize(
    ("g", "bucket"),
    [
        ((0, 1, 0), "landscape"),
        ((0, -1, 0), "landscape-flipped"),
        ((1, 0, 0), "portrait"),
        ((-1, 0, 0), "portrait-flipped"),
        ((0, 0, 1), "face-up"),
        ((0, 0, -1), "face-down"),
        ((0.3, 0.9, 0.3), "landscape"),  # tilted 20-ish degrees: still landscape
        ((0.7071, 0.7071, 0.0), "landscape"),  # exact tie: y wins (documented order y, x, z)
        ((0.0, 0.7071, -0.7071), "landscape"),
        ((0.7071, 0.0, 0.7071), "portrait"),  # x before z
        ((0.0, -9.81, 0.5), "landscape-flipped"),  # accelerometer units
    ],
)
def test_bucket_rule(g: tuple[float, float, float], bucket: str) -> None:
    assert orientation_bucket(g) == bucket


def test_bucket_agrees_with_the_simulator_labels() -> None:
    """The sim's two labels (landscape / flipped) are the pipeline's buckets for those poses."""
    for g in ((0.0, 1.0, 0.0), (0.02, -0.999, 0.03), (0.1, 0.99, -0.05)):
        assert orientation_bucket(g) == orientation_label(g)


@settings(max_examples=60, deadline=None)
@given(
    st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).filter(lambda v: max(map(abs, v)) > 1e-3)
)
def test_bucket_is_scale_invariant_and_total(v: tuple[float, float, float]) -> None:
    b = orientation_bucket(v)
    assert b in BUCKETS
    assert orientation_bucket(np.asarray(v) * 9.81) == b


def test_bad_gravity_and_labels() -> None:
    with pytest.raises(ShapeError, match=r"\(3,\)"):
        orientation_bucket([0.0, 1.0])
    with pytest.raises(InputError, match="non-zero"):
        orientation_bucket([0.0, 0.0, 0.0])
    with pytest.raises(InputError, match="non-zero"):
        orientation_bucket([np.nan, 1.0, 0.0])
    assert capture_bucket(None, "portrait") == "portrait"
    assert capture_bucket((0.0, -1.0, 0.0), "landscape") == "landscape-flipped"  # gravity wins
    with pytest.raises(InputError, match="not a bucket"):
        capture_bucket(None, "upside-down")
    with pytest.raises(InputError, match="gravity"):
        capture_bucket(None, None)


def test_offsets_recovered_from_noisy_samples() -> None:
    """Per-bucket offsets from noisy (measured, expected) samples, σ the standard error."""
    rng = np.random.default_rng(3)
    true = {"landscape": 0.0, "landscape-flipped": -0.333, "portrait": 0.12}
    b, dm, de = [], [], []
    for name, off in true.items():
        d_exp = rng.uniform(5, 30, 400)
        b += [name] * 400
        de.append(d_exp)
        dm.append(d_exp + off + rng.normal(0, 0.05, 400))  # 0.05 px matching noise
    fit = OrientationOffsets.fit(b, np.concatenate(dm), np.concatenate(de))
    for name, off in true.items():
        o, s = fit.offset(name)
        # σ = 0.05/√400 = 0.0025 px; 4σ = 0.01 px
        assert abs(o - off) < 0.01 and s == pytest.approx(0.0025, rel=0.15)
    rel = fit.relative("landscape")
    assert rel["landscape-flipped"][0] == pytest.approx(-0.333, abs=0.012)
    assert rel["landscape"] == (0.0, 0.0)
    d = np.array([[10.0, 11.0]])
    np.testing.assert_allclose(fit.correct(d, "portrait"), d - fit.offset("portrait")[0])
    again = OrientationOffsets.from_dict(fit.to_dict())
    assert again.offset("portrait") == fit.offset("portrait")


def test_unknown_bucket_is_a_result_or_a_typed_error() -> None:
    fit = OrientationOffsets.fit(["landscape"] * 2, [9.0, 9.2], [9.0, 9.0])
    got = fit.lookup("landscape-flipped")
    assert not got.found and "landscape-flipped" in got.reason and "landscape" in got.reason
    with pytest.raises(InputError, match="only within its orientation bucket"):
        fit.offset("landscape-flipped")
    with pytest.raises(InputError, match="only within"):
        fit.correct([9.0], "face-up")
    single = OrientationOffsets.fit(["face-up"], [1.0], [0.5])
    assert single.offset("face-up") == (0.5, float("inf"))  # one sample: no σ


def test_fit_input_errors_and_outliers() -> None:
    with pytest.raises(ShapeError, match="one value per sample"):
        OrientationOffsets.fit(["landscape"], [1.0, 2.0], [1.0, 2.0])
    with pytest.raises(InputError, match="unknown bucket"):
        OrientationOffsets.fit(["sideways"], [1.0], [1.0])
    b = ["landscape"] * 6
    dm = [1.0, 1.01, 0.99, 1.0, 1.0, 25.0]  # one gross mismatch
    fit = OrientationOffsets.fit(b, dm, np.zeros(6), max_abs_residual_px=0.5)
    assert fit.offset("landscape")[0] == pytest.approx(1.0, abs=1e-9)
    assert fit.lookup("landscape").n == 5
    nan = OrientationOffsets.fit(b, [np.nan] * 6, np.zeros(6))
    assert nan.buckets == ()
