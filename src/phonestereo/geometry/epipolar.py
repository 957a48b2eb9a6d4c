"""Epipolar algebra: E, F and the essential-matrix scales of eq. (8)–(9) (thesis §1.1.3, §3.5.4).

Eq. (5) q̃_teleᵀ F q̃_wide = 0;  eq. (6) F = K_tele⁻ᵀ [t]ₓ R K_wide⁻¹;  eq. (7) E = [t]ₓ R.
F acts on *undistorted* pixels (distortion removed, K kept).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.geometry.checks import Array, as_matrix, as_points


def skew(v: Any) -> Array:
    """Cross-product matrix [v]ₓ (3, 3) with [v]ₓ·w = v × w.

    Examples
    --------
    >>> skew([1.0, 0.0, 0.0]) @ np.array([0.0, 1.0, 0.0])
    array([0., 0., 1.])
    """
    x, y, z = as_points(v, 3, "v").reshape(3)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def essential_from_pose(R: Any, t: Any) -> Array:
    """E = [t]ₓ R (eq. 7) for p_tele = R·p_wide + t."""
    return skew(t) @ as_matrix(R, (3, 3), "R")


def fundamental_from_essential(E: Any, K_tele: Any, K_wide: Any) -> Array:
    """F = K_tele⁻ᵀ E K_wide⁻¹ (eq. 6)."""
    e = as_matrix(E, (3, 3), "E")
    kt = as_matrix(K_tele, (3, 3), "K_tele")
    kw = as_matrix(K_wide, (3, 3), "K_wide")
    return np.asarray(np.linalg.inv(kt).T @ e @ np.linalg.inv(kw), dtype=np.float64)


def epipolar_residual(F: Any, q_wide: Any, q_tele: Any) -> Array:
    """Algebraic residual q̃_teleᵀ F q̃_wide (eq. 5) per point pair, shape (...,)."""
    f = as_matrix(F, (3, 3), "F")
    qw = as_points(q_wide, 2, "q_wide")
    qt = as_points(q_tele, 2, "q_tele")
    hw = np.concatenate([qw, np.ones((*qw.shape[:-1], 1))], axis=-1)
    ht = np.concatenate([qt, np.ones((*qt.shape[:-1], 1))], axis=-1)
    return np.asarray(np.einsum("...i,ij,...j->...", ht, f, hw), dtype=np.float64)


@dataclass(frozen=True)
class EssentialScales:
    """Per-camera focal scales recovered from a reference and a current E (eq. 9)."""

    #: ``s_wide``, ``s_tele``: Focal scales of the current state relative to the reference (K′ =
    #: K·D(s)).
    s_wide: float
    #: See ``s_wide`` above.
    s_tele: float
    #: The unknown overall factor of E′ (sign included).
    A: float
    #: Condition number of the weighted log-domain system; ∞ when the entries used cannot separate
    #: the three unknowns (e.g. E₃₃ and the 2×2 block both ≈ 0).
    condition: float
    #: RMS log-domain residual of the fit (0 on exact data).
    residual_rms: float
    #: tuple of (int, int). The (row, col) entries of E used.
    entries: tuple[tuple[int, int], ...]

    @property
    def well_conditioned(self) -> bool:
        """True when the condition number is below 1e3."""
        return bool(np.isfinite(self.condition) and self.condition < 1e3)


def essential_scales(E_ref: Any, E_cur: Any, *, min_relative: float = 1e-3) -> EssentialScales:
    """Recover the per-camera focal scales between two essential matrices (eq. 8–9, §3.5.4).

    With K′ = K·D(s), the E′ computed with the nominal K is ``A · D(s_tele)⁻¹ E D(s_wide)⁻¹``:
    ``E′₃₃ = A E₃₃``, ``E′ᵢ₃ = A Eᵢ₃ / s_tele``, ``E′₃ⱼ = A E₃ⱼ / s_wide`` and
    ``E′ᵢⱼ = A Eᵢⱼ / (s_tele s_wide)`` for i, j ∈ {1, 2}. Taking logs of |E′ / E| over every
    entry with |Eᵢⱼ| ≥ ``min_relative`` · max|E| gives a linear system in (log|A|, log s_tele,
    log s_wide), solved by least squares with each row weighted by |Eᵢⱼ| (relative noise on
    small entries is large). Its condition number is reported: for a near-canonical rig
    (R ≈ I, t ≈ (B, 0, 0)) only the non-baseline components of t make the system solvable.

    Parameters
    ----------
    E_ref, E_cur : array_like, shape (3, 3)
        Reference and current essential matrices (any scale and sign).
    min_relative : float
        Entries smaller than this fraction of the largest are left out.

    Returns
    -------
    EssentialScales

    Examples
    --------
    >>> E = essential_from_pose(np.eye(3), [0.0, 0.012, 0.0015])
    >>> D = lambda s: np.diag([1 / s, 1 / s, 1.0])
    >>> r = essential_scales(E, 3.0 * D(1.05) @ E @ D(0.95))
    >>> round(r.s_tele, 9), round(r.s_wide, 9)
    (1.05, 0.95)
    """
    e0 = as_matrix(E_ref, (3, 3), "E_ref")
    e1 = as_matrix(E_cur, (3, 3), "E_cur")
    e0 = e0 / np.max(np.abs(e0))
    s1 = np.max(np.abs(e1))
    if s1 == 0:
        raise InputError("E_cur is all zeros; estimate it from at least 5 point pairs first")
    e1 = e1 / s1
    rows, rhs, weights, used, signs = [], [], [], [], []
    for i in range(3):
        for j in range(3):
            if abs(e0[i, j]) < min_relative or abs(e1[i, j]) < min_relative:
                continue
            rows.append([1.0, -1.0 if i < 2 else 0.0, -1.0 if j < 2 else 0.0])
            rhs.append(np.log(abs(e1[i, j]) / abs(e0[i, j])))
            weights.append(abs(e0[i, j]))
            used.append((i, j))
            signs.append(np.sign(e1[i, j] * e0[i, j]))
    if len(rows) < 3:
        return EssentialScales(np.nan, np.nan, np.nan, np.inf, np.nan, tuple(used))
    a = np.asarray(rows) * np.asarray(weights)[:, None]
    b = np.asarray(rhs) * np.asarray(weights)
    sv = np.linalg.svd(a, compute_uv=False)
    cond = float(sv[0] / sv[-1]) if sv[-1] > 1e-12 * sv[0] else float("inf")
    if not np.isfinite(cond):
        return EssentialScales(np.nan, np.nan, np.nan, cond, np.nan, tuple(used))
    sol, *_ = np.linalg.lstsq(a, b, rcond=None)
    log_a, log_st, log_sw = sol
    resid = np.asarray(rows) @ sol - np.asarray(rhs)
    sign = float(np.sign(np.sum(np.asarray(signs) * np.asarray(weights)))) or 1.0
    return EssentialScales(
        s_wide=float(np.exp(log_sw)),
        s_tele=float(np.exp(log_st)),
        A=sign * float(np.exp(log_a)) * s1,
        condition=cond,
        residual_rms=float(np.sqrt(np.mean(resid**2))),
        entries=tuple(used),
    )
