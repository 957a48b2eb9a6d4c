"""The sparse matcher on real phone pairs (../shared/data/phone_wide_ultra): the per-pair table.

What is measured and how is ``tests/_support/match_phone.py`` (shared with
``tests/features/test_match_isp.py``). ``python benchmarks/bench_match_phone.py`` prints it.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _support.match_phone import evaluate, pairs, pooled_rms_z, rectification


def main() -> int:
    rect = rectification()
    print(
        f"canonical rectification: f = {rect.f_px:.1f} px, B = {rect.baseline_m * 1e3:.1f} mm,"
        f" size {rect.wide_rect.size}"
    )
    print(
        "pair                                       matches  (R→L)  median|e|px  σ_d px"
        "  paired  RMS z"
    )
    rows = []
    for name, wide, tele in pairs():
        out = evaluate(wide, tele)
        rows.append(out)
        print(
            f"{name:42s} {out['matches']:7d} {out['matches_rl']:6d} {out['median_abs_e_px']:12.3f}"
            f" {out['median_sigma_d_px']:7.3f} {out['paired']:7d} {out['rms_z']:6.2f}",
            flush=True,
        )
    n100 = sum(r["matches"] >= 100 for r in rows)
    z = [r["rms_z"] for r in rows if np.isfinite(r["rms_z"])]
    paired = sum(r["paired"] for r in rows if np.isfinite(r["rms_z"]))
    print(
        f"≥ 100 matches on {n100} of {len(rows)} pairs; RMS z median {np.median(z):.2f}, "
        f"pooled over the {paired} paired matches {pooled_rms_z(rows):.2f}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
