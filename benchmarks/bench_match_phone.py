"""The sparse matcher on real phone pairs: ../shared/data/phone_wide_ultra (issue #16 item 4).

Real ultra-wide (our ``wide``) + wide (our ``tele``) 480 × 424 JPEGs out of a phone's ISP, with a
third party's OpenCV calibration (camera 1 = the phone's wide = our tele). Per pair, through the
product: the calibration converted by :func:`phonestereo.io.opencv_yaml.import_opencv_yaml`
(``convert-calibration … --first-camera tele``), the pair rectified in canonical mode
(:class:`phonestereo.rectification.rectify.Rectification`, the tele's field of view), matched
with :func:`phonestereo.features.matching.match_rectified` both ways. Reported: the matches,
the median |e| (row error after rectification, px) and the left→right vs right→left
consistency: the pair is matched again with the images swapped and mirrored (x → W − 1 − x keeps
d > 0), matches are paired by position (same left pixel within 1 px: the mirrored right point
x − d), and RMS of (d_LR − d_RL) / √(σ_LR² + σ_RL²) is reported (≈ 1 for honest σ).

``python benchmarks/bench_match_phone.py`` prints the per-pair table.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _support.match_phone import evaluate, pairs, rectification


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
    print(f"≥ 100 matches on {n100} of {len(rows)} pairs; RMS z median {np.median(z):.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
