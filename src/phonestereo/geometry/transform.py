"""Rigid transforms named ``T_a_b`` (maps frame b into frame a; docs/conventions.md, thesis eq. 3).

``p_a = T_a_b.apply(p_b) = R · p_b + t`` and ``T_a_c = T_a_b @ T_b_c``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from phonestereo.errors import InputError
from phonestereo.geometry._checks import Array, as_matrix, as_points, frozen

ORTHONORMAL_TOLERANCE = 1e-6
"""Largest max |R·Rᵀ − I| accepted: real files print R with 6–9 significant digits."""

SNAP_TOLERANCE = 1e-12
"""An R further than this from orthonormal (but within ORTHONORMAL_TOLERANCE) is snapped."""


def orthonormality_error(r: Array) -> float:
    """max |R·Rᵀ − I| of a 3×3 matrix (0 for an exact rotation).

    >>> orthonormality_error(np.eye(3))
    0.0
    """
    m = np.asarray(r, dtype=np.float64)
    return float(np.abs(m @ m.T - np.eye(3)).max())


def nearest_rotation(r: Array) -> Array:
    """The rotation closest to ``r`` in the Frobenius norm (SVD: U·Vᵀ, det forced to +1).

    >>> r = np.round(Rotation.from_rotvec([0.01, 0.02, 0.3]).as_matrix(), 6)
    >>> orthonormality_error(r) > 1e-8, orthonormality_error(nearest_rotation(r)) < 1e-14
    (True, True)
    """
    u, _, vt = np.linalg.svd(np.asarray(r, dtype=np.float64))
    d = np.sign(np.linalg.det(u @ vt))
    return np.asarray(u @ np.diag([1.0, 1.0, d]) @ vt, dtype=np.float64)


@dataclass(frozen=True, eq=False)
class Transform:
    """A rigid transform: rotation R (3, 3) and translation t (3,) in metres.

    An R orthonormal to within :data:`ORTHONORMAL_TOLERANCE` (a file's 6–9 printed digits) is
    replaced by the nearest rotation (:func:`nearest_rotation`); a larger deviation is an error.

    Examples
    --------
    >>> T_tele_wide = Transform.from_rotvec([0, 0, 0], [-0.012, 0, 0])
    >>> T_tele_wide.apply([0.0, 0.0, 2.0]).tolist()
    [-0.012, 0.0, 2.0]
    """

    R: Array
    t: Array

    def __post_init__(self) -> None:
        r = as_matrix(self.R, (3, 3), "R")
        t = as_matrix(np.ravel(np.asarray(self.t, dtype=float)), (3,), "t")
        dev = orthonormality_error(r)
        if not dev <= ORTHONORMAL_TOLERANCE or np.linalg.det(r) < 0:
            raise InputError(
                f"R must be a rotation matrix (orthonormal to {ORTHONORMAL_TOLERANCE:g}, "
                f"det = +1); max |R·Rᵀ − I| is {dev:.2g} and det {np.linalg.det(r):.6g}: "
                "check that R was written with at least 6 significant digits"
            )
        if dev > SNAP_TOLERANCE:  # printed with 6–9 digits (OpenCV, Kalibr, phones): snap
            r = nearest_rotation(r)
        object.__setattr__(self, "R", frozen(r))
        object.__setattr__(self, "t", frozen(t))

    @classmethod
    def identity(cls) -> Transform:
        """The identity transform."""
        return cls(np.eye(3), np.zeros(3))

    @classmethod
    def from_rotvec(cls, rotvec: Any, t: Any) -> Transform:
        """From a rotation vector (axis · angle, radians) and a translation in metres."""
        rv = as_points(rotvec, 3, "rotvec").reshape(3)
        return cls(Rotation.from_rotvec(rv).as_matrix(), np.asarray(t, dtype=float))

    @classmethod
    def from_matrix(cls, M: Any) -> Transform:
        """From a 4×4 homogeneous matrix."""
        m = as_matrix(M, (4, 4), "4x4 transform")
        return cls(m[:3, :3], m[:3, 3])

    @property
    def rotvec(self) -> Array:
        """Rotation vector (3,), radians."""
        return np.asarray(Rotation.from_matrix(self.R).as_rotvec(), dtype=np.float64)

    @property
    def matrix(self) -> Array:
        """4×4 homogeneous matrix."""
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = self.R, self.t
        return m

    def apply(self, points: Any) -> Array:
        """Map points (..., 3) from frame b to frame a."""
        p = as_points(points, 3, "points")
        return np.asarray(p @ self.R.T + self.t, dtype=np.float64)

    def inverse(self) -> Transform:
        """``T_b_a`` from ``T_a_b``."""
        return Transform(self.R.T, -self.R.T @ self.t)

    def __matmul__(self, other: Transform) -> Transform:
        return Transform(self.R @ other.R, self.R @ other.t + self.t)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready ``{"R": 3×3 list, "t": 3 list (metres)}``."""
        return {"R": self.R.tolist(), "t": self.t.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Transform:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(np.asarray(data["R"], dtype=float), np.asarray(data["t"], dtype=float))
        except KeyError as exc:
            raise InputError(f"transform entry needs 'R' and 't'; missing {exc}") from exc

    def __repr__(self) -> str:
        rv, t = np.round(self.rotvec, 6).tolist(), np.round(self.t, 6).tolist()
        return f"Transform(rotvec={rv}, t={t})"
