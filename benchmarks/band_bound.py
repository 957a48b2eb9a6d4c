"""What the within-σ band (issue #18: each set's fraction within σ in 50–90 %) can reach.

A set's errors are its common offset c_i ~ N(0, c²), shared by its captures, plus per-capture
scatter N(0, s²). With an honest σ = √(c² + s²) the fraction of sets whose within-σ lands in
the band depends only on c/s; this prints it (and the best single scale k·σ) for 18 captures a
set (the model: ``phonestereo.evaluation.band_bound``; asserted by
tests/evaluation/test_band_bound.py). docs/module-random.md, session 14: 16 of 20 needs
c/s ≤ ~0.9.

Run: ``.venv/bin/python benchmarks/band_bound.py [--sets N] [--captures K]`` (~10 s).
"""

from __future__ import annotations

import argparse

import numpy as np

from phonestereo.evaluation.band_bound import band_fraction


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sets", type=int, default=200_000, help="simulated sets per ratio")
    ap.add_argument("--captures", type=int, default=18, help="captures per set")
    args = ap.parse_args()
    print("c/s    honest σ    best k·σ")
    for r in (0.0, 0.25, 0.5, 0.75, 1.0, 1.25, 1.5, 2.0):
        ks = np.linspace(0.5, 2.0, 31)
        fs = [band_fraction(r, k, sets=args.sets, captures=args.captures) for k in ks]
        i = int(np.argmax(fs))
        print(f"{r:4.2f}   {band_fraction(r, sets=args.sets, captures=args.captures):6.2f}"
              f"      {fs[i]:.2f} (k = {ks[i]:.2f})")


if __name__ == "__main__":
    main()
