"""Verification-chart detection at 2000 × 1500: speed vs OpenCV, accuracy vs the render's truth.

For each scene (the folded-x3 wide camera, f = 1500 px, at 0.8–4 m with a tilt, and the tele,
f = 4500 px, which sees the central part only), rendered by the virtual module with sensor
noise, this times

- ours: ``detect_verification_chart`` (circles, lattice, labels, saddle refinement), and
- OpenCV: ``cv2.findChessboardCorners`` (39 × 27 inner corners, adaptive threshold +
  normalisation) followed by ``cv2.cornerSubPix`` (11 × 11 window),

each as the best of ``--repeat`` runs, and reports the ratio ours / OpenCV (< 1: faster) and
both RMS corner errors (px, per coordinate) against the projected truth. OpenCV needs the whole
board in view and does not label corners by the chart's circles; on the tele view it fails.

Run: ``.venv/bin/python benchmarks/bench_detect.py [--repeat 5] [--json out.json]``.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from typing import Any

import cv2
import numpy as np

from phonestereo.charts.verification import VerificationChart
from phonestereo.features.verification import detect_verification_chart
from phonestereo.geometry import Camera, Transform
from phonestereo.sim.render import render_view
from phonestereo.sim.scene import PlanarObject, Scene, facing_pose
from phonestereo.sim.sensor import SensorModel, capture

CHART = VerificationChart()
SIZE = (2000, 1500)
SCENES = (  # name, focal px, distance m, tilt rotation vector rad
    ("wide 0.8 m", 1500.0, 0.8, (0.15, 0.25, 0.05)),
    ("wide 1.5 m", 1500.0, 1.5, (0.2, 0.3, 0.1)),
    ("wide 2.5 m", 1500.0, 2.5, (0.3, 0.2, 0.1)),
    ("wide 4.0 m", 1500.0, 4.0, (0.1, 0.2, 0.05)),
    ("tele 1.5 m", 4500.0, 1.5, (0.2, 0.3, 0.1)),
)


def _scene(f: float, dist: float, tilt: tuple[float, float, float]) -> tuple[Any, Any]:
    w, h = SIZE
    cam = Camera(SIZE, f, f, (w - 1) / 2, (h - 1) / 2)
    T = facing_pose(CHART.size_m, dist, tilt_rad=tilt)
    rad = render_view(cam, Transform.identity(), Scene((PlanarObject(CHART, T),))).radiance
    img = capture(rad, np.random.default_rng(0), SensorModel())
    uv = CHART.corners_uv()
    return img, cam.project(T.apply(np.c_[uv, np.zeros(len(uv))]))


def _best(fn: Callable[[], Any], repeat: int) -> tuple[float, Any]:
    best, out = np.inf, None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t)
    return best, out


def _opencv(img: Any) -> Any:
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(img, CHART.pattern, flags=flags)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 0.01)
    return cv2.cornerSubPix(img, corners, (5, 5), (-1, -1), crit).reshape(-1, 2)


def run(repeat: int = 5) -> list[dict[str, Any]]:
    """Benchmark every scene; one dict per scene (times in s, RMS in px)."""
    rows = []
    cols = CHART.pattern[0]
    for name, f, dist, tilt in SCENES:
        img, truth = _scene(f, dist, tilt)
        t_ours, det = _best(lambda img=img: detect_verification_chart(img), repeat)
        t_cv, cv_pts = _best(lambda img=img: _opencv(img), repeat)
        ours_rms = float("nan")
        if det.found:
            err = det.points - truth[det.ids[:, 0] * cols + det.ids[:, 1]]
            ours_rms = float(np.sqrt(np.mean(err**2)))
        cv_rms = float("nan")
        if cv_pts is not None:  # OpenCV's order may start at any board corner: nearest truth
            d = np.linalg.norm(cv_pts[:, None, :] - truth[None, :, :], axis=2)
            err = cv_pts - truth[np.argmin(d, axis=1)]
            cv_rms = float(np.sqrt(np.mean(err**2)))
        rows.append(
            {
                "scene": name,
                "ours_s": round(t_ours, 4),
                "opencv_s": round(t_cv, 4),
                "ratio": round(t_ours / t_cv, 3),
                "ours_found": bool(det.found),
                "ours_corners": len(det.ids),
                "ours_refine_s": round(det.seconds.get("refine", 0.0), 4),
                "opencv_found": cv_pts is not None,
                "ours_rms_px": round(ours_rms, 4),
                "opencv_rms_px": round(cv_rms, 4),
            }
        )
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs per method; the best counts")
    ap.add_argument("--json", default=None, help="also write the rows to this JSON file")
    args = ap.parse_args()
    rows = run(args.repeat)
    head = f"{'scene':<11} {'ours s':>7} {'cv s':>7} {'ratio':>6} {'n':>5} {'rms':>7} {'cv rms':>7}"
    print(head)
    for r in rows:
        cv = "fail" if not r["opencv_found"] else f"{r['opencv_rms_px']:.4f}"
        print(
            f"{r['scene']:<11} {r['ours_s']:>7.3f} {r['opencv_s']:>7.3f} {r['ratio']:>6.2f} "
            f"{r['ours_corners']:>5d} {r['ours_rms_px']:>7.4f} {cv:>7}"
        )
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=1)


if __name__ == "__main__":
    main()
