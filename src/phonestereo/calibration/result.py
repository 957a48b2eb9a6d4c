"""What a calibration found and how well (:class:`CalibrationResult`, thesis §1.3.2)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from phonestereo.errors import InputError
from phonestereo.geometry import Camera, Transform


@dataclass(frozen=True, eq=False)
class CalibrationResult:
    """What a calibration found and how well."""

    #: tuple of Camera. One camera (mono) or (wide, tele).
    cameras: tuple[Camera, ...]
    #: Stereo extrinsics (None for mono).
    T_tele_wide: Transform | None
    #: tuple of Transform. ``T_cam0_board`` per view.
    board_poses: tuple[Transform, ...]
    #: tuple of str.
    parameter_names: tuple[str, ...]
    #: ``parameters``, ``covariance``: ndarray, shapes (P,), (P, P). Covariance = σ² (JᵀJ)⁻¹ over
    #: the inliers, σ the fitted per-coordinate noise.
    parameters: np.ndarray
    #: See ``parameters`` above.
    covariance: np.ndarray
    #: ndarray, shape (M, 2). Predicted − observed pixels for every observed point.
    residuals: np.ndarray
    #: ndarray, shape (M, 2). The observed pixels (x, y) themselves, in the same order (for residual
    #: plots).
    image_points: np.ndarray
    #: ``camera_index``, ``view_index``, ``ids``: ndarray, shape (M,)
    camera_index: np.ndarray
    #: See ``camera_index`` above.
    view_index: np.ndarray
    #: See ``camera_index`` above.
    ids: np.ndarray
    #: ndarray of bool, shape (M,)
    inliers: np.ndarray
    #: sqrt(mean |r|²) over the inliers (OpenCV's figure).
    rms_px_per_point: float
    #: sqrt(mean r²) over inlier coordinates (mrcal's figure) = per-point / √2.
    rms_px_per_coordinate: float
    rounds: int
    #: Wall time of the solve, initialisation included.
    seconds: float
    #: ndarray, shape (M,), or None. Each corner's weight σ_ref / σ_view: 1 where its view kept
    #: the pooled σ, None when every corner counted alike (:mod:`.view_weights`).
    weights: np.ndarray | None = None

    @property
    def n_outliers(self) -> int:
        """Number of rejected points."""
        return int(np.count_nonzero(~self.inliers))

    def view_sigma_ratios(self) -> dict[tuple[int, int], float]:
        """σ_view / σ_ref of each (camera, view) that got its own residual σ (:mod:`.view_weights`).

        Views that kept the pooled σ are left out; empty when every corner counted alike. The
        view index is the pair's (stereo) or the found view's (mono) position.
        """
        if self.weights is None:
            return {}
        own = np.flatnonzero(np.abs(self.weights - 1.0) > 1e-9)
        keys = zip(self.camera_index[own].tolist(), self.view_index[own].tolist(), strict=True)
        return {(c, v): float(1.0 / self.weights[i]) for (c, v), i in zip(keys, own, strict=True)}

    @property
    def std(self) -> dict[str, float]:
        """Per-parameter standard deviation from the covariance."""
        sd = np.sqrt(np.clip(np.diag(self.covariance), 0, None))
        return dict(zip(self.parameter_names, sd.tolist(), strict=True))

    def baseline(self) -> tuple[float, float]:
        """|t| of ``T_tele_wide`` and its standard deviation (first-order, from the covariance).

        In the unit of the board's square (metres when ``square_m`` was in metres); σ² = uᵀ C u,
        u = t / |t|, C the 3 × 3 covariance block of (tx, ty, tz).
        """
        if self.T_tele_wide is None:
            raise InputError("a mono calibration has no baseline; calibrate with --tele")
        t = np.asarray(self.T_tele_wide.t, dtype=np.float64)
        idx = [self.parameter_names.index(f"T_tele_wide.t{a}") for a in "xyz"]
        u = t / np.linalg.norm(t)
        var = float(u @ self.covariance[np.ix_(idx, idx)] @ u)
        return float(np.linalg.norm(t)), float(np.sqrt(max(var, 0.0)))

    def rms_per_camera(self) -> tuple[float, ...]:
        """RMS per point of each camera over its inliers."""
        out = []
        for c in range(len(self.cameras)):
            r = self.residuals[(self.camera_index == c) & self.inliers]
            out.append(float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) if len(r) else float("nan"))
        return tuple(out)
