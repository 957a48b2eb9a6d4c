"""Transforms (compose / inverse / apply), typed errors, and eq. (4) disparity ↔ depth."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from phonestereo.errors import InputError, PhysicsError, ShapeError
from phonestereo.geometry import (
    Camera,
    Rig,
    Transform,
    depth_from_disparity,
    disparity_from_depth,
    essential_scales,
    make_lens,
    relative_depth_error,
    skew,
)
from phonestereo.geometry.transform import ORTHONORMAL_TOLERANCE, orthonormality_error

SETTINGS = settings(derandomize=True, max_examples=100, deadline=None, database=None)

_vec = hnp.arrays(np.float64, 3, elements=st.floats(-1.0, 1.0))
transforms = st.builds(
    lambda rv, t: Transform.from_rotvec(rv * 3.0, t * 0.1),  # any rotation up to ~π, ±10 cm
    _vec,
    _vec,
)
points = hnp.arrays(np.float64, (7, 3), elements=st.floats(-5.0, 5.0))


@SETTINGS
@given(a=transforms, b=transforms, c=transforms, p=points)
def test_compose_inverse_apply(a: Transform, b: Transform, c: Transform, p: np.ndarray) -> None:
    # T_a_c = T_a_b @ T_b_c applies right to left; 1e-12 m: a few roundings of 5 m values.
    np.testing.assert_allclose((a @ b).apply(p), a.apply(b.apply(p)), atol=1e-12)
    np.testing.assert_allclose(a.inverse().apply(a.apply(p)), p, atol=1e-12)
    ident = a @ a.inverse()
    np.testing.assert_allclose(ident.R, np.eye(3), atol=1e-14)
    np.testing.assert_allclose(ident.t, 0.0, atol=1e-15)
    np.testing.assert_allclose(((a @ b) @ c).matrix, (a @ (b @ c)).matrix, atol=1e-14)
    np.testing.assert_allclose(
        (a @ b).inverse().matrix, (b.inverse() @ a.inverse()).matrix, atol=1e-14
    )
    back = Transform.from_rotvec(a.rotvec, a.t)
    np.testing.assert_allclose(back.R, a.R, atol=1e-14)
    np.testing.assert_allclose(Transform.from_matrix(a.matrix).R, a.R, atol=0)
    d = Transform.from_dict(a.to_dict())
    assert np.array_equal(d.R, a.R) and np.array_equal(d.t, a.t)


def test_transform_rejects_non_rotations_and_bad_shapes() -> None:
    with pytest.raises(InputError, match="rotation"):
        Transform(np.diag([1.0, 1.0, -1.0]), np.zeros(3))  # a reflection (det = −1)
    with pytest.raises(InputError, match="rotation"):
        Transform(np.eye(3) * 1.01, np.zeros(3))  # not orthonormal
    with pytest.raises(ShapeError):
        Transform(np.eye(2), np.zeros(3))
    with pytest.raises(ShapeError):
        Transform(np.eye(3), np.zeros(2))
    with pytest.raises(ShapeError):
        Transform.identity().apply(np.zeros((4, 2)))
    T = Transform.identity()
    with pytest.raises(ValueError, match="read-only"):
        T.R[0, 0] = 2.0  # getters never leak writable arrays


def test_transform_snaps_rotations_printed_with_few_digits() -> None:
    # ../shared/data/phone_wide_ultra/extrinsics.yml prints R with 8 decimals: orthonormal only
    # to ~6.5e-9, which a real file must still load; the stored R is the nearest rotation.
    r = np.array(
        [
            [0.99997791, 0.00637036, 0.0018983],
            [-0.00638274, 0.99995793, 0.0065878],
            [-0.00185626, -0.00659977, 0.9999765],
        ]
    )
    assert 1e-9 < orthonormality_error(r) < ORTHONORMAL_TOLERANCE
    T = Transform(r, np.zeros(3))
    assert orthonormality_error(T.R) < 1e-14  # float64 rounding of U·Vᵀ
    np.testing.assert_allclose(T.R, r, atol=1e-8)  # moved by less than the printed digits
    with pytest.raises(InputError, match="6 significant digits"):
        Transform(np.round(r, 4), np.zeros(3))  # 4 decimals: ~1e-4 off, not a rotation


def test_typed_errors() -> None:
    cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    for fx in (-1500.0, 0.0, float("nan")):
        with pytest.raises(PhysicsError, match="fx"):
            Camera((2000, 1500), fx, 1500.0, 999.5, 749.5)
    with pytest.raises(PhysicsError, match="fy"):
        Camera.from_matrix((2000, 1500), [[1500, 0, 999.5], [0, -1500, 749.5], [0, 0, 1]])
    with pytest.raises(PhysicsError):
        cam.scaled(0.0)
    with pytest.raises(PhysicsError, match="baseline"):
        Rig(cam, cam.scaled(3.0), Transform.identity())
    with pytest.raises(PhysicsError, match="baseline"):
        Rig(cam, cam, Transform(np.eye(3), [1e-6, 0.0, 0.0]))  # 1 µm: units slip (mm as m?)
    with pytest.raises(ShapeError):
        cam.project(np.zeros((5, 2)))
    with pytest.raises(ShapeError):
        cam.unproject(np.zeros((5, 3)))
    with pytest.raises(ShapeError):
        essential_scales(np.eye(3), np.eye(2))
    with pytest.raises(ShapeError):
        skew([1.0, 2.0])
    with pytest.raises(InputError, match="unknown lens model 'fisheye'"):
        make_lens("fisheye")
    with pytest.raises(InputError, match="5 coefficients"):
        make_lens("opencv5", [0.1, 0.2])
    with pytest.raises(InputError):
        Camera((2000, 0), 1500.0, 1500.0, 999.5, 749.5)
    with pytest.raises(PhysicsError):
        depth_from_disparity(9.0, 1500.0, 0.0)
    # Every typed error is also a ValueError (catchable by generic callers).
    assert issubclass(PhysicsError, ValueError) and issubclass(ShapeError, ValueError)


@SETTINGS
@given(
    z=hnp.arrays(np.float64, 20, elements=st.floats(0.1, 100.0)),
    f=st.floats(500.0, 6000.0),
    b=st.floats(0.005, 0.05),
)
def test_disparity_depth_round_trip(z: np.ndarray, f: float, b: float) -> None:
    d = disparity_from_depth(z, f, b)
    np.testing.assert_allclose(depth_from_disparity(d, f, b), z, rtol=1e-14)
    assert np.all(d > 0)


def test_disparity_depth_conventions_and_sensitivity() -> None:
    # Non-positive disparity or depth: no point in front → NaN, never a negative depth.
    assert np.isnan(depth_from_disparity([0.0, -1.0], 1500.0, 0.012)).all()
    assert np.isnan(disparity_from_depth([0.0, -2.0], 1500.0, 0.012)).all()
    # docs/equations.md: f = 1500 px, B = 12 mm, Z = 2 m, δd = 0.1 px → δZ/Z = 1.1 %.
    assert float(relative_depth_error(2.0, 1500.0, 0.012, 0.1)) == pytest.approx(0.0111, abs=1e-4)
    # It is the first-order term of the exact change of eq. (4) under a 0.1 px disparity error.
    d = float(disparity_from_depth(2.0, 1500.0, 0.012))
    exact = 2.0 / float(depth_from_disparity(d - 0.1, 1500.0, 0.012)) - 1.0
    assert abs(exact) == pytest.approx(0.0111, rel=0.02)
    # A 3 px disparity bias at 2 m is already the ~30 % naive error of docs/index.md (first order).
    assert float(relative_depth_error(2.0, 1500.0, 0.012, 3.0)) == pytest.approx(0.333, abs=1e-3)
