"""Batch runs: one command over many capture sets, each input a Dask task (issue #8).

``phonestereo batch COMMAND --inputs 'GLOB' --out DIR`` runs a command of :data:`COMMANDS` on
every capture-set folder the glob matches, with
:func:`~phonestereo.evaluation.runner.run_tasks`: per input one record
``DIR/inputs/<key>.json`` (the per-input log: status, reason, traceback, seconds, worker, the
result row), the command's own files in ``DIR/work/<key>/``, and one table of every input
``DIR/results.csv`` (and ``.parquet`` when pyarrow imports). A rerun skips the inputs that
finished (failed ones are retried by default); one input's failure is its record's reason and
does not stop the batch.

Commands (``--param KEY=VALUE`` sets their parameters):

``calibrate``  chessboard captures of the set → ``calibration.json`` (stereo, thesis §1.3.2);
               params ``board`` (inner corners, ``9x6``), ``square_m``, ``model``.
``learn``      face captures → a fix store ``fixes.sqlite`` on the set's factory calibration
               (thesis §4.1.3, the learning flow :func:`phonestereo.flows.learning.run`);
               params ``ipd_mm``, ``population`` (real faces: true/false) and ``config``
               (a ``--config`` FLOW.json; ``phonestereo batch --config`` sets it).
``naive``      simulated sets only: naive relative depth error of the verification captures
               from the ground truth's true pixels and the factory calibration (thesis §3).
``depth``, ``evaluate``  not available yet (they need the Phase 0 flows, issue #7).
"""

from __future__ import annotations

import glob
import hashlib
import json
import os
import re
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.evaluation.runner import Progress, run_tasks, write_table

RunFn = Callable[[Path, Path, dict[str, Any]], dict[str, Any]]


def _calibrate(folder: Path, work: Path, params: dict[str, Any]) -> dict[str, Any]:
    from phonestereo.calibration.from_images import parse_board
    from phonestereo.calibration.solve import (
        CalibrationOptions,
        calibrate_stereo,
        intrinsic_extrinsic_covariance,
    )
    from phonestereo.calibration.views import BoardView, chessboard_object_points
    from phonestereo.features.chessboard import find_chessboard
    from phonestereo.io import Calibration, load_capture_set, read_gray, save_calibration

    cs = load_capture_set(folder)
    board = parse_board(str(params["board"]))
    obj = chessboard_object_points(board, float(params["square_m"]))
    views: dict[str, list[BoardView | None]] = {"wide": [], "tele": []}
    sizes: dict[str, tuple[int, int]] = {}
    for entry in cs.captures():
        for role, path in zip(("wide", "tele"), cs.image_paths(entry.id), strict=True):
            img = read_gray(path)
            sizes[role] = (img.shape[1], img.shape[0])
            det = find_chessboard(img, board)
            view = BoardView(obj[det.ids], det.points, det.ids, str(path)) if det.found else None
            views[role].append(view)
    found = {r: sum(v is not None for v in views[r]) for r in views}
    if min(found.values()) < 1:
        raise InputError(f"chessboard {params['board']} not found in every camera: {found}")
    options = CalibrationOptions(model=str(params["model"]))
    result = calibrate_stereo(views["wide"], views["tele"], (sizes["wide"], sizes["tele"]), options)
    assert result.T_tele_wide is not None
    from phonestereo.geometry import Rig

    names, cov = intrinsic_extrinsic_covariance(result)
    rig = Rig(result.cameras[0], result.cameras[1], result.T_tele_wide)
    work.mkdir(parents=True, exist_ok=True)
    out = save_calibration(
        work / "calibration.json",
        Calibration(rig, covariance=cov, parameter_names=names, rms_px=result.rms_px_per_point),
    )
    return {
        "rms_px_per_point": result.rms_px_per_point,
        "outliers": result.n_outliers,
        # views whose residual σ differs from the others' beyond chance (weighted by their own)
        "views_own_sigma": len(result.view_sigma_ratios()),
        "views_wide": found["wide"],
        "views_tele": found["tele"],
        "wide_f_px": rig.wide.f,
        "tele_f_px": rig.tele.f,
        "baseline_mm": 1000 * rig.baseline_m,
        "calibration": str(out),
    }


def _learn(folder: Path, work: Path, params: dict[str, Any]) -> dict[str, Any]:
    from phonestereo.flows.config_file import load_flow_config
    from phonestereo.flows.learning import IpdMode, run
    from phonestereo.io import load_calibration, load_capture_set
    from phonestereo.learning.provenance import canonical_json
    from phonestereo.learning.store import FixStore

    cfg = load_flow_config(params["config"] or None)
    pop = str(params["population"]).strip().lower() in ("1", "true", "yes", "on")
    ipd = IpdMode.population() if pop else IpdMode.chart(float(params["ipd_mm"]))
    cs = load_capture_set(folder)
    cal = load_calibration(cs.calibration_path())
    work.mkdir(parents=True, exist_ok=True)
    with FixStore(work / "fixes.sqlite") as store:
        res = run(cfg, cs, cal, store, ipd=ipd)
    d = res.to_dict()
    n = max(d["n_captures"], 1)
    return {
        **{k: d[k] for k in ("n_captures", "n_learned", "n_observations", "set_fingerprint")},
        "seconds_per_capture": round(res.seconds / n, 4),
        "ipd": ipd.kind,
        "flow_config": canonical_json(cfg.to_dict()),
    }


def _naive(folder: Path, work: Path, params: dict[str, Any]) -> dict[str, Any]:
    from phonestereo.evaluation.naive import naive_relative_errors
    from phonestereo.io import load_calibration, load_capture_set
    from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

    cs = load_capture_set(folder, check_images=False)
    truth_path = folder / GROUND_TRUTH_NAME
    if not truth_path.is_file():
        raise InputError(f"{folder} has no {GROUND_TRUTH_NAME}; 'naive' needs a simulated set")
    truth = load_ground_truth(truth_path)
    cal = load_calibration(cs.calibration_path())
    caps = [c for c in truth.captures if c.kind == "verification"]
    if not caps:
        raise InputError(f"{folder} has no verification captures to measure")
    rel = np.concatenate([naive_relative_errors(c, cal) for c in caps])
    rel = rel[np.isfinite(rel)]
    return {
        "captures": len(caps),
        "points": int(rel.size),
        "median_rel_err": float(np.median(rel)) if rel.size else float("nan"),
        "p90_rel_err": float(np.percentile(rel, 90)) if rel.size else float("nan"),
    }


@dataclass(frozen=True)
class BatchCommand:
    """A batch command: ``run(capture_set, work_dir, params) -> row`` and its parameters.

    ``run`` None marks a command that is known but not available yet (``why`` says why).
    """

    name: str
    summary: str
    run: RunFn | None
    params: dict[str, Any] = field(default_factory=dict)
    why: str = ""


#: The command table: add a command by adding an entry.
COMMANDS: dict[str, BatchCommand] = {
    c.name: c
    for c in (
        BatchCommand(
            "calibrate",
            "chessboard captures → calibration.json",
            _calibrate,
            {"board": "9x6", "square_m": 0.02, "model": "opencv5"},
        ),
        BatchCommand(
            "learn",
            "face captures → fixes.sqlite",
            _learn,
            {"ipd_mm": 63.0, "population": "false", "config": ""},
        ),
        BatchCommand("naive", "naive depth error of a simulated set", _naive),
        BatchCommand("depth", "depth of the ROIs (application phase)", None, why="issue #7"),
        BatchCommand("evaluate", "full-flow error against ground truth", None, why="issue #7"),
    )
}


def get_command(name: str) -> BatchCommand:
    """The command of a name; raises InputError for unknown or not-yet-available commands."""
    if name not in COMMANDS:
        raise InputError(f"unknown batch command {name!r}; choose one of {list(COMMANDS)}")
    cmd = COMMANDS[name]
    if cmd.run is None:
        available = [c for c, v in COMMANDS.items() if v.run is not None]
        raise InputError(
            f"batch {name} is not available yet (it needs the Phase 0 flows, {cmd.why}); "
            f"available commands: {available}"
        )
    return cmd


def parse_params(cmd: BatchCommand, pairs: list[str] | dict[str, Any] | None) -> dict[str, Any]:
    """``["key=value", ...]`` (or a dict) → the command's parameters, typed like the defaults.

    >>> parse_params(COMMANDS["learn"], ["ipd_mm=61.5"])  # the rest keep their defaults
    {'ipd_mm': 61.5, 'population': 'false', 'config': ''}
    """
    given: dict[str, Any] = {}
    items = pairs.items() if isinstance(pairs, dict) else (p.split("=", 1) for p in pairs or [])
    for item in items:
        if len(item) != 2:
            raise InputError(f"--param must be KEY=VALUE, got {'='.join(item)!r}")
        key, value = item
        if key not in cmd.params:
            raise InputError(
                f"batch {cmd.name} has no parameter {key!r}; its parameters: {cmd.params}"
            )
        try:
            given[key] = type(cmd.params[key])(value)
        except (TypeError, ValueError):
            kind = type(cmd.params[key]).__name__
            raise InputError(f"--param {key}={value!r} is not a {kind}") from None
    return {**cmd.params, **given}


def input_key(folder: Path) -> str:
    """A stable, file-name-safe key of an input folder: its name and a hash of its path.

    >>> input_key(Path("/data/sets/phone 01"))[:9]
    'phone_01-'
    """
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", folder.name)[:40] or "input"
    digest = hashlib.sha1(str(folder.resolve()).encode()).hexdigest()[:8]
    return f"{name}-{digest}"


def expand_inputs(pattern: str) -> list[Path]:
    """Folders matching a glob (``**`` allowed), sorted; raises InputError when none match."""
    paths = sorted(Path(p) for p in glob.glob(os.path.expanduser(pattern), recursive=True))
    folders = [p for p in paths if p.is_dir()]
    if not folders:
        raise InputError(
            f"--inputs '{pattern}' matches no folder; quote the glob so the shell does not "
            "expand it, and point it at capture-set folders (each with a manifest.json)"
        )
    return folders


def batch_input(command: str, folder: str, work: str, params: dict[str, Any]) -> dict[str, Any]:
    """One batch task (runs on a worker): the command on one capture set."""
    cmd = get_command(command)
    assert cmd.run is not None
    return cmd.run(Path(folder), Path(work), params)


@dataclass(frozen=True)
class BatchResult:
    """A finished batch: one row per input, counts and the table files."""

    rows: tuple[dict[str, Any], ...]
    n_ok: int
    n_failed: int
    n_run: int
    seconds: float
    files: dict[str, str]


def run_batch(
    command: str,
    inputs: str | list[Path],
    out_dir: str | Path,
    params: list[str] | dict[str, Any] | None = None,
    *,
    client: Any = None,
    progress: Progress | None = None,
    retry_failed: bool = True,
) -> BatchResult:
    """Run a batch command over capture sets (resuming an earlier run in ``out_dir``).

    Parameters
    ----------
    command : str
        A key of :data:`COMMANDS`.
    inputs : str or list of Path
        A glob of capture-set folders, or the folders.
    out_dir : path
        Output folder (records, work folders, results table).
    params : list of "KEY=VALUE" or dict, optional
        The command's parameters.
    client : distributed.Client, optional
        Dask client; None runs the inputs here, one after another.
    progress : callable, optional
        ``progress(done, total, key)``.
    retry_failed : bool
        Rerun the inputs whose record says failed.

    Raises
    ------
    InputError
        Unknown or unavailable command, bad parameters, no matching input, or an out folder
        of a batch with another command or parameters — all before any work.
    """
    t0 = time.perf_counter()
    cmd = get_command(command)
    values = parse_params(cmd, params)
    folders = expand_inputs(inputs) if isinstance(inputs, str) else [Path(p) for p in inputs]
    if not folders:
        raise InputError("no inputs given; pass --inputs 'GLOB' matching capture-set folders")
    out = Path(out_dir)
    stamp = {"command": command, "params": values}
    stamp_path = out / "batch_inputs.json"
    if stamp_path.is_file() and json.loads(stamp_path.read_text()) != stamp:
        raise InputError(
            f"{out} holds a batch with another command or parameters "
            f"({stamp_path.read_text().strip()}); use a new --out folder"
        )
    out.mkdir(parents=True, exist_ok=True)
    stamp_path.write_text(json.dumps(stamp) + "\n")
    keys = {input_key(f): f for f in folders}
    tasks = {
        k: (batch_input, (command, str(f.resolve()), str(out / "work" / k), values))
        for k, f in keys.items()
    }
    records, n_run = run_tasks(
        tasks, out / "inputs", client=client, progress=progress, retry_failed=retry_failed
    )
    rows = []
    for k, rec in records.items():
        base = {"key": k, "input": str(keys[k]), "status": rec["status"], "reason": rec["reason"]}
        rows.append({**base, **(rec["result"] or {}), "seconds": rec["seconds"]})
    files = {f"results.{fmt}": p for fmt, p in write_table(rows, out / "results").items()}
    n_ok = sum(r["status"] == "ok" for r in rows)
    return BatchResult(tuple(rows), n_ok, len(rows) - n_ok, n_run, time.perf_counter() - t0, files)


__all__ = [
    "COMMANDS",
    "BatchCommand",
    "BatchResult",
    "batch_input",
    "expand_inputs",
    "get_command",
    "input_key",
    "parse_params",
    "run_batch",
]
