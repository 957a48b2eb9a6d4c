import importlib.util, sys
import numpy as np, cv2
sys.path.insert(0, "scratch")
from degr import CASES, bm
import phonestereo.features.matching as M
from phonestereo.features.matching import match_rectified, MatchConfig
orig = M.misfit_floor
def spy(rv, nv):
    f = orig(rv, nv); print("floor", f, "n", len(rv), "pct ratio", np.percentile(rv/nv, [10,50,90]).round(2)); return f
M.misfit_floor = spy
for sc, c in [(a, b) for a in sys.argv[1].split(",") for b in sys.argv[2].split(",")]:
    l, r, gt, nd = bm.load_motorcycle() if sc == "moto" else bm.load_middlebury(sc)
    a, b = CASES[c](l, r)
    for cfg in (MatchConfig(), MatchConfig(max_normalized_residual=1.0)):
        res = match_rectified(a, b, max_disparity=nd, config=cfg)
        g = bm.gt_at(gt, res.xy); ok = np.isfinite(g); err = np.abs(res.d - g)[ok]
        print(sc, c, len(res), np.median(err).round(4), res.counts["subpixel"], res.counts["residual"])
