"""The face ruler's own bias: the landmark detector's IPD against the chart's pupil table, by face
size and blur (issue #18's common mode, docs/module-random.md, session 10).

The face chart's IPD is defined by MediaPipe FaceMesh's iris centres on the shipped portraits
(``tools/locate_pupils.py`` → ``charts/data/pupils.json``). In a capture the detector sees each
portrait smaller (an IPD of 30–100 px in a 2 MP wide at 1–3 m) and blurred by the optics, so
its IPD reading may differ from the table's. This script measures that difference on the
shipped portraits (real CC0 photographs) with nothing of the simulator: each portrait is
resampled onto a grey canvas so that its table IPD is ``S`` px (antialiased area-like
resampling, ``cv2.warpAffine``), at a few random sub-pixel placements, optionally blurred by
a Gaussian point-spread function of σ px, and detected with the learning flow's wide backend
(``flows.face_backends.default_backend``'s wide half). It reports, per (S, σ), the median and
mean of IPD_detected / IPD_table − 1 over portraits × placements and its standard deviation.

Run: ``.venv/bin/python benchmarks/bench_ipd_ruler.py [--sizes 33,50,96] [--blurs 0,1,2]
[--placements 3] [--json]`` (~1 min on 2 cores).
"""

from __future__ import annotations

import argparse
import json
from importlib import resources
from typing import Any

import cv2
import numpy as np
from PIL import Image

from phonestereo.charts.faces import portraits
from phonestereo.features.landmarks import MediaPipeBackend

CANVAS = (1024, 768)


def _wide_backend() -> MediaPipeBackend:
    """The learning flow's wide backend (``default_backend``)."""
    return MediaPipeBackend(mirror_average=False, two_level_tiles=(0.35, 0.08),
                            detector_max_px=1024)


def _place(gray: np.ndarray, pupils: np.ndarray, scale: float, shift: np.ndarray) -> tuple[
        np.ndarray, np.ndarray]:
    """The portrait scaled by ``scale`` with its pupil midpoint at the canvas centre + shift;
    returns the canvas (uint8) and the affine map (2, 3) from portrait to canvas pixels."""
    w, h = CANVAS
    # area-like antialiasing before a downscale: Gaussian of σ = 0.5·sqrt(1/s² − 1) px
    sig = 0.5 * np.sqrt(max(1.0 / scale**2 - 1.0, 0.0))
    src = cv2.GaussianBlur(gray, (0, 0), sig) if sig > 0.05 else gray
    mid = pupils.mean(axis=0)
    m = np.array([[scale, 0.0, w / 2 + shift[0] - scale * mid[0]],
                  [0.0, scale, h / 2 + shift[1] - scale * mid[1]]])
    canvas = cv2.warpAffine(src, m, (w, h), flags=cv2.INTER_CUBIC, borderValue=128)
    return canvas, m


def measure(sizes: list[float], blurs: list[float], placements: int, seed: int = 0) -> list[
        dict[str, Any]]:
    """Rows of (size, blur) → relative IPD error statistics (module docstring)."""
    rng = np.random.default_rng(seed)
    backend = _wide_backend()
    table = portraits()
    shipped = resources.files("phonestereo.charts") / "data" / "faces"  # the shipped JPEGs
    grays = {}
    for n in table:
        with (shipped / n).open("rb") as fh:
            grays[n] = np.asarray(Image.open(fh).convert("L"))
    rows = []
    for size in sizes:
        for blur in blurs:
            rel: dict[str, list[float]] = {"iris": [], "contour": [], "both": []}
            for name, p in table.items():
                for _ in range(placements):
                    canvas, m = _place(grays[name], p.pupils_px, size / p.ipd_px,
                                       rng.uniform(-0.5, 0.5, 2))
                    if blur > 0:
                        canvas = cv2.GaussianBlur(canvas, (0, 0), blur)
                    faces = backend.detect(canvas).faces
                    if not faces:
                        continue
                    truth = p.pupils_px * m[0, 0] + m[:, 2]
                    f = min(faces, key=lambda f: float(np.linalg.norm(
                        f.pupils_px.mean(axis=0) - truth.mean(axis=0))))
                    one = {}
                    for kind, found, table_px in (
                        ("iris", f.pupils_px, p.pupils_px),
                        ("contour", f.eye_centres_px, p.eye_contours_px),
                    ):
                        t = table_px * m[0, 0] + m[:, 2]
                        one[kind] = (float(np.linalg.norm(found[1] - found[0]))
                                     / float(np.linalg.norm(t[1] - t[0])) - 1.0)
                        rel[kind].append(one[kind])
                    rel["both"].append(0.5 * (one["iris"] + one["contour"]))
            for kind, v in rel.items():
                r = np.asarray(v)
                rows.append({
                    "ipd_px": size, "blur_sigma_px": blur, "landmarks": kind, "n": int(r.size),
                    "median_rel": float(np.median(r)) if r.size else None,
                    "mean_rel": float(np.mean(r)) if r.size else None,
                    "sd_rel": float(np.std(r)) if r.size else None,
                })
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="33,50,70,96,130", help="table IPDs on the canvas, px")
    ap.add_argument("--blurs", default="0,1,2", help="Gaussian PSF σ values, px")
    ap.add_argument("--placements", type=int, default=3, help="sub-pixel placements per face")
    ap.add_argument("--json", action="store_true", help="print JSON instead of the table")
    a = ap.parse_args()
    rows = measure([float(s) for s in a.sizes.split(",")], [float(b) for b in a.blurs.split(",")],
                   a.placements)
    if a.json:
        print(json.dumps(rows, indent=1))
        return 0
    print("IPD px  blur σ px  landmarks   n   median     mean      sd   (IPD detected / table − 1)")
    for r in rows:
        if r["n"]:
            print(f"{r['ipd_px']:6.0f} {r['blur_sigma_px']:8.1f}  {r['landmarks']:8s} {r['n']:4d} "
                  f"{100 * r['median_rel']:+7.2f} % {100 * r['mean_rel']:+7.2f} % "
                  f"{100 * r['sd_rel']:6.2f} %")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
