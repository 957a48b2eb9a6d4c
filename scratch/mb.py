import importlib.util, numpy as np, sys, cv2
spec = importlib.util.spec_from_file_location("bmi", "benchmarks/bench_match_isp.py")
bmi = importlib.util.module_from_spec(spec); spec.loader.exec_module(bmi)
bench = bmi.bench
from phonestereo.features.matching import MatchConfig
left, right, gt, nd = bench.load_motorcycle(); lg = bench.gt_consistent_left(left, right, gt)
def b8(img, s): return np.clip(np.rint(cv2.GaussianBlur(img.astype(np.float32), (0, 0), s)), 0, 255).astype(np.uint8)
for kw in [dict(typical_misfit=float(k)) for k in sys.argv[1].split(",")]:
    cfg = MatchConfig(**kw)
    ref = bench.evaluate_real(lg, right, gt, nd, cfg)["median_abs_err_px"]["ours"]
    row = [f"ref {ref:.4f}"]
    for side, s in (("left", 0.7), ("right", 0.7), ("right", 1.0)):
        l2 = b8(lg, s) if side == "left" else lg; r2 = b8(right, s) if side == "right" else right
        o = bench.evaluate_real(l2, r2, gt, nd, cfg); row.append(f"{side}{s}: {o['matches']} {o['median_abs_err_px']['ours']/ref:.2f}x")
    for sc, c in [("Adirondack", "jpeg85"), ("Adirondack", "jpeg70"), ("Piano", "jpeg70")]:
        o = bmi.degraded(sc, c, cfg); row.append(f"{sc[:4]}-{c}: {o['matches']} {o['median_abs_err_px']:.4f}")
    print(kw, " | ".join(row), flush=True)
