"""``phonestereo faces``: faces of an image with pupils, pixel IPD and yaw (thesis §1.2.3)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from phonestereo.cli.app import app
from phonestereo.cli.outputs import IMAGE_OUT, require_output_file
from phonestereo.cli.widgets import error_exit, flag, json_option, overlay_option
from phonestereo.errors import InputError
from phonestereo.features.landmarks import MediaPipeBackend, read_color, read_openface_csv
from phonestereo.features.landmarks.base import FaceResult
from phonestereo.features.landmarks.overlay import draw_faces
from phonestereo.io import write_image


def _summary(image: Path, res: FaceResult) -> str:
    if not res.found:
        return f"{image}: no face: {res.reason}"
    lines = [f"{image}: {len(res)} face(s) ({res.backend})"]
    for k, f in enumerate(res.faces):
        (ax, ay), (bx, by) = f.pupils_px
        yaw = "unknown" if not np.isfinite(f.yaw_rad) else f"{np.degrees(f.yaw_rad):+.1f}°"
        lines.append(
            f"  #{k}: pupils ({ax:.2f}, {ay:.2f}) ({bx:.2f}, {by:.2f})  ipd {f.ipd_px:.2f} px "
            f"(eye centres {f.eye_centre_ipd_px:.2f}, frontal {f.ipd_frontal_px:.2f})  "
            f"yaw {yaw}  score {f.score:.2f}"
        )
    lines += [f"  rejected: {r.reason}" for r in res.rejected]
    lines += [f"  note: {n}" for n in res.notes]
    return "\n".join(lines)


@app.command("faces")
def faces(
    image: Annotated[Path, typer.Argument(help="Image file (PNG, JPEG, ...).")],
    as_json: Annotated[
        bool, json_option("Print the result as JSON (pixels, docs/conventions.md).")
    ] = False,
    overlay: Annotated[Path | None, overlay_option("faces, pupils and labels")] = None,
    openface_csv: Annotated[
        Path | None,
        typer.Option(
            "--openface-csv",
            help="Use landmarks OpenFace 2.0 wrote for IMAGE (its CSV) instead of MediaPipe.",
        ),
    ] = None,
    landmarks: Annotated[bool, flag("--landmarks", "With --json, include every landmark.")] = False,
    any_orientation: Annotated[
        bool,
        flag(
            "--any-orientation",
            "Also search the image turned by 90°, 180°, 270° (4× time).",
        ),
    ] = False,
    force: Annotated[bool, flag("--force", "Overwrite an existing --overlay file.")] = False,
) -> None:
    """List the faces of IMAGE with pupil positions, pixel IPD and head yaw, and draw them.

    Pixels are (x, y) with (0, 0) at the centre of the top-left pixel; eye 0 is the one on the
    image left. Small faces in large images are searched on tiles. Exit code 0 when a face is
    found, 1 when none is (the reason is printed), 2 on bad input.

    Example: phonestereo faces portrait.jpg --json --overlay portrait_faces.png
    """
    try:
        if overlay is not None:
            require_output_file(overlay, force=force, flag="--overlay", suffixes=IMAGE_OUT)
        img = read_color(image)
        if openface_csv is not None:
            frames = read_openface_csv(openface_csv, (img.shape[1], img.shape[0]))
            res = frames[min(frames)] if frames else FaceResult((), (0, 0), "openface", "empty CSV")
        else:
            turns = (0, 1, 2, 3) if any_orientation else (0,)
            res = MediaPipeBackend(quarter_turns=turns).detect(img)
        if overlay is not None:
            write_image(overlay, draw_faces(img, res))
    except InputError as exc:
        raise error_exit(exc) from exc
    if as_json:
        typer.echo(json.dumps({"image": str(image), **res.to_dict(landmarks)}))
    else:
        typer.echo(_summary(image, res))
    if not res.found:
        raise typer.Exit(1)
