import sys, importlib.util, numpy as np
spec = importlib.util.spec_from_file_location("bmi", "benchmarks/bench_match_isp.py")
bmi = importlib.util.module_from_spec(spec); spec.loader.exec_module(bmi)
for s in bmi.ISP_SETTINGS:
    for tilt in ((0.0, 0.0, 0.0), (0.0, 0.5, 0.0)):
        print(bmi.isp_honesty(s, tilt), flush=True)
