import importlib.util, numpy as np
spec = importlib.util.spec_from_file_location("bmi", "benchmarks/bench_match_isp.py")
bmi = importlib.util.module_from_spec(spec); spec.loader.exec_module(bmi)
from phonestereo.features.matching import MatchConfig
for kw in ({}, {"max_residual_ratio": 3.0}, {"max_normalized_residual": 0.15}, {"max_residual_ratio": 3.0, "max_normalized_residual": 0.15}, {"max_sigma_d": 0.1}):
    row = []
    for sc, c in [("motorcycle", "clean"), ("Adirondack", "clean"), ("Adirondack", "jpeg85"), ("Adirondack", "jpeg70"), ("Piano", "jpeg70"), ("Piano", "clean")]:
        o = bmi.degraded(sc, c, MatchConfig(**kw)); row.append(f"{sc[:4]}-{c}: {o['matches']} {o['median_abs_err_px']:.4f}")
    print(kw, " | ".join(row), flush=True)
