"""Write a planned scenario as a capture set: images, manifest, factory calibration, ground truth.

The folder is what a phone app plus a factory would give (DESIGN §4)::

    OUT/manifest.json         captures (only what the module reports)
    OUT/calibration.json      the imperfect factory calibration
    OUT/images/<id>_wide.png  8-bit grey images
    OUT/images/<id>_tele.png
    OUT/ground_truth.json     sim only: read by evaluation/, never by the pipeline

Every byte is a function of (scenario, module, seed, config): images are rendered with their
own random stream per capture and written as PNG with fixed settings; the JSON files are
written with sorted, ``repr``-exact numbers.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from phonestereo.errors import InputError
from phonestereo.io import save_calibration, write_image, write_manifest
from phonestereo.sim.capture import render_capture
from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, write_ground_truth
from phonestereo.sim.plan import STREAM_RENDER, Plan, stream

IMAGE_DIR = "images"
Progress = Callable[[int, int, str], None]


@dataclass(frozen=True)
class WriteResult:
    """What was written: the folder, number of captures, and whether images were rendered."""

    folder: Path
    captures: int
    rendered: bool
    files: tuple[str, ...]


def write_capture_set(
    out_dir: str | os.PathLike[str],
    plan: Plan,
    *,
    render: bool = True,
    progress: Progress | None = None,
) -> WriteResult:
    """Render and write a planned scenario as a capture set.

    Parameters
    ----------
    out_dir : path
        Output folder (created; existing files of the same names are overwritten).
    plan : Plan
        From :func:`phonestereo.sim.scenarios.plan_scenario`.
    render : bool
        False writes the JSON files only (fast; images are then missing).
    progress : callable, optional
        Called as ``progress(done, total, capture_id)`` after each capture.

    Returns
    -------
    WriteResult
    """
    folder = Path(out_dir)
    if folder.exists() and not folder.is_dir():
        raise InputError(f"output {folder} exists and is not a folder; choose another --out")
    (folder / IMAGE_DIR).mkdir(parents=True, exist_ok=True)
    manifest = plan.manifest(IMAGE_DIR)
    files: list[str] = []
    total = len(plan.captures)
    for pc, entry in zip(plan.captures, manifest.captures, strict=True):
        if render:
            rng = stream(plan.seed, plan.scenario, STREAM_RENDER, pc.index)
            wide, tele = render_capture(plan.module, pc.state, pc.scene, rng)
            write_image(folder / entry.wide, wide)
            write_image(folder / entry.tele, tele)
            files += [entry.wide, entry.tele]
        if progress is not None:
            progress(pc.index + 1, total, pc.state.id)
    save_calibration(folder / manifest.calibration, plan.calibration)
    write_manifest(folder, manifest)
    write_ground_truth(folder / GROUND_TRUTH_NAME, plan.ground_truth())
    files += [manifest.calibration, "manifest.json", GROUND_TRUTH_NAME]
    return WriteResult(folder, total, render, tuple(files))
