import sys, importlib.util, numpy as np
spec = importlib.util.spec_from_file_location("bmi", "benchmarks/bench_match_isp.py")
bmi = importlib.util.module_from_spec(spec); spec.loader.exec_module(bmi)
from phonestereo.features.matching import match_rectified, MatchConfig
sets = {"mild": bmi.ISP_SETTINGS["mild"], "nodn_nosharp_png": {"denoise_strength": 0, "sharpen_amount": 0, "jpeg_quality": None},
        "bilinear_png": {"denoise_strength": 0, "sharpen_amount": 0, "jpeg_quality": None, "demosaic": "bilinear"},
        "vng_png": {"denoise_strength": 0, "sharpen_amount": 0, "jpeg_quality": None, "demosaic": "vng"}}
for name in sys.argv[1].split(","):
  for dd in (16.0, 16.5, 17.0):
    l, r, dt = bmi.isp_pair([(dd, (0,0,0), (0.0, 0.0))], sets[name])
    res = match_rectified(l, r, max_disparity=32)
    xi = np.rint(res.xy).astype(int); e = res.d - dt[xi[:, 1], xi[:, 0]]
    print(name, dd, len(res), "signed med %.4f  mad %.4f  sd %.4f  in1s %.2f" % (np.median(e), np.median(np.abs(e-np.median(e))), np.median(res.sigma_d), np.mean(np.abs(e)<=res.sigma_d)), flush=True)
