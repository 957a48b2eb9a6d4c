"""Residual plots of a calibration (thesis §1.3.2; issue #3 "residual plots").

One figure per camera, two panels:

- **residual vectors over the image**: an arrow from every observed corner along its
  residual (predicted − observed), magnified so the larger ones are visible; inliers blue,
  the points the iterative rejection dropped red; a key arrow gives the scale in pixels and a
  cross marks the principal point. A good model leaves random arrows; a pattern (swirls,
  arrows that grow towards the corners) is model error — e.g. an even-only radial model on a
  lens with odd terms (thesis §3.2, Figure 3-6).
- **residual vs radius**: residual norm against the distance from the principal point, with
  the inlier RMS per radius bin; model error shows as a trend with radius.

Matplotlib's object API on the Agg canvas (no pyplot state, safe in threads and tests).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from phonestereo.calibration.result import CalibrationResult
from phonestereo.errors import InputError

INLIER_COLOR = "tab:blue"
OUTLIER_COLOR = "tab:red"
#: Arrows are magnified so that the 95th-percentile inlier residual spans this image fraction.
ARROW_FRACTION = 0.04
#: Longer residuals (gross outliers) are drawn capped at this many 95th-percentile inliers.
CAP_TYPICAL = 4.0


def camera_names(result: CalibrationResult) -> tuple[str, ...]:
    """``("wide", "tele")`` for a stereo result, ``("camera",)`` for a mono one."""
    return ("wide", "tele") if len(result.cameras) == 2 else ("camera",)


def _nice(value: float) -> float:
    """The 1-2-5 number nearest below ``value`` (> 0), for the key arrow."""
    exp = np.floor(np.log10(value))
    base = value / 10**exp
    step = 5.0 if base >= 5 else 2.0 if base >= 2 else 1.0
    return float(step * 10**exp)


def _rms(r: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1)))) if len(r) else float("nan")


def residual_figure(result: CalibrationResult, camera: int = 0) -> Figure:
    """The two residual panels of one camera of a calibration.

    Parameters
    ----------
    result : CalibrationResult
        A mono or stereo calibration.
    camera : int
        0 (wide or mono) or 1 (tele).

    Returns
    -------
    matplotlib.figure.Figure
        Axes 0: residual vectors over the image (pixels, y down); axes 1: residual norm vs
        radius from the principal point (pixels).
    """
    names = camera_names(result)
    if not 0 <= camera < len(names):
        raise InputError(f"camera must be 0..{len(names) - 1} for this calibration, got {camera}")
    cam = result.cameras[camera]
    sel = result.camera_index == camera
    q = result.image_points[sel]
    r = result.residuals[sel]
    inl = result.inliers[sel]
    norm = np.linalg.norm(r, axis=1)
    w, h = cam.size
    fig = Figure(figsize=(13.0, 5.2), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax_q, ax_r = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1.25, 1.0]})
    typical = float(np.percentile(norm[inl], 95)) if inl.any() else 1.0
    typical = typical if typical > 0 else 1.0
    gain = ARROW_FRACTION * w / typical
    # Gross outliers would cross the whole image: their arrows are capped (direction kept).
    cap = CAP_TYPICAL * typical
    shown = r * np.minimum(1.0, cap / np.maximum(norm, 1e-300))[:, None]
    for mask, color, label in ((inl, INLIER_COLOR, "inliers"), (~inl, OUTLIER_COLOR, "outliers")):
        if not mask.any():
            continue
        if label == "outliers" and (norm[mask] > cap).any():
            label += f", arrows capped at {cap:.2g} px"
        ax_q.quiver(
            q[mask, 0], q[mask, 1], shown[mask, 0], shown[mask, 1],
            color=color, angles="xy", scale_units="xy", scale=1.0 / gain, width=0.0022,
            label=f"{label} ({int(mask.sum())})",
        )
    key = _nice(typical)
    if ax_q.collections:
        ax_q.quiverkey(
            ax_q.collections[0], 0.05, 0.05, key, f"{key:g} px", labelpos="E", coordinates="axes"
        )
    ax_q.plot([cam.cx], [cam.cy], "k+", markersize=12, label="principal point")
    ax_q.set_xlim(-0.5, w - 0.5)
    ax_q.set_ylim(h - 0.5, -0.5)  # image convention: y down
    ax_q.set_aspect("equal")
    ax_q.set_xlabel("x [px]")
    ax_q.set_ylabel("y [px]")
    ax_q.set_title(f"{names[camera]}: residual vectors, predicted − observed (×{gain:.0f})")
    ax_q.legend(loc="lower right", fontsize=8)
    radius = np.hypot(q[:, 0] - cam.cx, q[:, 1] - cam.cy)
    ax_r.scatter(radius[inl], norm[inl], s=6, color=INLIER_COLOR, alpha=0.5, label="inliers")
    top = 1.15 * max(float(norm[inl].max()) if inl.any() else 0.0, CAP_TYPICAL * typical)
    far = ~inl & (norm > top)
    near = ~inl & ~far
    if near.any():
        ax_r.scatter(
            radius[near], norm[near], s=24, color=OUTLIER_COLOR, marker="x", label="outliers"
        )
    if far.any():
        ax_r.scatter(
            radius[far], np.full(int(far.sum()), top), s=30, color=OUTLIER_COLOR, marker="^",
            clip_on=False, label=f"outliers beyond {top:.2g} px",
        )
    if inl.sum() >= 2:
        edges = np.linspace(0.0, float(radius.max()) * 1.0001, 13)
        which = np.digitize(radius[inl], edges) - 1
        mid, rms = [], []
        for b in range(len(edges) - 1):
            rb = r[inl][which == b]
            if len(rb) >= 3:
                mid.append(0.5 * (edges[b] + edges[b + 1]))
                rms.append(_rms(rb))
        ax_r.plot(mid, rms, "k.-", label="inlier RMS per radius bin")
    ax_r.set_xlabel("radius from the principal point [px]")
    ax_r.set_ylabel("|residual| [px]")
    ax_r.set_title(f"{names[camera]}: residual vs radius")
    ax_r.set_xlim(left=0)
    ax_r.set_ylim(0, top)
    ax_r.legend(loc="best", fontsize=8)
    n_out = int((~inl).sum())
    fig.suptitle(
        f"{names[camera]} ({cam.lens.name}): RMS {_rms(r[inl]):.4f} px per point (OpenCV), "
        f"{float(np.sqrt(np.mean(r[inl] ** 2))) if inl.any() else float('nan'):.4f} px per "
        f"coordinate (mrcal); {n_out} of {len(inl)} points rejected as outliers"
    )
    return fig


def write_residual_plots(
    result: CalibrationResult,
    out_dir: str | os.PathLike[str],
    *,
    dpi: int = 100,
    names: Sequence[str] | None = None,
) -> list[Path]:
    """Write ``residuals_<camera>.png`` for every camera of a calibration.

    Parameters
    ----------
    result : CalibrationResult
    out_dir : path
        Folder (created).
    dpi : int
        Resolution of the PNGs (the figure is 13 × 5.2 inches).
    names : sequence of str, optional
        File-name stems instead of ``wide``/``tele``/``camera``.

    Returns
    -------
    list of Path
        The files written, one per camera.
    """
    stems = list(names) if names is not None else list(camera_names(result))
    if len(stems) != len(result.cameras):
        raise InputError(f"names needs one entry per camera ({len(result.cameras)}), got {stems}")
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--plots {folder} exists and is not a folder; choose another path")
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for c, stem in enumerate(stems):
        fig = residual_figure(result, c)
        path = folder / f"residuals_{stem}.png"
        fig.savefig(path, dpi=dpi)
        paths.append(path)
    return paths
