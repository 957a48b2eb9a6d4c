"""The result of verification-chart detection: labelled corners, or the reason there are none.

Made by :func:`phonestereo.features.verification.detect_verification_chart` (which re-exports
it); kept apart so the detector module holds only the detection stages.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.features._image import F64


@dataclass(frozen=True, eq=False)
class ChartDetection:
    """Labelled corners of a verification chart, or the reason there are none."""

    found: bool
    #: Empty when found (or a note on dropped corners); otherwise what went wrong.
    reason: str
    #: ndarray of int, shape (N, 2). Chart (row, col) of each corner
    #: (:meth:`VerificationChart.corner_ids` convention).
    ids: NDArray[np.int64]
    #: ndarray, shape (N, 2). Sub-pixel corner positions (x, y), pixels of the full image.
    points: F64
    #: ndarray, shape (N,). Saddle strength √(−det H) of the refined corner, intensity units per px²
    #: (higher is sharper; compare corners of one image).
    quality: F64
    #: tuple of str. Names of the circle pairs whose two circles were seen in the lattice.
    pairs_found: tuple[str, ...] = ()
    #: In-image angle of the chart's rows (+u axis), degrees from +x towards +y: the angle of the
    #: sum of the vectors from each corner to its right neighbour (NaN if not found).
    rotation_deg: float = float("nan")
    #: dict. Counts per stage (circle candidates, pairs, Harris candidates, lattice nodes, squares,
    #: dropped corners, pyramid levels).
    stages: dict[str, Any] = field(default_factory=dict)
    #: dict. Wall time per stage.
    seconds: dict[str, float] = field(default_factory=dict)
    #: dict of str to ndarray, shape (2, 2). Pixel centres (x, y) of the circles of each pair found,
    #: in the order of :attr:`CirclePair.centers_uv` (the squares' centres, from the labelled
    #: lattice).
    circles: dict[str, F64] = field(default_factory=dict)
    #: ndarray, shape (N,). Distance of each corner from the quadratic fitted to its 5 × 5
    #: neighbourhood, pixels (noise level ~0.01–0.05 px; corners above 0.15 px are dropped); NaN
    #: where the neighbourhood is too small (chart border, image edge).
    residual_px: F64 = field(default_factory=lambda: np.zeros(0))
    #: ndarray, shape (N,). Predicted position σ per coordinate from the image noise, pixels
    #: (``features.saddle.position_covariance``).
    sigma_px: F64 = field(default_factory=lambda: np.zeros(0))

    def to_dict(self) -> dict[str, Any]:
        """JSON-friendly summary with every corner (row, col, x, y, quality, residual_px,
        sigma_px)."""
        nan = np.full(len(self.ids), np.nan)
        res = self.residual_px if len(self.residual_px) else nan
        sig = self.sigma_px if len(self.sigma_px) else nan
        corners = [
            {
                "row": int(r),
                "col": int(c),
                "x": float(x),
                "y": float(y),
                "quality": float(q),
                "residual_px": round(float(e), 4) if np.isfinite(e) else None,
                "sigma_px": round(float(sd), 5) if np.isfinite(sd) else None,
            }
            for (r, c), (x, y), q, e, sd in zip(
                self.ids, self.points, self.quality, res, sig, strict=True
            )
        ]
        rot = None if not np.isfinite(self.rotation_deg) else round(self.rotation_deg, 3)
        return {
            "found": self.found,
            "reason": self.reason,
            "n_corners": len(corners),
            "pairs_found": list(self.pairs_found),
            "circles": {k: np.round(v, 3).tolist() for k, v in self.circles.items()},
            "rotation_deg": rot,
            "stages": self.stages,
            "seconds": {k: round(v, 4) for k, v in self.seconds.items()},
            "corners": corners,
        }


def failed_detection(
    reason: str, stages: dict[str, Any], seconds: dict[str, float]
) -> ChartDetection:
    """A ``found=False`` detection with its reason, stage counts and timings."""
    return ChartDetection(
        False,
        reason,
        np.zeros((0, 2), np.int64),
        np.zeros((0, 2)),
        np.zeros(0),
        (),
        float("nan"),
        stages,
        seconds,
    )
