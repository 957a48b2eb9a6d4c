"""The thesis bench (docs/architecture.md): learn on faces, apply on verification captures, score.

For a capture set with face and verification captures (``phonestereo simulate thesis-bench``
or a user's own set with ``ground_truth.json``), :func:`run_bench`

1. learns with the learning flow (:mod:`phonestereo.flows.learning`) into a store (or memory);
2. runs the application flow (:mod:`phonestereo.flows.application`) on every verification
   capture;
3. scores each stage against the ground truth's ROI depth: ``naive`` (Z = f·B/d at the true
   chart corners with the factory calibration — the thesis's ~30 %), ``measured`` (the
   application's measuring blocks — canonical rectification, focus fix, W-T scale — without
   the learned correction), ``full`` (the whole flow), and the Cramér–Rao floor (the matching
   bound alone, σ_d/d);
4. optionally repeats learning + application with each fix switched off (the ablation table).

Ground truth is read here only (evaluation layer), never by the flows.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.evaluation.summary import score_capture_set
from phonestereo.features.landmarks import LandmarkBackend
from phonestereo.flows import application, learning
from phonestereo.flows.config import FIXES, LOOKUPS, FlowConfig
from phonestereo.flows.corrector import Corrector
from phonestereo.flows.learning import CachedBackend, default_backend, stack_corrections
from phonestereo.flows.roi_disparity import reference_rectification
from phonestereo.io import CaptureSet, load_calibration, load_capture_set, read_gray
from phonestereo.learning.store import FixStore
from phonestereo.learning.store_radial import radial_fits
from phonestereo.sim.ground_truth import GROUND_TRUTH_NAME, load_ground_truth

Progress = Callable[[str, int, int], None]


def _stats(errors: Any) -> dict[str, Any]:
    e = np.abs(np.asarray(errors, dtype=np.float64))
    e = e[np.isfinite(e)]
    if e.size == 0:
        return {"median_rel_err": None, "p90_rel_err": None, "n": 0}
    return {"median_rel_err": round(float(np.median(e)), 6),
            "p90_rel_err": round(float(np.percentile(e, 90)), 6), "n": int(e.size)}


def apply_all(
    config: FlowConfig,
    cs: CaptureSet,
    corrector: Corrector | None,
    *,
    progress: Callable[[int, int], None] | None = None,
) -> list[application.DepthResult]:
    """The application phase on every verification capture of ``cs`` (with focus stacks)."""
    cal = load_calibration(cs.calibration_path())
    ver = [c for c in cs.captures() if c.kind == "verification"]
    focus = stack_corrections(config, cs, ver, cal)
    ref = reference_rectification(cal.rig, config.mode)
    out = []
    for i, c in enumerate(ver):
        w, t = (read_gray(p) for p in cs.image_paths(c.id))
        inputs = application.ApplicationInputs(
            cal, c, w, t, corrector, focus=focus.get(c.id), reference=ref
        )
        out.append(application.run(config, inputs))
        if progress is not None:
            progress(i + 1, len(ver))
    return out


def _rows(cs: CaptureSet, results: Sequence[application.DepthResult]) -> list[dict[str, Any]]:
    gt = load_ground_truth(cs.root / GROUND_TRUTH_NAME)
    rows = []
    for r in results:
        z_true = gt.capture(r.capture_id).roi_depth_m
        row = {"capture_id": r.capture_id, "ok": r.ok, "gate": r.gate, "reason": r.reason,
               "z_true_m": z_true, "depth_m": r.depth_m, "sigma_m": r.sigma_m,
               "depth_uncorrected_m": r.depth_uncorrected_m, "seconds": r.seconds}
        if z_true is not None and r.ok:
            row["rel_err"] = r.depth_m / z_true - 1
            row["rel_err_measured"] = r.depth_uncorrected_m / z_true - 1
            row["within_sigma"] = bool(abs(r.depth_m - z_true) <= r.sigma_m)
            sig = r.stages.get("sigma_px", {})
            d = r.disparity_fixed_px
            row["crlb_rel"] = float(sig.get("matching", np.nan)) / d if d > 0 else np.nan
        rows.append(row)
    return rows


def _score(rows: list[dict[str, Any]]) -> dict[str, Any]:
    ok = [r for r in rows if "rel_err" in r]
    return {
        "measured": _stats([r["rel_err_measured"] for r in ok]),
        "full": _stats([r["rel_err"] for r in ok]),
        "cramer_rao_floor": _stats([r["crlb_rel"] for r in ok]),
        "within_sigma": round(float(np.mean([r["within_sigma"] for r in ok])), 4) if ok else None,
        "gated": len(rows) - len(ok),
    }


def learn_and_apply(
    config: FlowConfig,
    cs: CaptureSet,
    backend: LandmarkBackend,
    *,
    store: FixStore | None = None,
    progress: Progress | None = None,
) -> tuple[learning.LearningResult, list[application.DepthResult]]:
    """Learning flow then application flow on one capture set."""
    cal = load_calibration(cs.calibration_path())
    lr = learning.run(
        config, cs, cal, store, backend=backend,
        progress=None if progress is None else (lambda k, n, _id: progress("learning", k, n)),
    )
    obs = (
        store.observations(context_id=lr.context_id)  # only this calibration's and config's
        if store is not None
        else [o for c in lr.captures for o in c.observations]
    )
    radial = (
        radial_fits(store, lr.context_id) if store is not None else [c.radial for c in lr.captures]
    )
    corrector = (
        Corrector.for_calibration(obs, config, cal, radial_fits=radial)
        if len(obs) else None
    )
    res = apply_all(
        config, cs, corrector,
        progress=None if progress is None else (lambda k, n: progress("application", k, n)),
    )
    return lr, res


def run_bench(
    capture_set: str | Path | CaptureSet,
    config: FlowConfig | None = None,
    *,
    ablations: bool = False,
    lookups: bool = False,
    backend: LandmarkBackend | None = None,
    store_path: str | Path | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Run and score the thesis bench on a capture set (module docstring).

    Parameters
    ----------
    capture_set : path or CaptureSet
        With face and verification captures and a ``ground_truth.json``.
    config : FlowConfig
    ablations : bool
        Also re-run with each fix of :data:`~phonestereo.flows.config.FIXES` off.
    lookups : bool
        Also apply the same learned observations with every lookup strategy (Figure 3-31's
        nearest, mean, max, min, centre beside the smooth field).
    backend : LandmarkBackend
        Default MediaPipe (cached across the ablation runs).
    store_path : path, optional
        Fix store to learn into (default: observations kept in memory).
    progress : callable, optional
        ``progress(stage, done, total)``.

    Raises
    ------
    InputError
        No ground truth, no face or no verification captures.
    """
    t0 = time.perf_counter()
    cfg = config or FlowConfig()
    cs = capture_set if isinstance(capture_set, CaptureSet) else load_capture_set(capture_set)
    if not (cs.root / GROUND_TRUTH_NAME).is_file():
        raise InputError(
            f"{cs.root} has no {GROUND_TRUTH_NAME}: the bench scores against ground truth "
            "(simulate one with `phonestereo simulate thesis-bench`); use `phonestereo depth` "
            "on captures without it"
        )
    kinds = {c.kind for c in cs.captures()}
    missing = [k for k in ("face", "verification") if k not in kinds]
    if missing:
        raise InputError(f"the bench needs 'face' and 'verification' captures; {cs.root} has no "
                         f"{' or '.join(repr(k) for k in missing)} captures")
    det = CachedBackend(backend if backend is not None else default_backend())
    store = FixStore(store_path) if store_path is not None else None
    try:
        lr, res = learn_and_apply(cfg, cs, det, store=store, progress=progress)
    finally:
        if store is not None:
            store.close()
    rows = _rows(cs, res)
    naive = score_capture_set(cs.root)
    out: dict[str, Any] = {
        "capture_set": str(cs.root), "config": cfg.to_dict(),
        "stages": {"naive": _stats_from_naive(naive), **_score(rows)},
        "learning": lr.to_dict(), "captures": rows,
        "per_distance": _per_distance(rows, naive),
    }
    n_faces = max(len(lr.captures), 1)
    out["timing"] = {
        "learn_s_per_capture": round(lr.seconds / n_faces, 4),
        "apply_s_per_capture": round(float(np.median([r.seconds for r in res])), 4),
    }
    if ablations:
        table = []
        for i, fix in enumerate(FIXES):
            if progress is not None:
                progress("ablation", i, len(FIXES))
            _, res_off = learn_and_apply(cfg.toggled(fix), cs, det)
            sc = _score(_rows(cs, res_off))
            label = f"without {fix}" if getattr(cfg, fix) else f"with {fix}"
            table.append({"without": label, **sc["full"], "gated": sc["gated"],
                          "within_sigma": sc["within_sigma"]})
        out["ablation"] = table
    obs_all = [o for c in lr.captures for o in c.observations]
    if lookups and obs_all:
        rows_l = []
        cal_l = load_calibration(cs.calibration_path())
        for name in LOOKUPS:
            cfg_l = replace(cfg, lookup=name)
            corr_l = Corrector.for_calibration(obs_all, cfg_l, cal_l,
                                               radial_fits=[c.radial for c in lr.captures])
            res_l = apply_all(cfg_l, cs, corr_l)
            sc = _score(_rows(cs, res_l))
            rows_l.append({"lookup": name, **sc["full"], "within_sigma": sc["within_sigma"],
                           "gated": sc["gated"]})
        out["lookups"] = rows_l
    out["seconds"] = round(time.perf_counter() - t0, 2)
    out["_observations"] = [o for c in lr.captures for o in c.observations]  # not JSON
    return out


def _stats_from_naive(naive: dict[str, Any]) -> dict[str, Any]:
    s = naive["stages"]["naive"]
    return {"median_rel_err": s["median_rel_err"], "p90_rel_err": s["p90_rel_err"], "n": s["n"]}


def _per_distance(rows: list[dict[str, Any]], naive: dict[str, Any]) -> list[dict[str, Any]]:
    ok = [r for r in rows if "rel_err" in r]
    naive_by_d = {round(p["distance_m"], 1): p["stages"]["naive"] for p in naive["per_distance"]}
    dists = sorted({round(r["z_true_m"], 1) for r in rows if r["z_true_m"] is not None})
    out = []
    for d in dists:
        sel = [r for r in ok if round(r["z_true_m"], 1) == d]
        out.append({
            "distance_m": d, "naive": naive_by_d.get(d),
            "measured": _stats([r["rel_err_measured"] for r in sel]),
            "full": _stats([r["rel_err"] for r in sel]),
            "cramer_rao_floor": _stats([r["crlb_rel"] for r in sel]),
        })
    return out


__all__ = ["apply_all", "learn_and_apply", "run_bench"]
