"""The matcher on phone-like images: degraded real pairs and ISP renders (issue #16).

The cases and their evaluation are ``tests/_support/match_isp.py`` (shared with
``tests/features/test_match_isp.py``, so the tests and this table measure the same thing).
``python benchmarks/bench_match_isp.py [SCENE,...]`` prints the table.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _support.match_isp import CASES, ISP_SETTINGS, SCENES, degraded, isp_honesty


def main() -> int:
    scenes = sys.argv[1].split(",") if len(sys.argv) > 1 else list(SCENES)
    print("scene       case       matches  kept  median|e|px  ≤0.5px  within σ")
    for scene in scenes:
        clean = None
        for case in CASES:
            out = degraded(scene, case)
            clean = clean or out
            print(
                f"{scene:11s} {case:10s} {out['matches']:7d}"
                f" {out['matches'] / clean['matches']:5.0%}"
                f" {out['median_abs_err_px']:11.4f} {out['within_0.5px']:7.3f}"
                f" {out['within_1_sigma']:8.2f}",
                flush=True,
            )
    # LR/RL z: the phone pairs' left→right vs right→left statistic on the same renders
    # (bench_match_phone.py), and the correlation of the two directions' errors against the truth
    print("\nISP setting  tilt   matches  median|e|px  median σ_d  within σ  LR/RL z  err corr")
    for setting in ISP_SETTINGS:
        for tilt in ((0.0, 0.0, 0.0), (0.0, 0.5, 0.0)):
            out = isp_honesty(setting, tilt)
            print(
                f"{setting:11s} {tilt[1]:5.2f} {out['matches']:8d} {out['median_abs_err_px']:11.4f}"
                f" {out['median_sigma_d_px']:11.4f} {out['within_1_sigma']:9.2f}"
                f" {out['lr_rms_z']:8.2f} {out['lr_error_corr']:9.2f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
