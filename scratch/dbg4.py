import sys, numpy as np
sys.path.insert(0, "scratch")
from degr import CASES, bm
import phonestereo.features.matching as M, phonestereo.features.subpixel as S
from phonestereo.features.matching import match_rectified, MatchConfig
orig = M.misfit_floor
def spy(rv, nv):
    f = orig(rv, nv); print(" floor %.2f" % f, end=""); return f
M.misfit_floor = spy
ow = S._without_blur_term
l, r, dt = bm.render_pair([(16.3, (0.0, 0.5, 0.0), (0.0, 0.0))], size=(320, 240), seed=0, blur=(0.7, 0))
for on in (True, False):
    S._without_blur_term = ow if on else (lambda res, *a: res)
    res = match_rectified(l, r, max_disparity=32); print(on, len(res))
