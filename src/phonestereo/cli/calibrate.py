"""`phonestereo calibrate`: chessboard images → calibration.json (thesis §1.3.2)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer
from rich.console import Console
from rich.progress import Progress

from phonestereo.calibration.from_images import ImageReport, calibrate_from_images, parse_board
from phonestereo.calibration.result import CalibrationResult
from phonestereo.calibration.solve import CalibrationOptions, intrinsic_extrinsic_covariance
from phonestereo.cli.app import app
from phonestereo.cli.outputs import require_output_file, require_output_folder
from phonestereo.cli.widgets import figure_table, flag, json_option
from phonestereo.errors import InputError
from phonestereo.geometry import LENS_MODELS, Rig
from phonestereo.io import Calibration, save_calibration
from phonestereo.report.calibration_plots import write_residual_plots

# A chessboard cannot tell a distortion centre from the principal point and p1, p2 (they trade
# against each other to first order), so radial-odd-centred is for imported tables only.
FIT_MODELS = tuple(m for m in LENS_MODELS if m != "radial-odd-centred")


@app.command()
def calibrate(
    board: Annotated[str, typer.Option(help="Inner corners COLSxROWS, e.g. 9x6 (10x7 squares).")],
    square_m: Annotated[
        float,
        typer.Option(help="Square side in metres (any unit works; translations come out in it)."),
    ],
    wide: Annotated[str, typer.Option(help="Quoted glob of wide (or mono) images.")],
    out: Annotated[Path, typer.Option(help="Output calibration.json.")],
    tele: Annotated[
        str | None,
        typer.Option(
            help="Quoted glob of tele images: stereo calibration, pairs matched by sorted name."
        ),
    ] = None,
    model: Annotated[str, typer.Option(help=f"Lens model: {', '.join(FIT_MODELS)}.")] = "opencv5",
    reject_outliers: Annotated[
        bool,
        typer.Option(
            help="Iterative outlier rejection (mrcal-like); RMS figures are over the kept points."
        ),
    ] = True,
    view_weights: Annotated[
        bool,
        typer.Option(
            help="Give a board view its own residual σ where it differs from the others' beyond "
            "chance (phone JPEGs: far boards' corners err several times more than near ones). "
            "--no-view-weights: every corner alike, as OpenCV solves."
        ),
    ] = True,
    as_json: Annotated[bool, json_option("Print a JSON summary.")] = False,
    plots: Annotated[
        Path | None,
        typer.Option(
            help="Folder for residual plots: per camera, residual vectors over the image "
            "(inliers / outliers) and residual vs radius (residuals_<camera>.png)."
        ),
    ] = None,
    force: Annotated[
        bool, flag("--force", "Overwrite an existing --out file (and --plots figures).")
    ] = False,
) -> None:
    """Calibrate one camera, or the wide + tele pair, from images of a plain chessboard.

    Corners: OpenCV's detector orders the board, a saddle-point fit refines every corner.
    Solve: nonlinear least squares with an analytic sparse Jacobian; RMS is reported per point
    (as OpenCV does) and per coordinate (as mrcal does), with outliers and the covariance;
    ``--plots DIR`` draws the residuals of every camera. "corner σ" is what the image noise,
    or the saddle fit's own misfit on processed images (JPEGs), predicts per corner coordinate:
    an RMS per coordinate far above it points at the lens model, the board or the images (blur,
    rolling shutter). A view whose residual σ differs from the others' beyond chance is
    weighted by its own, and named in the table (on phone-ISP renders the pooled solve rejected
    the far views' corners as outliers and read d²/P 1.31, with the weights 1.00);
    ``--no-view-weights`` weighs every corner alike, as OpenCV does.
    """
    console = Console(stderr=True)
    if model not in FIT_MODELS:
        raise typer.BadParameter(f"unknown model '{model}'; choose one of {sorted(FIT_MODELS)}")
    try:
        require_output_file(out, force=force, suffixes=(".json",))
        if plots is not None:
            stems = ("wide", "tele") if tele else ("camera",)
            pngs = [f"residuals_{stem}.png" for stem in stems]
            require_output_folder(plots, pngs, force=force, flag="--plots")
        pattern = parse_board(board)
        with Progress(console=console, transient=True, disable=as_json) as bar:
            task = bar.add_task("detecting boards", total=None)
            result, reports = calibrate_from_images(
                wide,
                tele,
                pattern,
                square_m,
                CalibrationOptions(
                    model=model, reject_outliers=reject_outliers, view_weights=view_weights
                ),
                progress=lambda _p: bar.advance(task),
            )
    except InputError as exc:
        console.print(f"[red]error:[/red] {exc}", soft_wrap=True)
        raise typer.Exit(2) from exc
    out.parent.mkdir(parents=True, exist_ok=True)
    names, cov = intrinsic_extrinsic_covariance(result)
    if result.T_tele_wide is not None:
        rig = Rig(result.cameras[0], result.cameras[1], result.T_tele_wide)
        save_calibration(
            out,
            Calibration(rig, covariance=cov, parameter_names=names, rms_px=result.rms_px_per_point),
        )
    else:
        out.write_text(
            json.dumps(
                {
                    "camera": result.cameras[0].to_dict(),
                    "rms_px": result.rms_px_per_point,
                    "std": {n: result.std[n] for n in names},
                },
                indent=2,
            )
            + "\n"
        )
    plot_paths: list[str] = []
    if plots is not None:
        try:
            plot_paths = [str(p) for p in write_residual_plots(result, plots)]
        except InputError as exc:
            console.print(f"[red]error:[/red] {exc}", soft_wrap=True)
            raise typer.Exit(2) from exc
    corner_sigma = _corner_sigma(reports)
    own_sigma = _views_with_own_sigma(result, reports)
    summary = {
        "rms_px_per_point": result.rms_px_per_point,
        "rms_px_per_coordinate": result.rms_px_per_coordinate,
        "outliers": result.n_outliers,
        "points": int(result.inliers.size),
        "seconds": result.seconds,
        "views_used": sum(r.found for r in reports),
        "images": len(reports),
        "cameras": [c.to_dict() for c in result.cameras],
        "T_tele_wide": result.T_tele_wide.to_dict() if result.T_tele_wide else None,
        "std": {n: result.std[n] for n in names},
        "corner_sigma_px": corner_sigma,
        "views_own_sigma": own_sigma,
        "baseline": None
        if result.T_tele_wide is None
        else dict(zip(("norm", "std"), result.baseline(), strict=True)),
        "out": str(out),
        "plots": plot_paths,
    }
    if as_json:
        typer.echo(json.dumps(summary))
        return
    table = figure_table(f"calibration ({model}) → {out}")
    table.add_row("boards found", f"{summary['views_used']} / {summary['images']} images")
    table.add_row("RMS per point (OpenCV)", f"{result.rms_px_per_point:.4f} px")
    table.add_row("RMS per coordinate (mrcal)", f"{result.rms_px_per_coordinate:.4f} px")
    table.add_row("outliers", f"{result.n_outliers} of {result.inliers.size}")
    sig = ", ".join(f"{k} {v:.4f}" for k, v in corner_sigma.items())
    table.add_row("corner σ (noise or misfit)", f"{sig} px (median)")
    if own_sigma:
        worst = sorted(own_sigma, key=lambda v: -abs(np.log(v["sigma_ratio"])))[:4]
        listed = ", ".join(f"{Path(v['image']).name} ×{v['sigma_ratio']:.1f}" for v in worst)
        more = f", +{len(own_sigma) - len(worst)} more" if len(own_sigma) > len(worst) else ""
        table.add_row("views with their own σ", f"{len(own_sigma)}: {listed}{more}")
    for c, cam in enumerate(result.cameras):
        who = ("wide", "tele")[c] if len(result.cameras) == 2 else "camera"
        sd = result.std
        table.add_row(f"{who} f", f"{cam.fx:.2f}, {cam.fy:.2f} ± {sd[f'{who}.fx']:.2f} px")
        table.add_row(f"{who} c", f"{cam.cx:.2f}, {cam.cy:.2f} ± {sd[f'{who}.cx']:.2f} px")
    if result.T_tele_wide is not None:
        norm, sd_norm = result.baseline()
        t = ", ".join(f"{v:+.4f}" for v in result.T_tele_wide.t)
        table.add_row("baseline |t|", f"{norm:.4f} ± {sd_norm:.4f} (unit of --square-m)")
        table.add_row("t (tele ← wide)", f"({t})")
    table.add_row("solve time", f"{result.seconds:.2f} s")
    for path in plot_paths:
        table.add_row("residual plot", path)
    Console().print(table)
    for r in reports:
        if not r.found:
            console.print(f"[yellow]skipped[/yellow] {r.path}: {r.reason}")


def _views_with_own_sigma(result: CalibrationResult, reports: list[ImageReport]) -> list[dict]:
    """The views whose residual σ differs from the others' beyond chance: image, camera, and
    σ_view / σ_pooled (stereo views are pairs in sorted-name order, mono ones the found images)."""
    stereo = result.T_tele_wide is not None
    by_camera = {
        cam: [r for r in reports if r.camera == cam and (stereo or r.found)]
        for cam in ("wide", "tele")
    }
    out = []
    for (c, v), ratio in sorted(result.view_sigma_ratios().items()):
        cam = ("wide", "tele")[c] if stereo else "wide"
        label = cam if stereo else "camera"  # mono: named as in the rest of the table
        out.append({"image": by_camera[cam][v].path, "camera": label, "sigma_ratio": ratio})
    return out


def _corner_sigma(reports: list[ImageReport]) -> dict[str, float]:
    """Median predicted corner σ per camera over the images with a board, px per coordinate."""
    out: dict[str, float] = {}
    for cam in ("wide", "tele"):
        vals = [r.corner_sigma_px for r in reports if r.camera == cam and r.found]
        if vals:
            out[cam] = float(np.median(vals))
    if not any(r.camera == "tele" for r in reports) and "wide" in out:
        out = {"camera": out["wide"]}  # mono: named as in the rest of the table
    return out
