import sys, importlib.util, numpy as np
spec = importlib.util.spec_from_file_location("bmi", "benchmarks/bench_match_isp.py")
bmi = importlib.util.module_from_spec(spec); spec.loader.exec_module(bmi)
from phonestereo.features.matching import match_rectified, MatchConfig
for dd in (16.3, 16.0, 16.5):
  for s in ("mild",):
    l, r, dt = bmi.isp_pair([(dd, (0,0,0), (0.0, 0.0))], bmi.ISP_SETTINGS[s])
    for cfg in (MatchConfig(), MatchConfig(correlated_misfit=False)):
        res = match_rectified(l, r, max_disparity=32, config=cfg)
        xi = np.rint(res.xy).astype(int); e = res.d - dt[xi[:, 1], xi[:, 0]]
        print(dd, s, len(res), "signed med %.4f  mad %.4f  sd %.4f  in1s %.2f  e_med %.3f" % (np.median(e), np.median(np.abs(e-np.median(e))), np.median(res.sigma_d), np.mean(np.abs(e)<=res.sigma_d), np.median(res.e)), res.blur_added, res.noise_sigma)
