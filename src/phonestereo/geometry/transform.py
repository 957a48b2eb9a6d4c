"""Rigid transforms named ``T_a_b`` (maps frame b into frame a; DESIGN §5, thesis eq. 3).

``p_a = T_a_b.apply(p_b) = R · p_b + t`` and ``T_a_c = T_a_b @ T_b_c``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from phonestereo.errors import InputError
from phonestereo.geometry._checks import Array, as_matrix, as_points, frozen


@dataclass(frozen=True, eq=False)
class Transform:
    """A rigid transform: rotation R (3, 3) and translation t (3,) in metres.

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
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
            raise InputError("R must be a rotation matrix (orthonormal, det = +1)")
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
