"""Why the one-sided denoiser costs matches (issue #16): what the clean pair's matches see after it.

For each scene of ``tests/_support/match_isp.py``, the clean pair is matched, then the same left
keypoints (the left image is untouched: the detector finds the same ones) are searched again in
the denoised right image with the matcher's own NCC search. Printed per scene:

* ``clean`` / ``denoised``: the matcher's matches on either pair;
* ``score<min``: clean matches whose best NCC in the denoised pair's band is below
  ``MatchConfig.min_score`` (the score test rejects them whatever comes after it);
* ``ambiguous``: clean matches above the score whose second peak fails the uniqueness test
  (``MatchConfig.uniqueness``): the denoiser lowered the true peak, not the other;
* ``ceiling``: the most that can leave the search, as a fraction of the clean count
  (issue #16 asks for 70 %);
* ``self≥0.9``: clean matches whose right window still correlates ≥ 0.9 with itself after the
  denoiser (the content the fit has to work with);
* ``kept``: clean matches that are still matches of the denoised pair (same left pixel).

Run: ``python benchmarks/bench_match_denoised.py``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from _support.match_isp import SCENES, degrade, load_scene
from phonestereo.features.matching import MatchConfig, match_rectified
from phonestereo.features.search import ncc_search


def _windows(img: np.ndarray, xy: np.ndarray, r: int) -> np.ndarray:
    """(N, 2r + 1, 2r + 1) windows of ``img`` at the integer pixels ``xy``."""
    u = np.arange(-r, r + 1)
    return np.asarray(img, np.float64)[
        xy[:, 1, None, None] + u[None, :, None], xy[:, 0, None, None] + u[None, None, :]
    ]


def _ncc(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a - a.mean(axis=(1, 2), keepdims=True)
    b = b - b.mean(axis=(1, 2), keepdims=True)
    return (a * b).sum(axis=(1, 2)) / np.sqrt((a * a).sum(axis=(1, 2)) * (b * b).sum(axis=(1, 2)))


def main() -> int:
    cfg = MatchConfig()
    r = cfg.radius
    print("scene       clean  denoised  score<min  ambiguous  ceiling  self≥0.9   kept")
    for scene in SCENES:
        left, right, _, ndisp = load_scene(scene)
        den = degrade(left, right, "denoised", scene)[1]
        clean = match_rectified(left, right, max_disparity=ndisp, config=cfg)
        out = match_rectified(left, den, max_disparity=ndisp, config=cfg)
        xy = np.rint(clean.xy).astype(np.int64)
        s = ncc_search(
            np.asarray(left, np.float32),
            np.asarray(den, np.float32),
            xy,
            radius=r,
            min_d=0,
            max_d=ndisp,
            row_tolerance=cfg.row_tolerance,
        )
        low = int(np.sum(~(s.score >= cfg.min_score)))
        xr = np.column_stack([np.rint(clean.xy[:, 0] - clean.d), np.rint(clean.xy[:, 1] - clean.e)])
        xr = xr.astype(np.int64)
        self_ncc = _ncc(_windows(right, xr, r), _windows(den, xr, r))
        found = {tuple(p) for p in np.rint(out.xy).astype(np.int64).tolist()}
        kept = sum(tuple(p) in found for p in xy.tolist())
        with np.errstate(invalid="ignore"):
            above = s.score >= cfg.min_score
            ambiguous = int(np.sum(above & (s.second >= cfg.uniqueness * s.score)))
        n = len(clean)
        print(
            f"{scene:11s} {n:5d} {len(out):9d} {low:10d} {ambiguous:10d}"
            f" {(n - low - ambiguous) / n:8.0%}"
            f" {int(np.sum(self_ncc >= 0.9)):9d} {kept:6d}",
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
