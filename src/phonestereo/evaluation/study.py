"""Tolerance studies: Monte Carlo over a module's manufacturing tolerances (docs/architecture.md).

Each sample draws the toleranced parameters (:mod:`~phonestereo.evaluation.tolerances`),
builds the sampled module and runs a bench on it (:mod:`~phonestereo.evaluation.study_bench`)
as one Dask task (:func:`~phonestereo.evaluation.runner.run_tasks`). The sensitivity of the
depth error to each tolerance is the linear regression of the metric (default the median
relative depth error) on all standardised sampled parameters together: the coefficient is the
change of the metric per +1σ of that parameter, its share of variance b²·var(z)/var(y), and
the Spearman rank correlation is reported beside it (robust to a non-linear response).

Outputs in ``out_dir``: ``samples/<key>.json`` (one record per sample: resumable),
``samples.csv`` and ``samples.parquet`` (when pyarrow imports; per-sample table: offsets,
standardised offsets, metrics, status, reason), ``sensitivity.csv`` (the ranked table),
``sensitivity.json`` (the same with the inputs, counts, failures, top three tolerances and
R²), ``tornado.png`` (the figure) and ``study_inputs.json`` (the fingerprint a resume checks).
Seeds make a study reproducible: sample ``i`` of seed ``s`` is the same on any worker.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from scipy import stats

from phonestereo.errors import InputError
from phonestereo.evaluation.runner import Progress, run_tasks, write_table
from phonestereo.evaluation.study_bench import BENCH_CONFIGS, get_bench
from phonestereo.evaluation.tolerances import ToleranceSet, sample_module, validate_tolerances
from phonestereo.sim.module import ModuleSpec

METRICS = ("median_rel_err", "p90_rel_err")
INPUTS_NAME = "study_inputs.json"


@dataclass(frozen=True)
class StudyConfig:
    """How to run a study: samples, seed, bench and its config, and the metric ranked.

    ``common_phone`` (default) benches every sample on the same simulated phone (factory
    calibration noise, hand shake, lens-position noise drawn from the study seed): common
    random numbers, so the spread between samples is the tolerances' alone and the ranking
    converges with few samples. ``False`` draws a new phone per sample (the spread then also
    holds the per-phone noise, which no tolerance explains).
    """

    samples: int
    seed: int = 0
    bench: str = "analytic"
    bench_config: Any = None
    metric: str = "median_rel_err"
    common_phone: bool = True

    def __post_init__(self) -> None:
        if self.samples < 1:
            raise InputError(f"--samples must be >= 1, got {self.samples}")
        if self.seed < 0:
            raise InputError(f"--seed must be >= 0, got {self.seed}")
        if self.metric not in METRICS:
            raise InputError(f"metric must be one of {METRICS}, got {self.metric!r}")


@dataclass(frozen=True)
class Sensitivity:
    """One tolerance's effect on the metric (metric units per 1σ of the parameter)."""

    parameter: str
    coefficient: float
    std_error: float
    share_of_variance: float
    spearman_rho: float
    spearman_p: float
    rank: int


@dataclass(frozen=True)
class StudyResult:
    """A finished study: ranked sensitivities, R² of the linear model, counts and files."""

    sensitivities: tuple[Sensitivity, ...]
    r_squared: float
    metric_mean: float
    n_ok: int
    n_failed: int
    n_run: int
    seconds: float
    files: dict[str, str]

    @property
    def top(self) -> tuple[str, ...]:
        """Parameters by decreasing |coefficient|."""
        return tuple(s.parameter for s in self.sensitivities)


def sample_seed(seed: int, index: int, common_phone: bool = True) -> int:
    """The bench seed (the simulated phone) of sample ``index``: the study seed's own phone
    for every sample (``common_phone``) or a hash of (seed, index)."""
    key = [int(seed)] if common_phone else [int(seed), int(index)]
    return int(np.random.SeedSequence(key).generate_state(1)[0] % (2**31))


def study_sample(
    spec: ModuleSpec,
    tolerances: ToleranceSet,
    seed: int,
    index: int,
    bench: str,
    cfg: Any,
    common_phone: bool = True,
) -> dict[str, Any]:
    """Run one sample (a Dask task): draw, apply, bench. Returns offsets, z and metrics."""
    s = sample_module(spec, tolerances, seed, index)
    phone = sample_seed(seed, index, common_phone)
    out = get_bench(bench)(s.spec, phone, cfg)
    row: dict[str, Any] = {"sample": index, "bench_seed": phone}
    for name, off, z in zip(tolerances.names, s.offsets, s.z, strict=True):
        row[f"offset:{name}"] = float(off)
        row[f"z:{name}"] = float(z)
    for key in METRICS:
        row[key] = float(out[key])
    for stage, values in out.get("stages", {}).items():
        for key in METRICS:
            row[f"{stage}:{key}"] = float(values[key])
    return row


def sensitivity(
    names: tuple[str, ...], z: np.ndarray, y: np.ndarray
) -> tuple[tuple[Sensitivity, ...], float]:
    """Rank parameters by the linear-regression coefficient of ``y`` on standardised ``z``.

    Parameters
    ----------
    names : tuple of str
        K parameter names.
    z : ndarray (S, K)
        Standardised offsets of S samples.
    y : ndarray (S,)
        The metric of each sample.

    Returns
    -------
    sensitivities : tuple of Sensitivity
        Sorted by decreasing |coefficient|.
    r_squared : float
        Variance of y explained by the linear model.

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> z = rng.normal(size=(400, 2))
    >>> sens, r2 = sensitivity(("a", "b"), z, 0.3 + 0.02 * z[:, 1] + 0.001 * z[:, 0])
    >>> sens[0].parameter, round(sens[0].coefficient, 4), round(r2, 3)
    ('b', 0.02, 1.0)
    """
    z = np.asarray(z, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    s, k = z.shape
    if s < k + 2:
        raise InputError(
            f"{s} successful samples cannot rank {k} tolerances; run at least {k + 2} samples"
        )
    A = np.column_stack([np.ones(s), z])
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    resid = y - A @ beta
    var_y = float(np.var(y))
    dof = max(s - k - 1, 1)
    cov = np.linalg.pinv(A.T @ A) * float(resid @ resid) / dof
    se = np.sqrt(np.clip(np.diag(cov)[1:], 0, None))
    r2 = 1.0 - float(np.var(resid)) / var_y if var_y > 0 else float("nan")
    rows = []
    for j, name in enumerate(names):
        rho, p = stats.spearmanr(z[:, j], y) if np.ptp(z[:, j]) > 0 else (np.nan, np.nan)
        share = float(beta[j + 1] ** 2 * np.var(z[:, j]) / var_y) if var_y > 0 else float("nan")
        rows.append((name, float(beta[j + 1]), float(se[j]), share, float(rho), float(p)))
    rows.sort(key=lambda r: -abs(r[1]))
    return tuple(Sensitivity(*r, rank=i + 1) for i, r in enumerate(rows)), r2


def _fingerprint(spec: ModuleSpec, tol: ToleranceSet, cfg: StudyConfig) -> dict[str, Any]:
    bench_cfg = asdict(cfg.bench_config) if cfg.bench_config is not None else None
    text = json.dumps(
        [
            spec.model_dump(mode="json"),
            tol.model_dump(mode="json"),
            cfg.seed,
            cfg.bench,
            bench_cfg,
            cfg.common_phone,
        ],
        sort_keys=True,
        default=str,
    )
    return {
        "module": spec.name,
        "seed": cfg.seed,
        "bench": cfg.bench,
        "bench_config": bench_cfg,
        "common_phone": cfg.common_phone,
        "sha256": hashlib.sha256(text.encode()).hexdigest(),
    }


def _check_out(out: Path, fp: dict[str, Any]) -> None:
    path = out / INPUTS_NAME
    if path.is_file():
        old = json.loads(path.read_text())
        if old.get("sha256") != fp["sha256"]:
            raise InputError(
                f"{out} holds a study of other inputs (module, tolerances, seed or bench); "
                "use a new --out folder, or the same inputs to resume it"
            )
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(fp, indent=1, default=str) + "\n")


def _tornado(path: Path, result: StudyResult, metric: str, k_max: int = 15) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    sens = result.sensitivities[:k_max][::-1]
    fig = Figure(figsize=(9, 1.6 + 0.4 * len(sens)))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    base = 100 * result.metric_mean
    y = np.arange(len(sens))
    lo = np.array([-abs(s.coefficient) for s in sens]) * 100
    hi = -lo
    up = np.array([s.coefficient > 0 for s in sens])
    ax.barh(y, hi, left=base, color=np.where(up, "tab:red", "tab:blue"))
    ax.barh(y, lo, left=base, color=np.where(up, "tab:blue", "tab:red"), alpha=0.5)
    ax.axvline(base, color="k", lw=0.8)
    ax.set_yticks(y, [f"{s.parameter}  ({100 * s.share_of_variance:.0f} %)" for s in sens])
    ax.set_xlabel(f"{metric} of the naive depth (%), at −1σ / +1σ of each tolerance")
    ax.set_title(
        f"Tolerance sensitivity ({result.n_ok} samples, linear-model R² = "
        f"{result.r_squared:.2f})\nright: +1σ, left: −1σ; red raises the error, "
        "(%) share of variance",
        fontsize=10,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def run_study(
    spec: ModuleSpec,
    tolerances: ToleranceSet,
    out_dir: str | Path,
    config: StudyConfig,
    *,
    client: Any = None,
    progress: Progress | None = None,
) -> StudyResult:
    """Run (or resume) a tolerance study and write its tables and tornado figure.

    Parameters
    ----------
    spec : ModuleSpec
        The nominal module.
    tolerances : ToleranceSet
        Validated against ``spec`` here, before any work.
    out_dir : path
        Output folder; a folder of an earlier run of the same inputs is resumed.
    config : StudyConfig
        Samples, seed, bench.
    client : distributed.Client, optional
        Dask client; None runs the samples here, one after another.
    progress : callable, optional
        ``progress(done, total, key)``.

    Raises
    ------
    InputError
        Unknown tolerance parameters, an unavailable bench, an out folder of another study,
        or too few successful samples to rank the tolerances.
    """
    t0 = time.perf_counter()
    tol = validate_tolerances(tolerances, spec)
    get_bench(config.bench)  # an unavailable bench fails before any work
    bench_cfg = config.bench_config
    if bench_cfg is None and config.bench in BENCH_CONFIGS:
        bench_cfg = BENCH_CONFIGS[config.bench]()
    config = StudyConfig(
        config.samples, config.seed, config.bench, bench_cfg, config.metric, config.common_phone
    )
    out = Path(out_dir)
    _check_out(out, _fingerprint(spec, tol, config))
    tasks = {
        f"s{i:06d}": (
            study_sample,
            (spec, tol, config.seed, i, config.bench, bench_cfg, config.common_phone),
        )
        for i in range(config.samples)
    }
    records, n_run = run_tasks(tasks, out / "samples", client=client, progress=progress)
    rows = []
    for key, rec in records.items():
        base = {"key": key, "status": rec["status"], "reason": rec["reason"]}
        rows.append({**base, **(rec["result"] or {}), "seconds": rec["seconds"]})
    table = pd.DataFrame(rows)
    files = {f"samples.{k}": v for k, v in write_table(rows, out / "samples").items()}
    ok = table[table["status"] == "ok"]
    z = ok[[f"z:{n}" for n in tol.names]].to_numpy(dtype=float) if len(ok) else np.zeros((0, 0))
    y = ok[config.metric].to_numpy(dtype=float) if len(ok) else np.zeros(0)
    sens, r2 = sensitivity(tol.names, z.reshape(len(ok), len(tol.names)), y)
    for name in ("sensitivity.json", "sensitivity.csv", "tornado.png"):
        files[name] = str(out / name)
    result = StudyResult(
        sens,
        r2,
        float(np.mean(y)),
        len(ok),
        len(table) - len(ok),
        n_run,
        time.perf_counter() - t0,
        files,
    )
    sens_table = pd.DataFrame([asdict(s) for s in sens])
    sens_table.to_csv(out / "sensitivity.csv", index=False)
    summary = {
        "module": spec.name,
        "samples": config.samples,
        "seed": config.seed,
        "bench": config.bench,
        "metric": config.metric,
        "common_phone": config.common_phone,
        "metric_mean": result.metric_mean,
        "r_squared": r2,
        "n_ok": result.n_ok,
        "n_failed": result.n_failed,
        "n_run": n_run,
        "seconds": result.seconds,
        "top": list(result.top[:3]),
        "sensitivities": [asdict(s) for s in sens],
        "failures": table.loc[table["status"] != "ok", ["key", "reason"]].to_dict("records"),
    }
    (out / "sensitivity.json").write_text(json.dumps(summary, indent=1, default=float) + "\n")
    _tornado(out / "tornado.png", result, config.metric)
    return result


__all__ = [
    "METRICS",
    "Sensitivity",
    "StudyConfig",
    "StudyResult",
    "run_study",
    "sample_seed",
    "sensitivity",
    "study_sample",
]
