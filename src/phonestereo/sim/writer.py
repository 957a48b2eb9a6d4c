"""Write a planned scenario as a capture set: images, manifest, factory calibration, ground truth.

The folder is what a phone app plus a factory would give (docs/capture-set.md)::

    OUT/manifest.json         captures (only what the module reports)
    OUT/calibration.json      the imperfect factory calibration
    OUT/images/<id>_wide.jpg  the ISP's JPEG (colour, as a phone stores it); .png for the
    OUT/images/<id>_tele.jpg  linear grey path (no isp block or the ``isp`` effect off)
    OUT/ground_truth.json     sim only: read by evaluation/, never by the pipeline

Every byte is a function of (scenario, module, seed, config): images are rendered with their
own random stream per capture and written as the ISP's JPEG bytes or as PNG with fixed settings;
the JSON files are written with sorted, ``repr``-exact numbers.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from phonestereo.errors import InputError
from phonestereo.io import save_calibration, write_image, write_manifest
from phonestereo.sim.capture import render_capture_images
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


def _render_one(job: tuple[Any, ...]) -> str:
    """Render and write one capture (a process-pool job)."""
    module, state, scene, seed, scenario, index, path_wide, path_tele = job
    rng = stream(seed, scenario, STREAM_RENDER, index)
    images = render_capture_images(module, state, scene, rng)
    for path, image in zip((path_wide, path_tele), images, strict=True):
        if image.data is None:
            write_image(path, image.gray, noisy=module.effects.sensor_noise)
        else:  # the ISP's file bytes, as a phone stores them (no re-encoding)
            Path(path).parent.mkdir(parents=True, exist_ok=True)
            Path(path).write_bytes(image.data)
    return str(state.id)


def write_capture_set(
    out_dir: str | os.PathLike[str],
    plan: Plan,
    *,
    render: bool = True,
    progress: Progress | None = None,
    workers: int = 1,
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
    workers : int
        Processes rendering in parallel (each capture has its own random stream, so the bytes
        do not depend on it).

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
    jobs = [
        (plan.module, pc.state, pc.scene, plan.seed, plan.scenario, pc.index,
         str(folder / entry.wide), str(folder / entry.tele))
        for pc, entry in zip(plan.captures, manifest.captures, strict=True)
    ]
    if render:
        files += [f for entry in manifest.captures for f in (entry.wide, entry.tele)]
    if render and workers > 1:
        with ProcessPoolExecutor(max_workers=int(workers)) as pool:
            for done, cid in enumerate(pool.map(_render_one, jobs), start=1):
                if progress is not None:
                    progress(done, total, cid)
    else:
        for done, (job, pc) in enumerate(zip(jobs, plan.captures, strict=True), start=1):
            if render:
                _render_one(job)
            if progress is not None:
                progress(done, total, pc.state.id)
    save_calibration(folder / manifest.calibration, plan.calibration)
    write_manifest(folder, manifest)
    write_ground_truth(folder / GROUND_TRUTH_NAME, plan.ground_truth())
    files += [manifest.calibration, "manifest.json", GROUND_TRUTH_NAME]
    return WriteResult(folder, total, render, tuple(files))
