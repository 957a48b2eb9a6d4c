import importlib.util, sys
import numpy as np, cv2
spec = importlib.util.spec_from_file_location("bm", "benchmarks/bench_match.py")
bm = importlib.util.module_from_spec(spec); spec.loader.exec_module(bm)
sys.path.insert(0, "scratch"); 
from degr import CASES
from phonestereo.features.matching import match_rectified, MatchConfig
l, r, gt, nd = bm.load_middlebury("Adirondack")
a, b = CASES["sharp"](l, r)
for eq in (True, False):
    res = match_rectified(a, b, max_disparity=nd, config=MatchConfig(equalise_blur=eq))
    print(eq, res.blur_added, res.noise_sigma, res.counts)
