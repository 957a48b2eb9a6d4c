"""The generalization bench: the demo flow on many random modules (issue #18 item 7).

``phonestereo bench modules --seeds A-B`` draws module ``random-<seed>`` for every seed
(:func:`~phonestereo.sim.random_module.random_module`), simulates the demo's quick thesis bench
on it (the scenario planned for the module, :mod:`~phonestereo.sim.coverage`; the phone's seed
is the module's), runs the learning and application flows and scores them against ground truth
(:func:`~phonestereo.evaluation.bench.run_bench`). Each module is one Dask task of
:func:`~phonestereo.evaluation.runner.run_tasks`, so a rerun resumes.

Outputs in ``out_dir``:

- ``modules/seed-<N>.json``   one record per module (status, reason, seconds, the row);
- ``work/seed-<N>/``          the module JSON, the capture set's JSON files and ``bench.json``
  (the images are deleted unless ``keep_images``);
- ``modules.csv`` (and ``.parquet``)  one row per module: its optics and rig, full-flow median
  and p90 relative error, within-σ, captures measured / gated and the gates' reasons, the
  largest |error|/σ, learned observations and the plan's notes;
- ``distribution.json``  quantiles of every metric over the modules and the issue's acceptance
  counts (median ≤ 1 %, p90 ≤ 2.5 %, within-σ in [50, 90] %, no capture beyond 4σ, ≥ 80 %
  measured);
- ``modules.png``  the figure: median and p90 per module against the focal ratio, within-σ
  and the measured fraction per module.
"""

from __future__ import annotations

import json
import re
import shutil
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.evaluation.runner import Progress, run_tasks, write_table

INPUTS_NAME = "bench_inputs.json"
#: The issue #18 acceptance thresholds.
MEDIAN_MAX, P90_MAX, WITHIN_SIGMA, MEASURED_MIN, Z_MAX = 0.01, 0.025, (0.5, 0.9), 0.8, 4.0


def demo_quick_config() -> Any:
    """The bench of ``phonestereo demo`` (without ``--full``): faces at 3 distances × 5 sensor
    positions, one attempt; the verification chart at 9 distances × 2 attempts."""
    from phonestereo.sim.scenarios import BenchConfig, LearningConfig, VerificationConfig

    return BenchConfig(
        LearningConfig(distances_m=(1.0, 2.0, 3.0), attempts=1), VerificationConfig(attempts=2)
    )


def parse_seeds(text: str) -> tuple[int, ...]:
    """``"1000-1019"``, ``"7"`` or ``"1,5,9-11"`` → the seeds, sorted and unique.

    >>> parse_seeds("1000-1003"), parse_seeds("3,1,5-6")
    ((1000, 1001, 1002, 1003), (1, 3, 5, 6))
    """
    seeds: set[int] = set()
    for part in str(text).split(","):
        m = re.fullmatch(r"\s*(\d+)\s*(?:-\s*(\d+)\s*)?", part)
        if m is None or (m.group(2) is not None and int(m.group(2)) < int(m.group(1))):
            raise InputError(f"--seeds {text!r}: use A-B, N or a comma list (e.g. 1000-1019)")
        lo = int(m.group(1))
        seeds.update(range(lo, int(m.group(2) or lo) + 1))
    return tuple(sorted(seeds))


def _gates(captures: list[dict[str, Any]]) -> dict[str, int]:
    reasons = Counter(f"{c.get('gate')}: {c.get('reason')}" for c in captures if "rel_err" not in c)
    return dict(reasons.most_common())


def module_row(seed: int, ranges: dict[str, Any], work: str, keep_images: bool) -> dict[str, Any]:
    """One module of the bench (a Dask task): draw, simulate, learn, apply, score."""
    from phonestereo.evaluation.analyses._common import json_clean
    from phonestereo.evaluation.bench import run_bench
    from phonestereo.sim.random_module import ModuleRanges, random_module
    from phonestereo.sim.scenarios import plan_scenario
    from phonestereo.sim.writer import write_capture_set

    spec = random_module(seed, ModuleRanges.model_validate(ranges))
    folder = Path(work)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "module.json").write_text(spec.to_json())
    plan = plan_scenario("thesis-bench", spec, seed, config=demo_quick_config())
    cs = folder / "set"
    write_capture_set(cs, plan)
    try:
        res = run_bench(cs)
    finally:
        if not keep_images:
            shutil.rmtree(cs / "images", ignore_errors=True)
    res.pop("_observations", None)
    (folder / "bench.json").write_text(json.dumps(json_clean(res), indent=1) + "\n")
    caps = res["captures"]
    ok = [c for c in caps if "rel_err" in c]
    z = [abs(c["depth_m"] - c["z_true_m"]) / c["sigma_m"] for c in ok if c["sigma_m"]]
    full, w, t = res["stages"]["full"], spec.wide, spec.tele
    ex = spec.extrinsics.tele_center_mm
    return {
        "seed": seed,
        "module": spec.name,
        "focal_ratio": round(t.focal_px_infinity / w.focal_px_infinity, 3),
        "size": f"{w.size[0]}x{w.size[1]}",
        "tele_focal_mm": t.focal_length_mm,
        "tele_pitch_um": t.pixel_pitch_um,
        "baseline_mm": round(float(np.hypot(ex[0], ex[1])), 2),
        "tz_mm": ex[2],
        "temperature": spec.reports.temperature,
        "median_rel_err": full["median_rel_err"],
        "p90_rel_err": full["p90_rel_err"],
        "measured_median_rel_err": res["stages"]["measured"]["median_rel_err"],
        "within_sigma": res["stages"]["within_sigma"],
        "captures": len(caps),
        "measured": len(ok),
        "gated": len(caps) - len(ok),
        "gate_reasons": json.dumps(_gates(caps)),
        "max_abs_err_over_sigma": round(max(z), 3) if z else None,
        "over_4_sigma": int(sum(v > Z_MAX for v in z)),
        "observations": res["learning"]["n_observations"],
        "plan_notes": " | ".join(plan.notes),
    }


def distribution(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Quantiles of the metrics over the modules and the issue's acceptance counts."""
    ok = [r for r in rows if r.get("status") == "ok"]

    def q(key: str) -> dict[str, float | None]:
        v = np.array([r[key] for r in ok if r.get(key) is not None], dtype=np.float64)
        if v.size == 0:
            return {"min": None, "median": None, "p90": None, "max": None}
        p = np.percentile(v, [0, 50, 90, 100])
        return dict(
            zip(("min", "median", "p90", "max"), (round(float(x), 6) for x in p), strict=True)
        )

    def count(pred: Any) -> int:
        return int(sum(bool(pred(r)) for r in ok))

    n_caps = sum(r["captures"] for r in ok)
    reasons: Counter[str] = Counter()
    for r in ok:
        reasons.update(json.loads(r["gate_reasons"]))
    return {
        "modules": len(rows),
        "ok": len(ok),
        "failed": [{"seed": r["seed"], "reason": r["reason"]} for r in rows if r not in ok],
        "quantiles": {
            k: q(k)
            for k in (
                "median_rel_err",
                "p90_rel_err",
                "within_sigma",
                "max_abs_err_over_sigma",
                "observations",
            )
        },
        "acceptance": {
            "median_le_1pct": count(lambda r: (r["median_rel_err"] or 1) <= MEDIAN_MAX),
            "p90_le_2p5pct": count(lambda r: (r["p90_rel_err"] or 1) <= P90_MAX),
            "within_sigma_50_90pct": count(
                lambda r: (
                    r["within_sigma"] is not None
                    and WITHIN_SIGMA[0] <= r["within_sigma"] <= WITHIN_SIGMA[1]
                )
            ),
            "captures_over_4_sigma": int(sum(r["over_4_sigma"] for r in ok)),
            "measured_fraction": round(sum(r["measured"] for r in ok) / n_caps, 4)
            if n_caps
            else None,
            "of_modules": len(ok),
        },
        "gate_reasons": dict(reasons.most_common()),
    }


def _figure(path: Path, rows: list[dict[str, Any]]) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    ok = [r for r in rows if r.get("status") == "ok"]
    fig = Figure(figsize=(11, 4))
    FigureCanvasAgg(fig)
    ax1, ax2, ax3 = fig.subplots(1, 3)
    ratio = np.array([r["focal_ratio"] for r in ok], dtype=float)
    for key, label, mark in (("median_rel_err", "median", "o"), ("p90_rel_err", "p90", "^")):
        v = np.array([np.nan if r[key] is None else 100 * r[key] for r in ok], dtype=float)
        ax1.scatter(ratio, v, marker=mark, label=label)
    ax1.axhline(100 * MEDIAN_MAX, color="C0", ls=":", lw=0.8)
    ax1.axhline(100 * P90_MAX, color="C1", ls=":", lw=0.8)
    ax1.set(xlabel="tele/wide focal ratio", ylabel="|Z − Z_true| / Z_true (%)",
            title="full flow per module", yscale="log")
    ax1.legend(fontsize=8)
    seeds = [str(r["seed"]) for r in ok]
    ws = [np.nan if r["within_sigma"] is None else 100 * r["within_sigma"] for r in ok]
    ax2.bar(seeds, ws, color="C2")
    ax2.axhspan(100 * WITHIN_SIGMA[0], 100 * WITHIN_SIGMA[1], color="0.9", zorder=0)
    ax2.set(ylabel="captures with |Z − Z_true| ≤ σ (%)", title="within σ", ylim=(0, 100))
    meas = [100 * r["measured"] / max(r["captures"], 1) for r in ok]
    ax3.bar(seeds, meas, color="C4")
    ax3.axhline(100 * MEASURED_MIN, color="k", ls=":", lw=0.8)
    ax3.set(ylabel="verification captures measured (%)", title="measured (rest gated)",
            ylim=(0, 100))
    for ax in (ax2, ax3):
        ax.tick_params(axis="x", labelrotation=90, labelsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


@dataclass(frozen=True)
class ModuleBenchResult:
    """A finished (or resumed) bench: rows, distribution, files, counts."""

    rows: tuple[dict[str, Any], ...]
    distribution: dict[str, Any]
    files: dict[str, str]
    n_run: int
    seconds: float


def run_module_bench(
    seeds: tuple[int, ...],
    out_dir: str | Path,
    *,
    ranges_path: str | Path | None = None,
    keep_images: bool = False,
    client: Any = None,
    progress: Progress | None = None,
    retry_failed: bool = True,
) -> ModuleBenchResult:
    """Run (or resume) the bench over ``seeds`` (module docstring).

    Raises
    ------
    InputError
        No seeds, bad ranges, or an out folder holding a bench with other ranges.
    """
    from phonestereo.sim.random_module import load_ranges

    t0 = time.perf_counter()
    if not seeds:
        raise InputError("no seeds given; pass --seeds A-B (e.g. 1000-1019)")
    ranges = load_ranges(ranges_path).model_dump(mode="json")
    out = Path(out_dir)
    stamp = {"ranges": ranges, "bench": "demo quick thesis-bench, phone seed = module seed"}
    stamp_path = out / INPUTS_NAME
    if stamp_path.is_file() and json.loads(stamp_path.read_text()) != stamp:
        raise InputError(f"{out} holds a module bench with other ranges; use a new --out "
                         "folder, or the same --ranges to resume it")
    out.mkdir(parents=True, exist_ok=True)
    stamp_path.write_text(json.dumps(stamp, indent=1) + "\n")
    tasks = {
        f"seed-{s}": (module_row, (s, ranges, str(out / "work" / f"seed-{s}"), keep_images))
        for s in seeds
    }
    records, n_run = run_tasks(tasks, out / "modules", client=client, progress=progress,
                               retry_failed=retry_failed, chunk=1)
    rows = []
    for key, rec in records.items():
        base = {"seed": int(key.split("-")[1]), "status": rec["status"], "reason": rec["reason"]}
        rows.append({**base, **(rec["result"] or {}), "seconds": round(rec["seconds"], 1)})
    files = {f"modules.{k}": v for k, v in write_table(rows, out / "modules").items()}
    dist = distribution(rows)
    (out / "distribution.json").write_text(json.dumps(dist, indent=1) + "\n")
    files["distribution.json"] = str(out / "distribution.json")
    if any(r["status"] == "ok" for r in rows):
        _figure(out / "modules.png", rows)
        files["modules.png"] = str(out / "modules.png")
    return ModuleBenchResult(tuple(rows), dist, files, n_run, time.perf_counter() - t0)


__all__ = [
    "ModuleBenchResult",
    "demo_quick_config",
    "distribution",
    "module_row",
    "parse_seeds",
    "run_module_bench",
]
