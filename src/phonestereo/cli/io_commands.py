"""`phonestereo check-set` and `phonestereo convert-calibration`: the files of docs/capture-set.md
and docs/calibration.md."""

from __future__ import annotations

import json
from collections import Counter
from pathlib import Path
from typing import Annotated, Any

import typer

from phonestereo.cli.app import app
from phonestereo.cli.outputs import require_output_file
from phonestereo.cli.widgets import error_exit, flag, json_option
from phonestereo.errors import InputError
from phonestereo.geometry.transform import SNAP_TOLERANCE, orthonormality_error
from phonestereo.io import (
    Calibration,
    export_opencv_yaml,
    load_calibration,
    load_capture_set,
    read_gray,
    save_calibration,
)
from phonestereo.io.images import image_size, size_mismatch
from phonestereo.io.opencv_yaml import read_opencv_yaml

_YAML = (".yml", ".yaml", ".xml")
_JSON = (".json",)


def _size(text: str | None, name: str) -> tuple[int, int] | None:
    if text is None:
        return None
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError as exc:
        raise typer.BadParameter(f"{name} must be WIDTHxHEIGHT, e.g. 640x480") from exc
    return w, h


def calibration_summary(cal: Calibration) -> dict[str, Any]:
    """The numbers an engineer checks first: focal lengths, zoom, baseline, conditions."""
    rig = cal.rig
    return {
        "wide": {"size": list(rig.wide.size), "f_px": rig.wide.f, "lens": rig.wide.lens.name},
        "tele": {"size": list(rig.tele.size), "f_px": rig.tele.f, "lens": rig.tele.lens.name},
        "zoom": rig.zoom,
        "baseline_m": rig.baseline_m,
        "t_m": rig.T_tele_wide.t.tolist(),
        "rms_px": cal.rms_px,
        "focus_distance_m": cal.conditions.focus_distance_m,
        "has_covariance": cal.covariance is not None,
    }


@app.command("check-set")
def check_set(
    folder: Annotated[Path, typer.Argument(help="Capture-set folder (with manifest.json).")],
    decode: Annotated[
        bool,
        typer.Option(
            help="Also decode every image (without it, only each image's header is read: "
            "format and size)."
        ),
    ] = False,
    as_json: Annotated[bool, json_option("Print a JSON summary.")] = False,
) -> None:
    """Validate a capture set: manifest fields, image and calibration files (docs/capture-set.md).

    Every image's size is checked against the calibration's: from its header, or from the
    decoded pixels with --decode (which also finds truncated files).
    """
    try:
        cs = load_capture_set(folder)
        cal = load_calibration(cs.calibration_path())
        sizes = {"wide": cal.rig.wide.size, "tele": cal.rig.tele.size}
        for c in cs.captures():
            for cam, path in zip(("wide", "tele"), cs.image_paths(c.id), strict=True):
                if decode:
                    h, w = read_gray(path).shape
                else:
                    w, h = image_size(path)
                what = f"capture '{c.id}' {cam} image '{path}'"
                problem = size_mismatch((w, h), sizes[cam], what, cam)
                if problem:
                    raise InputError(problem)
    except InputError as exc:
        raise error_exit(exc) from exc
    caps = cs.captures()
    times = [c.time_s for c in caps if c.time_s is not None]
    summary: dict[str, Any] = {
        "folder": str(cs.root),
        "captures": len(caps),
        "kinds": dict(sorted(Counter(c.kind for c in caps).items())),
        "focus_groups": sorted({c.focus_group for c in caps if c.focus_group}),
        "with_temperature": sum(c.temperature_c is not None for c in caps),
        "time_s": [min(times), max(times)] if times else [],
        "without_time_s": len(caps) - len(times),
        "focus_mode_unknown": sum(c.focus_mode == "unknown" for c in caps),
        "images_decoded": decode,
        "calibration": calibration_summary(cal),
    }
    if as_json:
        typer.echo(json.dumps(summary, indent=1))
        return
    cal_s = summary["calibration"]
    typer.echo(
        f"ok: {len(caps)} captures {summary['kinds']}, {len(summary['focus_groups'])} focus "
        f"groups; calibration f = {cal_s['wide']['f_px']:.1f} / {cal_s['tele']['f_px']:.1f} px "
        f"(×{cal_s['zoom']:.2f}), baseline {cal_s['baseline_m'] * 1000:.2f} mm"
    )


@app.command("convert-calibration")
def convert_calibration(
    src: Annotated[Path, typer.Argument(help="calibration.json or OpenCV .yml/.yaml/.xml.")],
    dst: Annotated[Path, typer.Argument(help="Output: .json, or .yml/.yaml/.xml for OpenCV.")],
    extrinsics: Annotated[
        Path | None, typer.Option(help="OpenCV extrinsics.yml (R, T) when SRC holds M1..D2.")
    ] = None,
    wide_size: Annotated[str | None, typer.Option(help="Wide image WIDTHxHEIGHT.")] = None,
    tele_size: Annotated[str | None, typer.Option(help="Tele image WIDTHxHEIGHT.")] = None,
    t_unit_m: Annotated[
        float, typer.Option(help="Metres per unit of OpenCV's T (e.g. the square size).")
    ] = 1.0,
    first_camera: Annotated[
        str, typer.Option(help="Which camera is OpenCV's camera 1: wide or tele.")
    ] = "wide",
    as_json: Annotated[
        bool, json_option("Print what was written and what was changed as JSON.")
    ] = False,
    force: Annotated[bool, flag("--force", "Overwrite an existing DST file.")] = False,
) -> None:
    """Convert a calibration between phonestereo JSON and OpenCV FileStorage YAML.

    An R printed with 6–9 digits (orthonormal only to ~1e-8) is replaced by the nearest
    rotation; the command says so on stderr (and in --json: r_reorthonormalised, r_deviation).
    """
    if first_camera not in ("wide", "tele"):
        raise typer.BadParameter("--first-camera must be 'wide' or 'tele'")
    try:
        if dst.suffix.lower() not in _YAML + _JSON:
            raise InputError(
                f"cannot tell the output format of '{dst}' from its suffix "
                f"'{dst.suffix}': name it .json (phonestereo calibration) or .yml/.yaml/.xml "
                "(OpenCV FileStorage)"
            )
        require_output_file(dst, force=force, flag="DST")
        if src.suffix.lower() in _YAML:
            imported = read_opencv_yaml(
                src,
                extrinsics,
                wide_size=_size(wide_size, "--wide-size"),
                tele_size=_size(tele_size, "--tele-size"),
                t_unit_m=t_unit_m,
                first_camera="wide" if first_camera == "wide" else "tele",
            )
            cal, r_dev = imported.calibration, imported.r_deviation
        else:
            cal = load_calibration(src)
            r_dev = _json_r_deviation(src)
        out = (
            export_opencv_yaml(dst, cal)
            if dst.suffix.lower() in _YAML
            else save_calibration(dst, cal)
        )
    except InputError as exc:
        raise error_exit(exc) from exc
    c = calibration_summary(cal)
    snapped = r_dev > SNAP_TOLERANCE
    r_file = (extrinsics or src).name if src.suffix.lower() in _YAML else src.name
    if as_json:
        doc = {
            "wrote": str(out),
            "r_reorthonormalised": snapped,
            "r_deviation": r_dev,
            **c,
        }
        typer.echo(json.dumps(doc, indent=1))
    else:
        typer.echo(
            f"wrote {out} (baseline {c['baseline_m'] * 1000:.3f} mm, zoom ×{c['zoom']:.3f})"
        )
    if snapped:
        typer.echo(
            f"note: R was orthonormal only to {r_dev:.2g} (max |R·Rᵀ − I| as written in "
            f"{r_file}); it was replaced by the nearest rotation (SVD)",
            err=True,
        )


def _json_r_deviation(path: Path) -> float:
    """max |R·Rᵀ − I| of T_tele_wide.R as written in a (valid) calibration.json."""
    data = json.loads(path.read_text(encoding="utf-8"))
    return orthonormality_error(data["T_tele_wide"]["R"])
