"""Population mode: the learned depth-scale correction converges as eq. 10 predicts.

Simulated faces with IPDs drawn from the §3.6 prior (half men 65 ± 3.6 mm, half women
60 ± 3.5 mm) are measured by a stereo module whose depths are 8 % short, with 1 % landmark
noise on each pixel IPD. After n faces the correction is ``population_scale`` of the first n;
over many independent runs its (1 − α) error quantile must stay under the Chebyshev bound
(eq. 10, any distribution) and follow the normal bound z σ / (μ √n).

Run this file as a script to draw the figure: ``python tests/learning/test_ipd_population.py
OUT.png``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from phonestereo.learning.ipd import IpdPrior, error_bound, population_scale, samples_needed

PRIOR = IpdPrior.population()
ALPHA = 0.05
TRUE_SCALE = 1.08  # true depth = 1.08 × stereo depth
NOISE_REL = 0.01  # landmark noise on each face's pixel IPD


def simulate(trials: int = 2000, faces: int = 1000, seed: int = 6) -> tuple[np.ndarray, np.ndarray]:
    """n = 1..faces and the relative error |k̂_n / k − 1| per trial (trials, faces)."""
    rng = np.random.default_rng(seed)
    ipd = PRIOR.sample(trials * faces, rng).reshape(trials, faces)
    measured = ipd * (1 + NOISE_REL * rng.standard_normal(ipd.shape)) / TRUE_SCALE
    n = np.arange(1, faces + 1)
    running_mean = np.cumsum(measured, axis=1) / n  # population_scale of the first n, vectorised
    scale = PRIOR.mean_m / running_mean
    # spot-check the vectorised form against the library on one trial
    assert np.isclose(population_scale(measured[0, :37], PRIOR).scale, scale[0, 36])
    return n, np.abs(scale / TRUE_SCALE - 1)


def test_correction_converges_within_eq10_bounds() -> None:
    n, err = simulate(trials=1000, faces=400)
    q = np.quantile(err, 1 - ALPHA, axis=0)
    sigma_rel = PRIOR.sd_m / PRIOR.mean_m  # 6.9 % of IPD
    cheb = error_bound(n, sigma_rel, ALPHA, "chebyshev")
    normal = error_bound(n, sigma_rel, ALPHA, "normal")
    # Chebyshev holds for every n (it is a bound for any distribution; here 2.3× loose).
    assert (q <= cheb).all()
    # The normal bound is the actual behaviour: the 95 % quantile within 15 % of it from
    # n = 5 on (1 % landmark noise adds 1 % of variance; quantile noise over 1000 runs ~5 %).
    assert np.allclose(q[4:], normal[4:], rtol=0.15)
    # 1 % depth with 95 % confidence: the normal bound says 186 faces, and so it is.
    need = samples_needed(sigma_rel, 0.01, ALPHA, "normal")
    assert need == 186  # (1.96 · 6.94 % / 1 %)²
    assert q[need - 1] < 0.0105 and q[need // 2] > 0.0125
    # and the error keeps falling like 1/√n: 4× the faces, half the error (±10 %)
    assert q[399] / q[99] == np.clip(q[399] / q[99], 0.45, 0.55)


def draw(path: Path) -> Path:
    """The convergence figure: error quantiles vs number of faces with both bounds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n, err = simulate()
    sigma_rel = PRIOR.sd_m / PRIOR.mean_m
    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=120)
    ax.loglog(n, 100 * np.median(err, axis=0), color="0.5", label="median error (2000 runs)")
    ax.loglog(n, 100 * np.quantile(err, 1 - ALPHA, axis=0), "k", label="95 % of runs below")
    ax.loglog(n, 100 * error_bound(n, sigma_rel, ALPHA, "normal"), "b--", label="normal bound")
    ax.loglog(n, 100 * error_bound(n, sigma_rel, ALPHA, "chebyshev"), "r--",
              label="Chebyshev bound (eq. 10)")
    for bound, colour in (("normal", "b"), ("chebyshev", "r")):
        m = samples_needed(sigma_rel, 0.01, ALPHA, bound)  # type: ignore[arg-type]
        ax.axvline(m, color=colour, lw=0.6, ls=":")
        ax.annotate(f"n = {m}", (m, 20), color=colour, rotation=90, ha="right", fontsize=8)
    ax.axhline(1.0, color="g", lw=0.8, label="1 % depth")
    ax.set_xlabel("faces n")
    ax.set_ylabel("depth-scale correction error, %")
    ax.set_title(
        "Population mode: IPD prior 62.5 ± 4.3 mm (§3.6 sexes), α = 5 %, 1 % landmark noise",
        fontsize=9,
    )
    ax.grid(True, which="both", lw=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def test_figure_is_drawn(tmp_path: Path) -> None:
    out = draw(tmp_path / "ipd_convergence.png")
    assert out.stat().st_size > 10_000


if __name__ == "__main__":
    print(draw(Path(sys.argv[1] if len(sys.argv) > 1 else "ipd_convergence.png")))
