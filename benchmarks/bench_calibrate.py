"""Stereo calibration speed and accuracy on the OpenCV sample, against cv2.stereoCalibrate.

Same corners for both solvers (our detection: OpenCV ordering + saddle refinement), same
5-coefficient model, one core. Prints seconds and RMS of each, and the ratio. Issue #3 target:
our stereo solve ≤ 2 s on one core (mrcal: ~2.2 s).

Usage: ``.venv/bin/python benchmarks/bench_calibrate.py [--json]``
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core: set before numpy is imported

import argparse  # noqa: E402
import glob  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from phonestereo.calibration.solve import CalibrationOptions, calibrate_stereo  # noqa: E402
from phonestereo.calibration.views import BoardView, chessboard_object_points  # noqa: E402
from phonestereo.features.chessboard import find_chessboard  # noqa: E402

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "opencv_stereo"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    cv2.setNumThreads(1)
    obj = chessboard_object_points((9, 6), 1.0)
    views: list[list[BoardView]] = [[], []]
    for f in sorted(glob.glob(str(DATA / "left*.jpg"))):
        for cam, path in enumerate((f, f.replace("left", "right"))):
            det = find_chessboard(cv2.imread(path, cv2.IMREAD_GRAYSCALE), (9, 6))
            views[cam].append(BoardView(obj[det.ids], det.points, det.ids, path))
    size = (640, 480)
    out: dict[str, float] = {}
    for reject in (False, True):
        t0 = time.perf_counter()
        res = calibrate_stereo(
            views[0], views[1], (size, size), CalibrationOptions(reject_outliers=reject)
        )
        key = "robust" if reject else "plain"
        out[f"ours_{key}_seconds"] = time.perf_counter() - t0
        out[f"ours_{key}_rms_px_per_point"] = res.rms_px_per_point
        out[f"ours_{key}_rms_px_per_coordinate"] = res.rms_px_per_coordinate
        out[f"ours_{key}_outlier_fraction"] = res.n_outliers / res.inliers.size
    # OpenCV on the same corners (those found in both images of a pair): mono init, then the
    # joint stereo refinement.
    objs, pts = [], [[], []]
    for vw, vt in zip(views[0], views[1], strict=True):
        common = np.intersect1d(vw.ids, vt.ids)
        objs.append(obj[common].astype(np.float32))
        for c, v in enumerate((vw, vt)):
            pts[c].append(v.image_points[np.searchsorted(v.ids, common)].astype(np.float32))
    t0 = time.perf_counter()
    _, K1, D1, _, _ = cv2.calibrateCamera(objs, pts[0], size, None, None)
    _, K2, D2, _, _ = cv2.calibrateCamera(objs, pts[1], size, None, None)
    rms, *_ = cv2.stereoCalibrate(
        objs, pts[0], pts[1], K1, D1, K2, D2, size, flags=cv2.CALIB_USE_INTRINSIC_GUESS
    )
    out["opencv_seconds"] = time.perf_counter() - t0
    out["opencv_rms_px_per_point"] = float(rms)
    out["time_ratio_ours_plain_vs_opencv"] = out["ours_plain_seconds"] / out["opencv_seconds"]
    if args.json:
        print(json.dumps(out))
    else:
        for k, v in out.items():
            print(f"{k:40s} {v:.4f}")


if __name__ == "__main__":
    main()
