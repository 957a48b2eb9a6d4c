import importlib.util, numpy as np
spec = importlib.util.spec_from_file_location("bp", "benchmarks/bench_match_phone.py")
bp = importlib.util.module_from_spec(spec); spec.loader.exec_module(bp)
import phonestereo.features.matching as M
from phonestereo.features.matching import match_rectified, MatchConfig
from phonestereo.io.images import read_gray
orig = M.misfit_floor
def spy(rv, nv, **k):
    f = orig(rv, nv, **k); print("floor %.1f" % f, end=" "); return f
M.misfit_floor = spy
for name, w, t in bp.pairs()[::3]:
    l, r = bp.rectification().remap(read_gray(w), read_gray(t))
    res = match_rectified(np.asarray(l), np.asarray(r), max_disparity=64, config=MatchConfig(floor_after_blur=True))
    print(name, len(res), res.counts["subpixel"], res.blur_added)
