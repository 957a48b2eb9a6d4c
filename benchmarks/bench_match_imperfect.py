"""The sparse matcher on imperfectly rectified Middlebury-Q pairs (issue #18 item 6): the table.

What is measured and how is ``tests/_support/match_imperfect.py`` (shared with
``tests/features/test_match_imperfect.py``). ``python benchmarks/bench_match_imperfect.py
[ORDER]`` prints it; ORDER is the spline order of the right image's resampling (5 by default;
1 shows what a bilinear resampling of one image alone does to d).
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _support.match_imperfect import CASES, SCENES, evaluate


def main() -> int:
    order = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    print(f"right image resampled by a spline of order {order}")
    print("scene       dy px  roll°  matches  ≤0.5px  median|e|px  × aligned  within σ")
    for scene in SCENES:
        ref = evaluate(scene, 0.0, 0.0, order=order)
        for dy, roll in ((0.0, 0.0), *CASES):
            out = ref if (dy, roll) == (0.0, 0.0) else evaluate(scene, dy, roll, order=order)
            print(
                f"{scene:11s} {dy:+5.1f} {roll:+6.2f} {out['matches']:8d}"
                f" {out['within_0.5px']:7.3f} {out['median_abs_err_px']:12.4f}"
                f" {out['median_abs_err_px'] / ref['median_abs_err_px']:10.2f}"
                f" {out['within_1_sigma']:9.2f}",
                flush=True,
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
