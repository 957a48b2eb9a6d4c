import importlib.util, numpy as np, sys
spec = importlib.util.spec_from_file_location("bmi", "benchmarks/bench_match_isp.py")
bmi = importlib.util.module_from_spec(spec); spec.loader.exec_module(bmi)
import phonestereo.features.matching as M
orig = M.misfit_floor
for kappa in [float(x) for x in sys.argv[1].split(",")]:
    M.misfit_floor = lambda rv, nv, k=kappa: max(1.0, orig(rv, nv) / k)
    row = []
    for sc, c in [("motorcycle", "clean"), ("Adirondack", "clean"), ("Piano", "clean"), ("Adirondack", "jpeg85"), ("Adirondack", "jpeg70"), ("Piano", "jpeg70"), ("motorcycle", "jpeg70"), ("Piano", "denoised"), ("Piano", "sharpened")]:
        o = bmi.degraded(sc, c); row.append(f"{sc[:4]}-{c}: {o['matches']} {o['median_abs_err_px']:.4f}")
    print(kappa, " | ".join(row), flush=True)
