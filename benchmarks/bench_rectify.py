"""Rectification benchmark: accuracy of the three modes and speed against OpenCV.

Accuracy: the virtual module's true rig (calibration conditions) projects points in the tele's
view at 0.5–5 m; they are rectified with the true calibration and with the factory one, and
the non-disparity error e = y_wide − y_tele is reported per mode (max, median, and the
near − far median that shows the §3.3 depth dependence), for both presets, with and without
the non-baseline translation. OpenCV's stereoRectify on the factory calibration is beside it
(its e rescaled to the wide's focal length: it gives both cameras the mean focal length).

Speed: building the maps and remapping a 2000×1500 pair, against cv2.stereoRectify +
cv2.initUndistortRectifyMap + cv2.remap on the same factory calibration (median of repeats;
ratio = ours / OpenCV, lower is better).

Run: ``.venv/bin/python benchmarks/bench_rectify.py [--repeat 5] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import time
from typing import Any

import cv2
import numpy as np

from phonestereo.geometry import Rig
from phonestereo.rectification import MODES, Rectification, RectifyOptions
from phonestereo.sim.capture import calibration_rig
from phonestereo.sim.factory import factory_calibration
from phonestereo.sim.module import load_module


def scene(rig: Rig, n: int = 4000, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Wide-frame points in the tele's view at 0.5–5 m and their depths."""
    rng = np.random.default_rng(seed)
    q = rng.uniform([20, 20], [rig.tele.width - 20, rig.tele.height - 20], (n, 2))
    z = rng.uniform(0.5, 5.0, n)
    return rig.T_tele_wide.inverse().apply(rig.tele.unproject(q) * z[:, None]), z


def _stats(e: np.ndarray, z: np.ndarray) -> dict[str, float]:
    a = np.abs(e)
    return {
        "max_px": float(np.nanmax(a)),
        "median_px": float(np.nanmedian(a)),
        "near_minus_far_px": float(np.nanmedian(e[z < 1.0]) - np.nanmedian(e[z > 4.0])),
    }


def _opencv(rig: Rig, alpha: float = -1.0) -> tuple[np.ndarray, ...]:
    dist = [np.asarray(c.lens.coefficients) for c in (rig.wide, rig.tele)]
    T = rig.T_tele_wide
    return cv2.stereoRectify(
        rig.wide.K, dist[0], rig.tele.K, dist[1], rig.wide.size, T.R, T.t, alpha=alpha
    )


def opencv_e(rig: Rig, qw: np.ndarray, qt: np.ndarray) -> np.ndarray:
    """OpenCV's non-disparity error in wide pixels (its disparity axis is y for a vertical
    baseline; its rectified f is the mean of the two, so e is rescaled by f_wide / f_cv)."""
    R1, R2, P1, P2 = _opencv(rig)[:4]
    dist = [np.asarray(c.lens.coefficients) for c in (rig.wide, rig.tele)]
    rw = cv2.undistortPoints(qw[:, None], rig.wide.K, dist[0], R=R1, P=P1)[:, 0]
    rt = cv2.undistortPoints(qt[:, None], rig.tele.K, dist[1], R=R2, P=P2)[:, 0]
    axis = 0 if abs(P2[1, 3]) > abs(P2[0, 3]) else 1  # the axis *across* the baseline
    return np.asarray(rw[:, axis] - rt[:, axis]) * rig.wide.f / P1[0, 0]


def accuracy() -> list[dict[str, Any]]:
    rows = []
    for name in ("folded-x3", "nonfolded-x2"):
        for nbt in (True, False):
            spec = load_module(name).with_effects(non_baseline_translation=nbt)
            true = calibration_rig(spec)
            factory = factory_calibration(spec, np.random.default_rng(1)).rig
            P, z = scene(true)
            qw, qt = true.project(P)
            for cal, rig in (("true", true), ("factory", factory)):
                for mode in MODES:
                    _, e = Rectification.from_rig(rig, mode).disparity(qw, qt)
                    key = {"module": name, "t_y_t_z": nbt, "calibration": cal, "mode": mode}
                    rows.append({**key, **_stats(e, z)})
                if cal == "factory" and rig.wide.lens.name == "opencv5":
                    key = {**key, "mode": "opencv-stereoRectify"}
                    rows.append({**key, **_stats(opencv_e(rig, qw, qt), z)})
    return rows


def _median_time(fn: Any, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def speed(repeat: int) -> list[dict[str, Any]]:
    rig = factory_calibration(load_module("folded-x3"), np.random.default_rng(1)).rig
    rng = np.random.default_rng(0)
    img_w = rng.integers(0, 256, (1500, 2000), dtype=np.uint8)
    img_t = rng.integers(0, 256, (1500, 2000), dtype=np.uint8)
    dist = [np.asarray(c.lens.coefficients) for c in (rig.wide, rig.tele)]

    def opencv() -> None:
        R1, R2, P1, P2 = _opencv(rig)[:4]
        jobs = ((rig.wide.K, dist[0], R1, P1, img_w), (rig.tele.K, dist[1], R2, P2, img_t))
        for K, D, R, P, img in jobs:
            mx, my = cv2.initUndistortRectifyMap(K, D, R, P, (2000, 1500), cv2.CV_32FC1)
            cv2.remap(img, mx, my, cv2.INTER_LINEAR)

    t_cv = _median_time(opencv, repeat)
    f_cv = float(_opencv(rig)[2][0, 0])
    label = "opencv stereoRectify (alpha=-1, default)"
    rows = [{"method": label, "size": [2000, 1500], "f_px": f_cv, "seconds": t_cv, "ratio": 1.0}]
    configs = [
        ("canonical", RectifyOptions()),
        ("canonical", RectifyOptions(fov="wide")),
        ("canonical", RectifyOptions(resolution="tele")),
        ("tele-to-wide", RectifyOptions()),
        ("tele-to-wide", RectifyOptions(resolution="tele")),
        ("undistort-both", RectifyOptions(fov="wide")),
    ]
    for mode, opts in configs:
        rect = Rectification.from_rig(rig, mode, opts)

        def ours(m: str = mode, o: RectifyOptions = opts) -> None:
            Rectification.from_rig(rig, m, o).remap(img_w, img_t)  # fresh maps every run

        t = _median_time(ours, repeat)
        label = f"phonestereo {mode} resolution={opts.resolution} fov={opts.fov}"
        size = list(rect.wide_rect.size)
        rows.append(
            {"method": label, "size": size, "f_px": rect.f_px, "seconds": t, "ratio": t / t_cv}
        )
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    acc, spd = accuracy(), speed(args.repeat)
    if args.json:
        print(json.dumps({"accuracy": acc, "speed": spd}, indent=2))
        return
    print("non-disparity error e = y_wide − y_tele, points at 0.5–5 m (px)")
    head = ("module", "t_y,t_z", "calib", "mode", "max", "median", "near−far")
    print("{:13s} {:7s} {:8s} {:21s} {:>9s} {:>9s} {:>9s}".format(*head))
    for r in acc:
        print(
            f"{r['module']:13s} {'on' if r['t_y_t_z'] else 'off':7s} {r['calibration']:8s} "
            f"{r['mode']:21s} {r['max_px']:9.2e} {r['median_px']:9.2e} "
            f"{r['near_minus_far_px']:+9.4f}"
        )
    print("\nmaps + remap of a 2000×1500 pair (median of", args.repeat, "runs)")
    for r in spd:
        print(
            f"{r['method']:58s} {r['size'][0]:5d}×{r['size'][1]:<5d} f={r['f_px']:7.1f} "
            f"{r['seconds'] * 1e3:8.1f} ms  ratio {r['ratio']:.2f}"
        )


if __name__ == "__main__":
    main()
