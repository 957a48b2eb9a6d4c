import sys, numpy as np
sys.path.insert(0, "scratch")
from degr import CASES, bm
import phonestereo.features.matching as M
from phonestereo.features.matching import match_rectified, MatchConfig
orig_rc = M.residual_correlation
def spy_rc(res, m):
    rho = orig_rc(res, m); print(" rho lag(0,1)=%.2f (1,0)=%.2f (1,1)=%.2f (0,2)=%.2f (0,3)=%.2f" % (rho[3,4], rho[4,3], rho[4,4], rho[3,5], rho[3,6]), end=""); return rho
M.residual_correlation = spy_rc
orig_cf = M.correlation_factor
def spy_cf(g, rho):
    f = orig_cf(g, rho); print(" f med=%.2f" % np.nanmedian(f), end=""); return f
M.correlation_factor = spy_cf
def run(name, l, r, dt, nd, cfg=MatchConfig()):
    print(name, end="")
    res = match_rectified(l, r, max_disparity=nd, config=cfg)
    xi = np.rint(res.xy).astype(int)
    err = res.d - dt[xi[:, 1], xi[:, 0]] if dt.ndim == 2 and dt.shape == l.shape[:2] else None
    print(f" n={len(res)} honest={np.mean(np.abs(err) <= res.sigma_d):.2f} med={np.median(np.abs(err)):.4f}")
for blur in [(0.0, 0.0), (0.7, 0.0), (0.0, 0.7), (1.0, 0)]:
    l, r, dt = bm.render_pair([(16.3, (0.0, 0.5, 0.0), (0.0, 0.0))], size=(320, 240), seed=0, blur=blur)
    run(f"blur{blur}", l, r, dt, 32)
    if blur == (0.0, 0.0):
        for c in ("q95", "q85", "q70", "sharp", "denoise"):
            a, b = CASES[c](l, r); run(c, a, b, dt, 32)
