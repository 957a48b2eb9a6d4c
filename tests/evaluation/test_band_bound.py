"""The within-σ band's reach (README #18 row, docs/module-random.md session 14)."""

from __future__ import annotations

from phonestereo.evaluation.band_bound import band_fraction


def test_the_band_needs_a_common_mode_below_the_per_capture_scatter() -> None:
    # 20 000 simulated sets: the fraction's binomial σ is ≤ 0.0035, so ±0.02 is ~6σ.
    # 16 of 20 (80 %) in the band needs c/s ≤ ~0.9 with an honest σ (1.0 gives 77 %) ...
    assert band_fraction(0.9, sets=20_000) >= 0.80 > band_fraction(1.0, sets=20_000) + 0.02
    # ... today's c/s ≈ 1.4 puts ~60 % there (about 12 of 20), whatever one scale of σ.
    assert abs(band_fraction(1.4, sets=20_000) - 0.62) < 0.02
    assert max(band_fraction(1.4, k, sets=20_000) for k in (0.8, 0.9, 1.1)) < 0.70
