"""What the within-σ band of the module bench can reach (issue #18; docs/module-random.md,
session 14).

A set's errors are its common offset c_i ~ N(0, c²), shared by its captures, plus per-capture
scatter N(0, s²). With an honest σ = √(c² + s²), the fraction of sets whose within-σ lands in
the band (:data:`~phonestereo.evaluation.module_bench.WITHIN_SIGMA`) depends only on c/s: the
band asks for a small common mode, not for a different σ.

Examples
--------
>>> round(band_fraction(0.0, sets=20_000), 2)     # no common mode: ~68 % within, 96 % in band
0.96
"""

from __future__ import annotations

import numpy as np

from phonestereo.evaluation.module_bench import WITHIN_SIGMA


def band_fraction(
    ratio: float, k: float = 1.0, *, sets: int = 200_000, captures: int = 18, seed: int = 0
) -> float:
    """Fraction of simulated sets whose within-σ lies in the band.

    Parameters
    ----------
    ratio : float
        c/s, the common offset's σ over the per-capture scatter's.
    k : float
        σ scaled by this (1: honest).
    sets, captures : int
        Simulated sets, and captures per set (the bench's 18).
    seed : int
        Of the normal draws.
    """
    rng = np.random.default_rng(seed)
    e = ratio * rng.standard_normal((sets, 1)) + rng.standard_normal((sets, captures))
    w = (np.abs(e) <= k * np.hypot(ratio, 1.0)).mean(axis=1)
    return float(((w >= WITHIN_SIGMA[0]) & (w <= WITHIN_SIGMA[1])).mean())


__all__ = ["band_fraction"]
