import importlib.util, sys, time, json
from pathlib import Path
import numpy as np, cv2
spec = importlib.util.spec_from_file_location("bm", "benchmarks/bench_match.py")
bm = importlib.util.module_from_spec(spec); spec.loader.exec_module(bm)
from phonestereo.features.matching import match_rectified, MatchConfig

def jpeg(img, q):
    ok, buf = cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, q]); return cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
def sharpen(img):
    f = img.astype(np.float64); g = cv2.GaussianBlur(f, (0, 0), 1.0)
    return np.clip(np.rint(1.8 * f - 0.8 * g), 0, 255).astype(np.uint8)
def denoise(img):
    if img.ndim == 2: return cv2.fastNlMeansDenoising(img, None, 5)
    return cv2.fastNlMeansDenoisingColored(img, None, 5, 5)
CASES = {"clean": lambda l, r: (l, r), "q95": lambda l, r: (jpeg(l, 95), jpeg(r, 95)),
 "q85": lambda l, r: (jpeg(l, 85), jpeg(r, 85)), "q70": lambda l, r: (jpeg(l, 70), jpeg(r, 70)),
 "sharp": lambda l, r: (l, sharpen(r)), "denoise": lambda l, r: (l, denoise(r))}
if __name__ == '__main__':
    scenes = sys.argv[1].split(",") if len(sys.argv) > 1 else ["Adirondack", "Piano", "moto"]
    cases = sys.argv[2].split(",") if len(sys.argv) > 2 else list(CASES)
    for sc in scenes:
        l, r, gt, nd = bm.load_motorcycle() if sc == "moto" else bm.load_middlebury(sc)
        for c in cases:
            a, b = CASES[c](l, r)
            t = time.perf_counter()
            res = match_rectified(a, b, max_disparity=nd)
            dt = time.perf_counter() - t
            g = bm.gt_at(gt, res.xy); ok = np.isfinite(g); err = np.abs(res.d - g)[ok]
            z = (err / res.sigma_d[ok])
            print(f"{sc:10s} {c:8s} n={len(res):4d} med={np.median(err) if len(err) else np.nan:.4f} w05={np.mean(err<=0.5) if len(err) else np.nan:.3f} in1s={np.mean(z<=1) if len(err) else np.nan:.2f} sd={np.median(res.sigma_d) if len(err) else np.nan:.4f} t={dt:.2f} {res.counts} noise={res.noise_sigma}", flush=True)
