"""``phonestereo learn``: face captures → disparity observations in a fix store (thesis §4.1.3).

One path: :func:`phonestereo.flows.learning.run`, in face-chart or population mode.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import typer
from rich.console import Console
from rich.table import Table

from phonestereo.cli.app import app
from phonestereo.cli.flow_options import CONFIG_OPTION
from phonestereo.cli.widgets import JSON_SUMMARY, error_exit, flag, progress_bar, track
from phonestereo.errors import InputError, StoreError
from phonestereo.flows.config_file import load_flow_config
from phonestereo.flows.learning import IpdMode, LearningResult
from phonestereo.flows.learning import run as run_learning
from phonestereo.io import load_calibration, load_capture_set
from phonestereo.learning.store import FixStore


def _table(res: LearningResult, store: Path) -> Table:
    table = Table(title=f"learned into {store}")
    for col in ("capture", "faces", "W-T scale", "time (s)", "skipped because"):
        table.add_column(col)
    for c in res.captures:
        wt = c.stages.get("wt_scale") or {}
        scale = f"{wt['scale']:.5f}" if wt.get("ok") else "–"
        note = f"{c.gate}: {c.reason}" if c.gate else ""
        table.add_row(c.capture_id, str(len(c.observations)), scale, f"{c.seconds:.2f}", note)
    return table


@app.command("learn")
def learn(
    capture_set: Annotated[Path, typer.Argument(help="Capture-set folder (manifest.json).")],
    calibration: Annotated[
        Path, typer.Option("--calibration", help="calibration.json to learn on.")
    ],
    store: Annotated[
        Path, typer.Option("--store", help="Fix store (SQLite) to write; created when absent.")
    ],
    ipd_mm: Annotated[
        float, typer.Option("--ipd-mm", help="IPD of the face chart's faces, millimetres.")
    ] = 63.0,
    face_pitch_mm: Annotated[
        float,
        typer.Option(
            "--face-pitch-mm",
            help="Grid pitch of the face chart's eye midpoints (the printed chart's cell, "
            "`phonestereo chart faces`: 325 mm); it scales the chart's plane. 0: the IPDs alone "
            "(a chart of another layout).",
        ),
    ] = 325.0,
    population: Annotated[
        bool,
        flag(
            "--population",
            "Real faces of unknown IPD: use the population prior (thesis §3.6) instead.",
        ),
    ] = False,
    config: CONFIG_OPTION = None,
    new_context: Annotated[
        bool,
        flag(
            "--new-context",
            "The store was learned under another calibration or --config: keep these "
            "observations as a separate context in the same file instead of refusing.",
        ),
    ] = False,
    as_json: JSON_SUMMARY = False,
) -> None:
    """Learn disparity observations from the face captures of CAPTURE_SET into STORE.

    The learning flow of thesis Fig. 4-3/4-4, for a face chart (default, --ipd-mm) and for
    real faces (--population) alike: gates (warm-up, fixed focus, orientation), focus
    calibration of each refocus stack (when the config switches it on), faces in the wide and
    tele, depth from the IPD, disparity at the eyes, the W-T scale around the faces, one
    observation per face. Captures without usable faces are skipped with the reason.

    The store records the context (calibration, lens model, rectification mode, flow config)
    and each capture set's fingerprint: re-learning a set replaces its captures, another set
    with the same capture ids adds to them, and a store learned under another context is
    refused (naming what differs) unless --new-context. Exit code 0 when something was
    learned, 1 when nothing was, 2 on bad input.

    Example: phonestereo learn runs/learning --calibration runs/learning/calibration.json
    --store fixes.sqlite
    """
    console = Console(stderr=True, soft_wrap=True)
    try:
        cfg = load_flow_config(config)
        mode = IpdMode.population() if population else IpdMode.chart(ipd_mm, face_pitch_mm)
        cs = load_capture_set(capture_set)
        cal = load_calibration(calibration)
        with (
            FixStore(store) as fs,
            progress_bar("learning", console, field="capture", disable=as_json) as bar,
        ):
            res = run_learning(
                cfg,
                cs,
                cal,
                fs,
                ipd=mode,
                new_context=new_context,
                progress=track(bar, "learn", field="capture"),
            )
    except (InputError, StoreError) as exc:
        raise error_exit(exc) from exc
    if as_json:
        doc = {
            **res.to_dict(),
            "store": str(store),
            "config": cfg.to_dict(),
            "captures": [c.to_dict() for c in res.captures],
        }
        typer.echo(json.dumps(doc, indent=1))
    else:
        Console().print(_table(res, store))
        n_ok = sum(c.ok for c in res.captures)
        typer.echo(
            f"{res.n_observations} observation(s) from {n_ok}/{len(res.captures)} face "
            f"capture(s) in {res.seconds:.1f} s (context #{res.context_id}, set "
            f"{res.set_fingerprint})"
        )
    if res.n_observations == 0:
        raise typer.Exit(1)
