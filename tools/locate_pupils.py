"""Build the face-chart portraits and their pupil table (run once; output is committed).

Reads the CC0 portraits (default ``/work/shared/data/faces``), writes downscaled copies into
``src/phonestereo/charts/data/faces/`` (JPEG q95), copies ``LICENSES.md`` with a note on the change,
and writes ``pupils.json``: for each portrait the iris centres (MediaPipe FaceMesh,
``refine_landmarks=True``, static image mode, landmarks 468 and 473) and the eye-contour centroids
(mean of the 16 contour landmarks of each eye), in the pixel convention of docs/conventions.md ((0,
0) is the centre of the top-left pixel; MediaPipe's ``x · width`` has 0 at the left *edge*, so 0.5
is subtracted). Eye 0 is the one on the left of the image (the subject's right eye).

The landmarks are located on the *shipped* (downscaled, re-encoded) images, so the table matches
the pixels the chart samples; the full-resolution originals are located too and, mapped to the
shipped size, their difference is printed as a check.

Usage::

    .venv/bin/python tools/locate_pupils.py [--src DIR] [--dst DIR] [--size 600]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import mediapipe as mp
import numpy as np
from PIL import Image

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DST = ROOT / "src" / "phonestereo" / "charts" / "data" / "faces"
IRIS = {"right": 468, "left": 473}  # subject's right eye is on the image left


def _contour(conn: frozenset[tuple[int, int]]) -> list[int]:
    return sorted({i for edge in conn for i in edge})


CONTOUR = {
    "right": _contour(mp.solutions.face_mesh.FACEMESH_RIGHT_EYE),
    "left": _contour(mp.solutions.face_mesh.FACEMESH_LEFT_EYE),
}

LICENCE_NOTE = """\
> **Copies in this package.** The portraits here were downscaled from 1000 × 1000 to
> {size} × {size} pixels (area interpolation) and re-encoded as JPEG quality 95 by
> `tools/locate_pupils.py`; file names are as below. `pupils.json` holds their pupil centres
> located with MediaPipe FaceMesh. The licence (CC0 1.0) and sources are unchanged.

"""


def locate(rgb: np.ndarray, mesh: object) -> dict[str, list[list[float]]] | None:
    """Iris centres and eye-contour centroids (2, 2) of the one face in ``rgb``, pixels."""
    h, w = rgb.shape[:2]
    res = mesh.process(rgb)  # type: ignore[attr-defined]
    if not res.multi_face_landmarks:
        return None
    lm = res.multi_face_landmarks[0].landmark
    xy = np.array([[p.x * w - 0.5, p.y * h - 0.5] for p in lm], dtype=np.float64)
    iris = np.array([xy[IRIS["right"]], xy[IRIS["left"]]])
    contour = np.array([xy[CONTOUR["right"]].mean(axis=0), xy[CONTOUR["left"]].mean(axis=0)])
    order = np.argsort(iris[:, 0])  # eye 0 = image left
    return {"iris": iris[order].tolist(), "contour": contour[order].tolist()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--src", type=Path, default=Path("/work/shared/data/faces"))
    ap.add_argument("--dst", type=Path, default=DEFAULT_DST)
    ap.add_argument("--size", type=int, default=600, help="side of the shipped portraits, px")
    args = ap.parse_args(argv)
    args.dst.mkdir(parents=True, exist_ok=True)
    sources = sorted(args.src.glob("*.jpg"))
    if not sources:
        print(f"no *.jpg in {args.src}", file=sys.stderr)
        return 2
    table: dict[str, object] = {
        "convention": "pixels (x, y), (0, 0) = centre of the top-left pixel (docs/conventions.md); "
        "eye 0 = image left (subject's right eye)",
        "method": "MediaPipe FaceMesh 0.10.21, refine_landmarks=True, static_image_mode=True; "
        "iris = landmarks 468/473, contour = mean of FACEMESH_RIGHT_EYE/LEFT_EYE vertices",
        "faces": {},
    }
    faces: dict[str, object] = {}
    with mp.solutions.face_mesh.FaceMesh(
        static_image_mode=True, max_num_faces=1, refine_landmarks=True
    ) as mesh:
        for src in sources:
            img = Image.open(src).convert("RGB")
            small = img.resize((args.size, args.size), Image.Resampling.BOX)
            out = args.dst / src.name
            small.save(out, quality=95)
            shipped = np.asarray(Image.open(out).convert("RGB"))
            found = locate(shipped, mesh)
            full = locate(np.asarray(img), mesh)
            if found is None:
                print(f"{src.name}: no face found", file=sys.stderr)
                return 1
            iris = np.array(found["iris"])
            contour = np.array(found["contour"])
            ipd_px = float(np.linalg.norm(iris[1] - iris[0]))
            entry: dict[str, object] = {
                "size": [shipped.shape[1], shipped.shape[0]],
                "pupils_px": np.round(iris, 3).tolist(),
                "eye_contour_centroids_px": np.round(contour, 3).tolist(),
                "ipd_px": round(ipd_px, 3),
            }
            faces[src.name] = entry
            d_contour = np.linalg.norm(iris - contour, axis=1)
            msg = (
                f"{src.name}: ipd_px {ipd_px:7.2f}  |iris - contour| px "
                f"{d_contour[0]:5.2f} {d_contour[1]:5.2f}"
            )
            if full is not None:
                s = args.size / img.width
                mapped = (np.array(full["iris"]) + 0.5) * s - 0.5
                msg += f"  |shipped - full-res mapped| px {np.abs(mapped - iris).max():5.2f}"
            print(msg)
    table["faces"] = faces
    (args.dst / "pupils.json").write_text(json.dumps(table, indent=1) + "\n")
    licence = (args.src / "LICENSES.md").read_text()
    licence = licence.replace("; bytes unchanged)", "; downscaled, see the note above)")
    head, _, rest = licence.partition("\n")
    (args.dst / "LICENSES.md").write_text(
        head + "\n\n" + LICENCE_NOTE.format(size=args.size) + rest.lstrip("\n")
    )
    print(f"wrote {len(faces)} portraits, pupils.json and LICENSES.md to {args.dst}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
