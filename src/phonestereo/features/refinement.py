"""The result of :func:`~phonestereo.features.subpixel.refine_lk` (one row per window)."""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import NDArray

F32 = NDArray[np.float32]
F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, eq=False)
class Refinement:
    """Result of :func:`refine_lk` for N windows."""

    #: ``d``, ``e``: ndarray, shape (N,). Disparity and non-disparity error at the window centre,
    #: px.
    d: F64
    #: See ``d`` above.
    e: F64
    #: ``gain``, ``offset``: ndarray, shape (N,). Photometric map left ≈ gain · right + offset.
    gain: F64
    #: See ``gain`` above.
    offset: F64
    #: ndarray, shape (N, 2). Disparity gradient (∂d/∂x, ∂d/∂y) over the window, px/px (zeros
    #: without slant).
    slant: F64
    #: ndarray of bool, shape (N,). The (d, e) update fell below ``tol`` within ``max_iter`` steps,
    #: the window stayed in the image, the normal equations were well conditioned and the slant
    #: within bounds.
    converged: NDArray[np.bool_]
    #: ndarray of int, shape (N,)
    iterations: I64
    #: ndarray, shape (N, 2, 2). Covariance of (d, e) per unit residual variance, px²/DN²
    #: (:func:`~phonestereo.features.crlb.weighted_ls_covariance`); NaN where not converged.
    cov_unit: F64
    #: ndarray, shape (N,). A-posteriori residual variance Σ w r² / (Σ w − tr(H⁻¹ JᵀW²J)), DN².
    residual_var: F64
    #: ndarray, shape (N,). Weighted zero-mean NCC of the left window with the warped right window
    #: at the solution.
    zncc: F64
    #: ndarray, shape (N,). Weighted standard deviation of the left window, DN.
    template_std: F64
    #: ndarray, shape (N, 2, M²), float32. Influence images G of d and e: d̂ − d = Σ_p G_d(p)·n(p)
    #: for a small residual n in the window (row-major M × M, M = 2r + 1), so Var d = Σ_pq G_d(p)
    #: C(p − q) G_d(q) for noise of autocorrelation C, and Σ_p G_d(p)² = ``cov_unit[:, 0, 0]``
    #: (white noise); NaN where not converged; None unless ``refine_lk(influence=True)``
    #: (:mod:`.misfit`).
    influence: F32 | None = None
    #: ndarray, shape (N, M²), float32. The residual L − a·R(warp) − b at the solution, DN; NaN
    #: where not converged; None unless ``refine_lk(influence=True)``.
    residual: F32 | None = None

    @classmethod
    def concat(cls, parts: list[Refinement]) -> Refinement:
        """The windows of ``parts`` one after the other (influence/residual kept when every
        part has them)."""
        names = [f.name for f in fields(cls)]
        out: dict[str, Any] = {}
        for name in names:
            vals = [getattr(p, name) for p in parts]
            out[name] = None if any(v is None for v in vals) else np.concatenate(vals)
        return cls(**out)
