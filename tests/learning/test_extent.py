"""The learned correction's systematic and extrapolation σ (issue 18, item 4)."""

from __future__ import annotations

import numpy as np

from phonestereo.flows.config import FlowConfig
from phonestereo.flows.corrector import Corrector
from phonestereo.learning.extent import FOCAL_REL_SIGMA, LearnedExtent, distance_layers
from phonestereo.learning.observation import Observation


def _faces(distances_m: tuple[float, ...], seed: int = 0, gain: float = -0.05) -> list:
    """Face observations at the given distances (f·B = 18 px·m), 8 faces per capture, a true
    correction c = 0.3 + gain·d, 0.02 px noise, and each capture's own 0.3 % scale error."""
    rng = np.random.default_rng(seed)
    out = []
    for g, z in enumerate(np.repeat(distances_m, 3)):
        scale = 1 + rng.normal(0, 0.003)
        for _ in range(8):
            d_true = 18 / z * rng.uniform(0.97, 1.03)
            x, y = rng.uniform(200, 1800), rng.uniform(200, 1300)
            c = 0.3 + gain * d_true
            out.append(Observation(x, y, d_true - c, d_true * scale + rng.normal(0, 0.02),
                                   z, "landscape", "", 300.0, None, f"c{g}"))
    return out


def test_one_distance_leaves_the_gain_unknown_and_the_far_capture_unbounded() -> None:
    ext = LearnedExtent.from_observations(_faces((1.5,)))
    assert not np.isfinite(ext.gain_sigma)  # one distance: no slope over disparity
    sys_px, extra = ext.extra_sigma_px([[1000.0, 750.0, 12.0], [1000.0, 750.0, 4.5]])
    assert extra[0] == 0.0 and not np.isfinite(extra[1])
    # the systematic part is at least the focal prior: ρ ≥ 0.25 % of the disparity
    assert sys_px[0] >= FOCAL_REL_SIGMA * 12.0


def test_thin_store_is_gated_beyond_what_it_learned_and_honest_within() -> None:
    """Faces at 1.5 m only: a chart at 4 m must not get a confident number."""
    corr = Corrector(_faces((1.5,)), FlowConfig())
    c, parts = corr.correct_parts([[1000.0, 750.0, 4.5], [1000.0, 750.0, 12.0]], "landscape")
    assert not np.isfinite(c.sigma_px[0])  # far outside: unbounded (the application gates it)
    # within the learned disparities: the offset-only field is right to its σ (3σ)
    truth = 0.3 - 0.05 * (12.0 + 0.3) / 1.05  # d_measured = 1.05·d_true − 0.3
    assert abs(c.value_px[1] - truth) <= 3 * c.sigma_px[1]
    assert set(parts) == {"fit", "capture", "systematic", "extrapolation"}


def test_three_distances_bound_the_extrapolation() -> None:
    """Faces at 1–3 m: a query at 4 m (d = 4.5 px, below the learned 6–18 px) gets a finite
    extra σ that grows with the distance outside the range; the value is right within it."""
    corr = Corrector(_faces((1.0, 2.0, 3.0)), FlowConfig())
    ext = corr.extents["landscape"]
    assert np.isfinite(ext.gain_sigma)
    c, parts = corr.correct_parts([[1000.0, 750.0, 4.5], [1000.0, 750.0, 2.0]], "landscape")
    assert 0 < parts["extrapolation"][0] < parts["extrapolation"][1]
    truth = 0.3 - 0.05 * (4.5 + 0.3) / 1.05  # d_measured = 1.05·d_true − 0.3
    # within 2σ of the true correction
    assert abs(c.value_px[0] - truth) <= 2 * c.sigma_px[0]


def test_the_drift_gain_sigma_applies_about_the_learned_centre() -> None:
    """σ_g,drift·|d − d̄| at every disparity, inside the learned range too; 0 at d̄."""
    obs = _faces((1.0, 2.0, 3.0))
    ext = LearnedExtent.from_observations(obs, drift_gain_sigma=0.01)
    c = ext.d_centre_px
    assert ext.d_lo_px < c < ext.d_hi_px
    _, extra = ext.extra_sigma_px([[1000.0, 750.0, c], [1000.0, 750.0, c + 3.0],
                                   [1000.0, 750.0, ext.d_hi_px + 1.0]])
    assert extra[0] == 0.0 and np.isclose(extra[1], 0.03)
    assert extra[2] >= 0.01 * (ext.d_hi_px + 1.0 - c)  # the larger of the two gain readings
    assert np.isnan(LearnedExtent.from_observations(obs).drift_gain_sigma)


def test_the_capture_scatter_leaves_out_the_faces_own_noise() -> None:
    """12 captures of 8 faces with 0.05 px of noise each: their means scatter by ~0.018 px
    though no capture is offset; a new capture's own offset is what is left (≤ 0.01 px). With
    true capture offsets of 0.04 px it reads 0.02-0.07 px (robust spread of 12 means)."""
    rng = np.random.default_rng(3)

    def faces(offset_sd: float) -> list:
        out = []
        for g in range(12):
            z = (1.0, 2.0, 3.0)[g % 3]
            off = rng.normal(0, offset_sd)
            for _ in range(8):
                d = 18 / z * rng.uniform(0.97, 1.03)
                out.append(Observation(rng.uniform(200, 1800), rng.uniform(200, 1300),
                                       d - 0.3 - off + rng.normal(0, 0.05), d, z, "landscape",
                                       "", 300.0, None, f"c{g}"))
        return out

    assert Corrector(faces(0.0), FlowConfig()).capture_sigma_px <= 0.01
    assert 0.02 <= Corrector(faces(0.04), FlowConfig()).capture_sigma_px <= 0.07


def test_the_capture_scatter_leaves_out_the_noise_of_captures_with_two_or_three_faces() -> None:
    """15 captures of 2-3 faces (as the bench's face captures hold) with 0.05 px of noise each and
    no capture offset, 40 draws. The scatter is a difference of two noisy variances whose truth is
    0, so an unbiased one reads 0 about half the time. The plain median of the captures' sample
    variances (1-2 degrees of freedom) reads ~0.6 of the noise variance and left the rest as a
    false offset: zero in 45 % of the draws, 0.0122 px on average. Referred to its χ² median per
    dof: zero in 70 %, 0.0070 px (other seeds: 50-75 %, 0.005-0.012 px; before 25-45 %,
    0.012-0.017 px)."""
    rng = np.random.default_rng(5)

    def draw() -> float:
        out = []
        for g in range(15):
            z = (1.0, 2.0, 3.0)[g % 3]
            for _ in range(int(rng.integers(2, 4))):
                d = 18 / z * rng.uniform(0.97, 1.03)
                out.append(Observation(rng.uniform(200, 1800), rng.uniform(200, 1300),
                                       d - 0.3 + rng.normal(0, 0.05), d, z, "landscape",
                                       "", 300.0, None, f"c{g}"))
        return Corrector(out, FlowConfig()).capture_sigma_px

    v = np.array([draw() for _ in range(40)])
    assert np.mean(v == 0.0) >= 0.5 and np.mean(v) <= 0.01, (np.mean(v == 0.0), np.mean(v))


def test_the_common_scale_averages_over_distance_layers_not_captures() -> None:
    """ρ is the captures' relative spread over √(distance layers) ⊕ the focal prior: captures at
    one distance share its focus and faces, layers do not (over the 29 bench sets the sets'
    mean errors read 0.71 of ρ in rms without the division, 1.08 with it; session 16)."""
    one = LearnedExtent.from_observations(_faces((1.5,)))
    three = LearnedExtent.from_observations(_faces((1.0, 2.0, 3.0)))
    assert (one.n_layers, three.n_layers) == (1, 3)
    for ext in (one, three):
        assert np.isclose(ext.rho, np.hypot(ext.rho_captures / np.sqrt(ext.n_layers),
                                            FOCAL_REL_SIGMA))
    # a continuous spread of distances is one chain, not many layers (ρ stays conservative)
    assert distance_layers(18 / np.linspace(1.0, 3.0, 15)) == 1
