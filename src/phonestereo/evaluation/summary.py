"""Score a simulated capture set against its ground truth, stage by stage (docs/architecture.md).

Only the naive stage exists so far: Z = f·B/d from the true pixel positions of every chart
corner and the factory calibration (thesis chapter 3 intro). The fix stages and the full flow
join as they land; the JSON shape is the one ``phonestereo demo`` and ``evaluate`` print:
``{"stages": {name: {"median_rel_err", "p90_rel_err"}}, "per_distance": [...], ...}``.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from phonestereo.evaluation.naive import naive_relative_errors
from phonestereo.io import load_calibration, load_capture_set
from phonestereo.sim.ground_truth import load_ground_truth


def _stats(errors: np.ndarray) -> dict[str, float]:
    """Median and 90th percentile of relative errors (N,); an unbounded error (inf: a naive
    depth at or beyond infinity) counts as the largest, and a quantile it weighs in is inf
    (``n_unbounded`` says how many there were).

    >>> _stats(np.array([0.1, 0.2, 0.3, np.inf]))
    {'median_rel_err': 0.25, 'p90_rel_err': inf, 'n': 4, 'n_unbounded': 1}
    """
    if errors.size == 0:
        return {"median_rel_err": float("nan"), "p90_rel_err": float("nan"), "n": 0}
    finite = np.isfinite(errors)
    if finite.all():
        return {
            "median_rel_err": float(np.median(errors)),
            "p90_rel_err": float(np.percentile(errors, 90)),
            "n": int(errors.size),
        }
    # NumPy's linear quantiles turn inf into NaN: a finite stand-in above every error, then
    # any quantile above the largest finite error is one an unbounded error weighs in
    top = float(errors[finite].max(initial=0.0))
    q = np.percentile(np.where(finite, errors, 1e300), [50, 90])
    q = np.where(q > top, np.inf, q)
    return {"median_rel_err": float(q[0]), "p90_rel_err": float(q[1]), "n": int(errors.size),
            "n_unbounded": int(np.sum(~finite))}


def score_capture_set(folder: str | Path, kind: str = "verification") -> dict[str, Any]:
    """Relative depth error per verification capture for each stage available.

    Each capture contributes one number per stage: the median relative error over the chart
    corners both cameras see. Medians and 90th percentiles are over captures.

    Parameters
    ----------
    folder : path
        A simulated capture set (with ``ground_truth.json``).
    kind : str
        Capture kind to score.

    Returns
    -------
    dict
        ``{"stages": {...}, "per_distance": [{"distance_m", "stages"}...], "captures": n}``.
    """
    cs = load_capture_set(folder, check_images=False)
    cal = load_calibration(cs.calibration_path())
    gt = load_ground_truth(Path(folder) / "ground_truth.json")
    rows = []
    for cap in gt.captures:
        if cap.kind != kind:
            continue
        err = naive_relative_errors(cap, cal)
        if err.size == 0:
            continue
        depths = [
            np.nanmedian(o.keypoints["corners"].arrays().depth_m)
            for o in cap.objects
            if "corners" in o.keypoints
        ]
        rows.append((float(np.median(depths)), float(np.median(err))))
    naive = np.array([r[1] for r in rows])
    dist = np.array([r[0] for r in rows])
    per_distance = []
    for d in np.unique(np.round(dist, 1)):
        sel = np.round(dist, 1) == d
        per_distance.append({"distance_m": float(d), "stages": {"naive": _stats(naive[sel])}})
    return {"stages": {"naive": _stats(naive)}, "per_distance": per_distance, "captures": len(rows)}
