import importlib.util, numpy as np
spec = importlib.util.spec_from_file_location("bp", "benchmarks/bench_match_phone.py")
bp = importlib.util.module_from_spec(spec); spec.loader.exec_module(bp)
from phonestereo.features.matching import match_rectified, MatchConfig
from phonestereo.io.images import read_gray
name, w, t = bp.pairs()[1]
l, r = bp.rectification().remap(read_gray(w), read_gray(t))
for cfg in (MatchConfig(), MatchConfig(row_tolerance=6), MatchConfig(max_sigma_d=1.0)):
    res = match_rectified(np.asarray(l), np.asarray(r), max_disparity=64, config=cfg)
    print(res.counts, res.noise_sigma, res.blur_added, np.median(res.d) if len(res) else None)
