"""The wide + tele rig: two cameras and T_tele_wide (thesis §1.1.3, eq. 3, 5–7)."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from phonestereo.errors import InputError, PhysicsError
from phonestereo.geometry.camera import Camera
from phonestereo.geometry.checks import Array, as_points
from phonestereo.geometry.epipolar import essential_from_pose, fundamental_from_essential
from phonestereo.geometry.transform import Transform

MIN_BASELINE_M = 1e-5


@dataclass(frozen=True)
class Rig:
    """A wide + tele stereo pair.

    Examples
    --------
    >>> cam = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
    >>> rig = Rig(cam, cam.scaled(3.0), Transform.from_rotvec([0, 0, 0], [0, -0.012, 0]))
    >>> round(rig.baseline_m, 6), rig.zoom
    (0.012, 3.0)
    """

    #: ``wide``, ``tele``: The two cameras.
    wide: Camera
    #: See ``wide`` above.
    tele: Camera
    #: Maps wide-frame points into the tele frame: p_tele = R·p_wide + t (metres).
    T_tele_wide: Transform

    def __post_init__(self) -> None:
        if not isinstance(self.wide, Camera) or not isinstance(self.tele, Camera):
            raise InputError("Rig needs two Camera objects (wide, tele)")
        if not isinstance(self.T_tele_wide, Transform):
            raise InputError("Rig needs T_tele_wide as a Transform")
        if self.baseline_m < MIN_BASELINE_M:
            raise PhysicsError(
                f"rig baseline is {self.baseline_m:.3g} m; a stereo rig needs the two camera "
                "centres apart (check the units of t: metres)"
            )

    @property
    def baseline_m(self) -> float:
        """Distance between the camera centres in metres (|t|)."""
        return float(np.linalg.norm(self.T_tele_wide.t))

    @property
    def tele_center_in_wide(self) -> Array:
        """Tele optical centre in the wide frame, (3,) metres: −Rᵀ t."""
        return np.asarray(-self.T_tele_wide.R.T @ self.T_tele_wide.t, dtype=np.float64)

    @property
    def zoom(self) -> float:
        """f_tele / f_wide."""
        return self.tele.f / self.wide.f

    def essential(self) -> Array:
        """E = [t]ₓ R (eq. 7), for normalised coordinates."""
        return essential_from_pose(self.T_tele_wide.R, self.T_tele_wide.t)

    def fundamental(self) -> Array:
        """F = K_tele⁻ᵀ E K_wide⁻¹ (eq. 6), for undistorted pixels."""
        return fundamental_from_essential(self.essential(), self.tele.K, self.wide.K)

    def project(self, points_wide: Any) -> tuple[Array, Array]:
        """Project wide-frame points (..., 3) into both images → (q_wide, q_tele), (..., 2) each."""
        p = as_points(points_wide, 3, "points_wide")
        return self.wide.project(p), self.tele.project(self.T_tele_wide.apply(p))

    def with_cameras(self, wide: Camera | None = None, tele: Camera | None = None) -> Rig:
        """A copy with one or both cameras replaced."""
        return replace(self, wide=wide or self.wide, tele=tele or self.tele)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict with ``wide``, ``tele`` and ``T_tele_wide``."""
        return {
            "wide": self.wide.to_dict(),
            "tele": self.tele.to_dict(),
            "T_tele_wide": self.T_tele_wide.to_dict(),
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Rig:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(
                Camera.from_dict(data["wide"]),
                Camera.from_dict(data["tele"]),
                Transform.from_dict(data["T_tele_wide"]),
            )
        except KeyError as exc:
            raise InputError(
                f"rig entry needs 'wide', 'tele' and 'T_tele_wide'; missing {exc}"
            ) from exc
