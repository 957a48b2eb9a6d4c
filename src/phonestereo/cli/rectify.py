"""`phonestereo rectify`: a raw wide/tele pair → the rectified pair (thesis §1.3.3, §3.2, §3.3)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.console import Console

from phonestereo.cli.app import app
from phonestereo.cli.outputs import require_output_folder
from phonestereo.cli.widgets import error_exit, figure_table, flag, json_option
from phonestereo.errors import InputError
from phonestereo.io import load_calibration, read_gray, write_image
from phonestereo.rectification import MODES, Rectification, RectifyOptions, check_mode

WIDE_PNG, TELE_PNG, JSON_NAME = "wide_rectified.png", "tele_rectified.png", "rectification.json"


def _roi(text: str | None) -> tuple[int, int, int, int] | None:
    if text is None:
        return None
    try:
        x, y, w, h = (int(v) for v in text.replace(" ", "").split(","))
    except ValueError as exc:
        raise InputError(
            f"--roi must be X,Y,W,H in raw wide pixels (e.g. 800,500,400,300), got {text!r}"
        ) from exc
    return x, y, w, h


def rectify_files(
    calibration: Path,
    mode: str,
    wide: Path,
    tele: Path,
    out: Path,
    options: RectifyOptions,
    *,
    force: bool = False,
) -> dict[str, Any]:
    """Rectify one pair of image files into ``out``; returns the summary that is printed.

    Writes ``wide_rectified.png``, ``tele_rectified.png`` and ``rectification.json`` (mode,
    f_px, baseline_m, rectified cameras, rotations, options and the calibration's rig);
    earlier ones there only with ``force``.
    """
    t0 = time.perf_counter()
    require_output_folder(out, (WIDE_PNG, TELE_PNG, JSON_NAME), force=force)
    m = check_mode(mode)
    rig = load_calibration(calibration).rig
    img_w, img_t = read_gray(wide), read_gray(tele)
    rect = Rectification.from_rig(rig, m, options)
    out_w, out_t = rect.remap(img_w, img_t)
    out.mkdir(parents=True, exist_ok=True)
    write_image(out / WIDE_PNG, out_w)
    write_image(out / TELE_PNG, out_t)
    info = rect.to_dict()
    (out / JSON_NAME).write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    return {
        "mode": rect.mode,
        "f_px": rect.f_px,
        "baseline_m": rect.baseline_m,
        "size": list(rect.wide_rect.size),
        "quarter_turns": rect.quarter_turns,
        "tele_center_rect_m": info["tele_center_rect_m"],
        "wide": str(out / WIDE_PNG),
        "tele": str(out / TELE_PNG),
        "json": str(out / JSON_NAME),
        "seconds": time.perf_counter() - t0,
    }


@app.command()
def rectify(
    wide: Annotated[Path, typer.Argument(help="Raw wide image.")],
    tele: Annotated[Path, typer.Argument(help="Raw tele image.")],
    calibration: Annotated[Path, typer.Option(help="calibration.json of the module.")],
    mode: Annotated[str, typer.Option(help=f"Rectification mode: {', '.join(MODES)}.")],
    out: Annotated[Path, typer.Option(help="Output folder (created).")],
    force: Annotated[bool, flag("--force", "Overwrite earlier rectified images in --out.")] = False,
    resolution: Annotated[
        str, typer.Option(help="Rectified focal length: 'wide' (tele downscaled) or 'tele'.")
    ] = "wide",
    fov: Annotated[
        str, typer.Option(help="Window: 'shared' (the tele's view) or 'wide' (all of it).")
    ] = "shared",
    roi: Annotated[
        str | None, typer.Option(help="Window from a raw wide ROI X,Y,W,H (overrides --fov).")
    ] = None,
    margin: Annotated[int, typer.Option(help="Extra rectified pixels around the window.")] = 0,
    as_json: Annotated[bool, json_option("Print a JSON summary.")] = False,
) -> None:
    """Rectify a wide/tele pair in one of the thesis's three modes.

    tele-to-wide (§1.3.3): the tele in the wide's view, orientation and distortion, at the
    wide's scale; the wide only cropped. undistort-both (§3.2): both undistorted, the wide's
    orientation kept. canonical (§3.3): both rotated so the full baseline is the x axis.
    Disparity is then along x: d = x_wide − x_tele > 0 in front; a vertical-baseline module's
    images come out turned by 90°.
    """
    try:
        options = RectifyOptions(
            resolution=resolution,  # type: ignore[arg-type]
            fov=fov,  # type: ignore[arg-type]
            roi=_roi(roi),
            margin_px=margin,
        )
        summary = rectify_files(calibration, mode, wide, tele, out, options, force=force)
    except InputError as exc:
        raise error_exit(exc) from exc
    if as_json:
        typer.echo(json.dumps(summary))
        return
    table = figure_table(f"rectification ({summary['mode']}) → {out}")
    table.add_row("rectified size", "{}×{} px".format(*summary["size"]))
    table.add_row("f (eq. 4)", f"{summary['f_px']:.2f} px")
    table.add_row("B (eq. 4)", f"{summary['baseline_m'] * 1e3:.3f} mm")
    c = summary["tele_center_rect_m"]
    table.add_row(
        "tele centre, rectified",
        "({:.3f}, {:.3f}, {:.3f}) mm".format(*(round(v * 1e3, 3) + 0.0 for v in c)),
    )
    table.add_row("quarter turns", str(summary["quarter_turns"]))
    table.add_row("time", f"{summary['seconds']:.2f} s")
    Console().print(table)
    for key in ("wide", "tele", "json"):
        typer.echo(summary[key])
