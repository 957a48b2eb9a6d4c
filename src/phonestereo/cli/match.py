"""`phonestereo match`: sparse sub-pixel matches of a wide/tele pair, each with its σ (§1.2.1)."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Annotated, Any

import numpy as np
import typer
from rich.console import Console
from rich.markup import escape

from phonestereo.cli.app import app
from phonestereo.cli.widgets import error_exit, figure_table, flag, json_option
from phonestereo.errors import InputError
from phonestereo.features.keypoints import DETECTORS
from phonestereo.features.match_input import parse_roi
from phonestereo.features.matching import MatchConfig, match_rectified
from phonestereo.io import load_calibration, read_gray
from phonestereo.rectification import MODES, Rectification, check_mode


def _rectified_roi(rect: Rectification, roi: str | None, raw_size: tuple[int, int]) -> Any:
    """A raw-wide ROI → the bounding box of its rectified image, clipped to the rectified view."""
    if roi is None:
        return None
    x, y, w, h = parse_roi(roi, raw_size)
    corners = np.array([[x, y], [x + w - 1, y], [x + w - 1, y + h - 1], [x, y + h - 1]], float)
    q = rect.points_wide(corners)
    if not np.isfinite(q).all():
        raise InputError(f"--roi {roi} does not map into the rectified wide image")
    rw, rh = rect.wide_rect.size
    x0, y0 = np.floor(q.min(axis=0)).astype(int)
    x1, y1 = np.ceil(q.max(axis=0)).astype(int) + 1
    x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, rw), min(y1, rh)
    if x1 <= x0 or y1 <= y0:
        raise InputError(f"--roi {roi} falls outside the rectified (shared) view {rw}×{rh}")
    return x0, y0, x1 - x0, y1 - y0


def match_files(
    wide: Path,
    tele: Path,
    *,
    calibration: Path | None,
    rectified: bool,
    mode: str = "canonical",
    roi: str | None = None,
    max_disparity: int = 64,
    min_disparity: int = 0,
    config: MatchConfig | None = None,
) -> dict[str, Any]:
    """Match one pair of image files; returns the JSON summary that ``--json`` prints.

    ``rectified=True``: the files are already rectified (left = wide, right = tele, disparity
    along x); ``(x, y)`` are wide pixels. With ``calibration``, the pair is rectified first
    (:class:`~phonestereo.rectification.Rectification`, ``mode``); ``(x, y)``, ``d`` and ``e``
    are then in rectified wide pixels, and ``x_raw``, ``y_raw`` give the raw wide pixel.
    """
    if rectified == (calibration is not None):
        raise InputError(
            "pass exactly one of --rectified (the pair is already rectified, disparity along x) "
            "or --calibration FILE (rectify with the module's calibration first)"
        )
    t0 = time.perf_counter()
    img_w, img_t = read_gray(wide), read_gray(tele)
    rect = None
    if calibration is not None:
        rect = Rectification.from_rig(load_calibration(calibration).rig, check_mode(mode))
        raw_size = (img_w.shape[1], img_w.shape[0])
        roi_px = _rectified_roi(rect, roi, raw_size)
        img_w, img_t = rect.remap(img_w, img_t)
    else:
        roi_px = roi
    res = match_rectified(
        img_w,
        img_t,
        max_disparity=max_disparity,
        min_disparity=min_disparity,
        roi=roi_px,
        config=config,
    )
    out = res.to_dict()
    if rect is not None and len(res):
        raw = rect.unrectify_wide(res.xy)
        for m, (xr, yr) in zip(out["matches"], raw.tolist(), strict=True):
            m["x_raw"], m["y_raw"] = round(xr, 4), round(yr, 4)
    out["frame"] = "rectified" if rect is not None else "input"
    out["seconds"] = round(time.perf_counter() - t0, 4)
    out["match_seconds"] = round(res.seconds, 4)
    return out


@app.command()
def match(
    wide: Annotated[Path, typer.Argument(help="Wide (left) image.")],
    tele: Annotated[Path, typer.Argument(help="Tele (right) image.")],
    calibration: Annotated[
        Path | None, typer.Option(help="calibration.json: rectify the raw pair first.")
    ] = None,
    rectified: Annotated[
        bool, flag("--rectified", "The pair is already rectified (disparity on x).")
    ] = False,
    mode: Annotated[
        str, typer.Option(help=f"Rectification mode with --calibration: {', '.join(MODES)}.")
    ] = "canonical",
    roi: Annotated[
        str | None, typer.Option(help="Wide-image region X,Y,W,H whose features are matched.")
    ] = None,
    max_disparity: Annotated[int, typer.Option(help="Largest disparity searched, px.")] = 64,
    min_disparity: Annotated[int, typer.Option(help="Smallest disparity searched, px.")] = 0,
    detector: Annotated[str, typer.Option(help=f"Keypoints: {', '.join(DETECTORS)}.")] = "dog",
    max_keypoints: Annotated[
        int | None,
        typer.Option(
            help=f"Keypoints searched at most (default {MatchConfig.max_keypoints}; "
            f"{MatchConfig.fast().max_keypoints} with --fast)."
        ),
    ] = None,
    fast: Annotated[
        bool, flag("--fast", "Speed preset: fewer keypoints, translation-only fit.")
    ] = False,
    as_json: Annotated[bool, json_option("Print the matches as JSON.")] = False,
) -> None:
    """Sparse sub-pixel matching: DoG keypoints, NCC along the row, 2-D Lucas–Kanade.

    Prints {"matches": [{"x", "y", "d", "e", "sigma_d", ...}], "seconds": ...} with --json,
    where d = x_wide − x_tele (positive in front), e = y_wide − y_tele and sigma_d is the
    Cramér–Rao 1-σ of d from the image gradients and noise.
    """
    console = Console(stderr=True, soft_wrap=True)
    try:
        opts: dict[str, Any] = {"detector": detector}
        if max_keypoints is not None:
            opts["max_keypoints"] = max_keypoints
        cfg = MatchConfig.fast(**opts) if fast else MatchConfig(**opts)
        out = match_files(
            wide,
            tele,
            calibration=calibration,
            rectified=rectified,
            mode=mode,
            roi=roi,
            max_disparity=max_disparity,
            min_disparity=min_disparity,
            config=cfg,
        )
    except InputError as exc:
        raise error_exit(exc) from exc
    if as_json:
        typer.echo(json.dumps(out))
        return
    ms = out["matches"]
    table = figure_table(f"matches {wide.name} ↔ {tele.name} ({out['frame']} pixels)")
    for stage, n in out["counts"].items():
        table.add_row(f"after {stage}", str(n))
    if ms:
        d = np.array([m["d"] for m in ms])
        sd = np.array([m["sigma_d"] for m in ms])
        e = np.array([m["e"] for m in ms])
        table.add_row("disparity d", f"{np.median(d):.3f} px (range {d.min():.2f} … {d.max():.2f})")
        table.add_row("median σ_d", f"{np.median(sd):.4f} px")
        table.add_row("non-disparity e", f"{np.median(e):+.3f} px (median)")
    table.add_row("noise σ (wide, tele)", "{:.2f}, {:.2f} DN".format(*out["noise_sigma"]))
    table.add_row("time", f"{out['seconds']:.3f} s")
    Console().print(table)
    if out["reason"]:
        console.print(f"[yellow]{escape(out['reason'])}[/yellow]")
