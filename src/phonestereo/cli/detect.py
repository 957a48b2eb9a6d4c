"""``phonestereo detect-chart``: labelled verification-chart corners of an image (§1.2.2)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Annotated

import cv2
import numpy as np
import typer

from phonestereo.cli.app import app
from phonestereo.cli.outputs import IMAGE_OUT, require_output_file
from phonestereo.cli.widgets import error_exit, flag, json_option, overlay_option
from phonestereo.errors import InputError
from phonestereo.features.verification import ChartDetection, detect_verification_chart
from phonestereo.io import read_gray, write_image

_LABEL_EVERY = 5  # label corners whose row and column are multiples of this


def _parse_roi(text: str | None) -> tuple[int, int, int, int] | None:
    """``"x,y,w,h"`` → a tuple of four ints (pixels)."""
    if text is None:
        return None
    parts = text.replace(" ", "").split(",")
    try:
        x, y, w, h = (int(v) for v in parts)
    except ValueError as exc:
        raise InputError(f"--roi must be four integers x,y,w,h in pixels, got {text!r}") from exc
    return x, y, w, h


def draw_overlay(image: np.ndarray, det: ChartDetection) -> np.ndarray:
    """A BGR copy of ``image`` with the detection drawn on it.

    Corners are dots coloured by quality (saddle strength relative to the image's best corners:
    blue weak → red strong), every fifth row/column is labelled "row,col", the circle pairs are
    outlined and named, and a banner gives the result or the reason.

    Parameters
    ----------
    image : ndarray, shape (H, W), uint8
    det : ChartDetection

    Returns
    -------
    ndarray, shape (H, W, 3), uint8
    """
    out = cv2.cvtColor(np.asarray(image, dtype=np.uint8), cv2.COLOR_GRAY2BGR)
    h, w = out.shape[:2]
    scale = max(h, w) / 2000.0
    thick = max(1, round(2 * scale))
    font = 0.5 * max(scale, 0.5)
    if len(det.points):
        q = det.quality / max(float(np.percentile(det.quality, 95)), 1e-12)
        lut = np.clip(q * 255, 0, 255).astype(np.uint8).reshape(-1, 1)
        colors = cv2.applyColorMap(lut, cv2.COLORMAP_JET).reshape(-1, 3)
        for (x, y), (r, c), col in zip(det.points, det.ids, colors, strict=True):
            centre = (round(float(x)), round(float(y)))
            cv2.circle(out, centre, max(2, round(3 * scale)), tuple(int(v) for v in col), -1)
            if r % _LABEL_EVERY == 0 and c % _LABEL_EVERY == 0:
                cv2.putText(
                    out, f"{r},{c}", (centre[0] + 4, centre[1] - 4), cv2.FONT_HERSHEY_SIMPLEX,
                    font, (0, 200, 255), thick, cv2.LINE_AA,
                )
    for name, centres in det.circles.items():
        a, b = (tuple(round(float(v)) for v in p) for p in centres)
        rad = max(4, round(0.25 * float(np.hypot(*(centres[1] - centres[0])))))
        for p in (a, b):
            cv2.circle(out, p, rad, (0, 255, 0), thick, cv2.LINE_AA)
        cv2.line(out, a, b, (0, 255, 0), thick, cv2.LINE_AA)
        cv2.putText(
            out, name, (a[0], a[1] - rad - 4), cv2.FONT_HERSHEY_SIMPLEX, font,
            (0, 255, 0), thick, cv2.LINE_AA,
        )
    banner = (
        f"{len(det.ids)} corners, pairs: {', '.join(det.pairs_found) or '-'}"
        if det.found
        else f"not found: {det.reason}"
    )
    cv2.putText(
        out, banner, (10, round(30 * max(scale, 0.5))), cv2.FONT_HERSHEY_SIMPLEX, 2 * font,
        (0, 255, 0) if det.found else (0, 0, 255), thick, cv2.LINE_AA,
    )
    return out


@app.command("detect-chart")
def detect_chart(
    image: Annotated[
        Path, typer.Argument(help="Image file (PNG, JPEG, ...); colour is made gray.")
    ],
    as_json: Annotated[bool, json_option("Print the result with every corner as JSON.")] = False,
    overlay: Annotated[Path | None, overlay_option("corners, labels and circles")] = None,
    roi: Annotated[
        str | None, typer.Option("--roi", help="Search only x,y,w,h (pixels of the image).")
    ] = None,
    rotation_hint_deg: Annotated[
        float,
        typer.Option(
            "--rotation-hint",
            help="Expected angle of the chart's columns axis in the image, degrees from +x "
            "towards +y (e.g. 90 for a camera rolled by −90°); ±45° around it are accepted.",
        ),
    ] = 0.0,
    force: Annotated[bool, flag("--force", "Overwrite an existing --overlay file.")] = False,
) -> None:
    """Find the verification chart (chessboard + four circle pairs) and label its corners.

    Corners are identified by their chart (row, col), so wide and tele images of the same chart
    match by id even when the tele sees only part of it. Exit code 0 when the chart is found,
    1 when not (the reason is printed; with --json it is in the JSON), 2 on bad input.

    Example: phonestereo detect-chart wide.png --json --overlay wide_corners.png
    """
    if not math.isfinite(rotation_hint_deg):
        raise typer.BadParameter(
            f"must be a finite angle in degrees (e.g. 0, or 90 for a camera rolled by −90°), "
            f"got {rotation_hint_deg}",
            param_hint="--rotation-hint",
        )
    try:
        if overlay is not None:
            require_output_file(overlay, force=force, flag="--overlay", suffixes=IMAGE_OUT)
        img = read_gray(image)
        det = detect_verification_chart(
            img, roi=_parse_roi(roi), rotation_hint_deg=rotation_hint_deg
        )
        if overlay is not None:
            write_image(overlay, draw_overlay(img, det))
    except InputError as exc:
        raise error_exit(exc) from exc
    if as_json:
        typer.echo(json.dumps({"image": str(image), **det.to_dict()}))
    elif det.found:
        typer.echo(
            f"{image}: {len(det.ids)} corners, circle pairs {', '.join(det.pairs_found)}, "
            f"chart rotated {det.rotation_deg:.1f}° in {det.seconds.get('total', 0.0):.2f} s"
            + (f" ({det.reason})" if det.reason else "")
        )
    else:
        typer.echo(f"{image}: no verification chart: {det.reason}")
    if not det.found:
        raise typer.Exit(1)
