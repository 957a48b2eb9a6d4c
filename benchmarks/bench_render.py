"""Speed of the renderer: one wide + tele pair of a verification chart at 2 m, on ONE core.

Wide 2000 × 1500 (f = 1500 px, 4.2 mm f/1.8) and tele 2000 × 1500 (f = 4500 px, 12.6 mm f/2.8)
of the folded-x3 module, a realistic lens (opencv5 k1 = −0.05, k2 = 0.02, small p1/p2), the chart
tilted ~7° / 9°, defocus on (both focused at 1.5 m). Target: ≤ 1 s per pair.

Then the sensor stage on the same radiance images, both ways in the same run: the linear grey
sensor (``sim.sensor.capture``) and the folded-x3 preset's phone ISP per camera
(``sim.isp.isp_file``: CFA, noise, demosaic, ..., JPEG bytes). The ISP's extra time per pair is
their difference (issue #16 target: ≤ 0.5 s per pair).

Usage::

    .venv/bin/python benchmarks/bench_render.py [--repeat 5] [--profile] [--json]

Prints seconds per pair and per camera (the best of ``--repeat`` runs, wall clock; the
median beside it), the work done (samples per camera) and, with ``--json``, one JSON line.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = "1"  # one core: set before numpy is imported

import argparse  # noqa: E402
import cProfile  # noqa: E402
import json  # noqa: E402
import pstats  # noqa: E402
import time  # noqa: E402
from typing import Any  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

import phonestereo.sim.render as render  # noqa: E402
import phonestereo.sim.scene as scene_mod  # noqa: E402
from phonestereo.geometry import Camera, Transform, make_lens  # noqa: E402
from phonestereo.sim.isp import isp_file  # noqa: E402
from phonestereo.sim.module import load_module  # noqa: E402
from phonestereo.sim.optics import defocus_sigma_function  # noqa: E402
from phonestereo.sim.scene import PlanarObject, Scene, facing_pose  # noqa: E402
from phonestereo.sim.sensor import SensorModel, capture  # noqa: E402

LENS = make_lens("opencv5", (-0.05, 0.02, 3e-4, -2e-4, 0.0))
CAMERAS = {  # name: (focal length px, physical focal length m, f-number)
    "wide": (1500.0, 4.2e-3, 1.8),
    "tele": (4500.0, 12.6e-3, 2.8),
}
PITCH_M, FOCUS_M, CHART_M = 2.8e-6, 1.5, 2.0


def _chart() -> Any:
    """The charts helper's VerificationChart (40 × 28 squares of 25 mm)."""
    from phonestereo.charts.verification import VerificationChart

    return VerificationChart()


def _count_samples() -> tuple[list[int], Any]:
    """Wrap the ray caster (as the renderer and the scene see it) to count shaded samples.

    Returns the counts and a function that restores the originals.
    """
    counts: list[int] = []
    original = scene_mod.cast_rays

    def counting(planes: Any, x: Any, y: Any, background: float) -> Any:
        counts.append(len(x))
        return original(planes, x, y, background)

    render.cast_rays = scene_mod.cast_rays = counting  # type: ignore[assignment]

    def restore() -> None:
        render.cast_rays = scene_mod.cast_rays = original  # type: ignore[assignment]

    return counts, restore


def _isp_timing(cams: dict[str, Camera], scene: Scene, repeat: int) -> dict[str, float]:
    """Seconds per pair of the linear sensor and of the preset's ISP, best of ``repeat``:
    wall clock and this process's CPU time (the honest figure on a shared, loaded machine)."""
    spec = load_module("folded-x3")
    rad = {n: render.render_view(c, Transform.identity(), scene).radiance for n, c in cams.items()}
    out = dict.fromkeys(("linear_s", "isp_s", "linear_cpu_s", "isp_cpu_s"), 0.0)
    for name in cams:
        model = SensorModel(**spec.camera(name).sensor.model_dump())
        isp = spec.isp(name)
        assert isp is not None
        rng = np.random.default_rng(0)
        times: dict[str, list[float]] = {k: [] for k in out}
        for _ in range(repeat + 1):  # the first run warms up (OpenCV, caches)
            for key in ("linear", "isp"):
                w0, c0 = time.perf_counter(), time.process_time()
                if key == "linear":
                    capture(rad[name], rng, model)
                else:
                    isp_file(rad[name], isp, model, rng)
                times[f"{key}_s"].append(time.perf_counter() - w0)
                times[f"{key}_cpu_s"].append(time.process_time() - c0)
        for k in out:
            out[k] += min(times[k][1:])
    out["extra_s"] = out["isp_s"] - out["linear_s"]
    out["extra_cpu_s"] = out["isp_cpu_s"] - out["linear_cpu_s"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5, help="runs per camera (best is kept)")
    parser.add_argument("--profile", action="store_true", help="print a cProfile of one pair")
    parser.add_argument("--json", action="store_true", help="also print one JSON line")
    args = parser.parse_args()
    cv2.setNumThreads(1)

    chart = _chart()
    T_cam_chart = facing_pose(chart.size_m, CHART_M, tilt_rad=(0.12, -0.16, 0.02))
    scene = Scene((PlanarObject(chart, T_cam_chart, "verification"),))
    jobs = []
    for name, (f_px, f_m, n) in CAMERAS.items():
        cam = Camera((2000, 1500), f_px, f_px, 1003.2, 747.9, LENS)
        jobs.append((name, cam, defocus_sigma_function(f_m, n, FOCUS_M, PITCH_M)))

    def run(cam: Camera, blur: Any) -> None:
        render.render_view(cam, Transform.identity(), scene, defocus_sigma_px=blur)

    for _, cam, blur in jobs:  # warm-up (imports, caches)
        run(cam, blur)
    best, median, samples = {}, {}, {}
    for name, cam, blur in jobs:
        times = []
        for _ in range(max(args.repeat, 1)):
            t0 = time.perf_counter()
            run(cam, blur)
            times.append(time.perf_counter() - t0)
        best[name], median[name] = min(times), float(np.median(times))
        counts, restore = _count_samples()
        run(cam, blur)
        restore()
        samples[name] = sum(counts)

    pair, pair_median = sum(best.values()), sum(median.values())
    print(f"render pair (2000×1500 wide f=1500 + tele f=4500, chart at {CHART_M} m, one core)")
    for name in CAMERAS:
        print(
            f"  {name:5s} {best[name]:.3f} s (median {median[name]:.3f} s), "
            f"{samples[name] / 1e6:.2f} M samples ({samples[name] / 3e6:.2f} per pixel)"
        )
    print(f"  pair  {pair:.3f} s (median {pair_median:.3f} s); target <= 1 s")
    isp = _isp_timing({name: cam for name, cam, _ in jobs}, scene, max(args.repeat, 1))
    print("sensor stage per pair (same radiance, one core): best of the repeats")
    for kind, sfx in (("wall", "s"), ("CPU", "cpu_s")):
        lin, full, extra = isp[f"linear_{sfx}"], isp[f"isp_{sfx}"], isp[f"extra_{sfx}"]
        print(f"  {kind:4s} linear grey sensor {lin:.3f} s, phone ISP {full:.3f} s "
              f"(x{full / lin:.1f}); ISP extra {extra:.3f} s/pair; target <= 0.5 s")
    if args.profile:
        prof = cProfile.Profile()
        prof.enable()
        for _, cam, blur in jobs:
            run(cam, blur)
        prof.disable()
        pstats.Stats(prof).sort_stats("tottime").print_stats(15)
    if args.json:
        print(
            json.dumps(
                {
                    "benchmark": "render_pair",
                    "seconds_per_pair": round(pair, 4),
                    "seconds_per_pair_median": round(pair_median, 4),
                    "seconds_per_camera": {k: round(v, 4) for k, v in best.items()},
                    "samples_per_camera": samples,
                    "threads": 1,
                    "target_seconds_per_pair": 1.0,
                    "isp_seconds_per_pair": round(isp["isp_s"], 4),
                    "linear_sensor_seconds_per_pair": round(isp["linear_s"], 4),
                    "isp_extra_seconds_per_pair": round(isp["extra_s"], 4),
                    "isp_extra_cpu_seconds_per_pair": round(isp["extra_cpu_s"], 4),
                    "isp_target_extra_seconds_per_pair": 0.5,
                }
            )
        )


if __name__ == "__main__":
    main()
