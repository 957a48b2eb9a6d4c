"""Issue #18's second held-out module, rebuilt from its description: `folded-x3` with twice the
heating drift, stronger sag and hand shake, a worse autofocus (0.06 D, 10 % failures), a worse
factory calibration and temperature reported. The issue measured it at 1.26 % / 3.09 % with
17 % of the captures within σ (errors from +2 % at 0.8 m to −4 % at 4 m: the correction
extrapolated beyond the learned disparities without its σ growing).

Measured on this variant (seed 7, `demo`'s quick bench, session 21): full flow 0.21 % median,
0.49 % p90, 18 of 18 measured, 78 % within σ, largest |error| 1.3σ, naive 41 %.
"""

from __future__ import annotations

import json
from importlib import resources

import numpy as np
import pytest

from phonestereo.evaluation.bench import run_bench
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import BenchConfig, LearningConfig, VerificationConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set


def hot_folded_module(path):
    """Write the variant's module JSON (the preset with the issue's changes) to ``path``."""
    text = resources.files("phonestereo.sim").joinpath("presets", "folded-x3.json").read_text()
    m = json.loads(text)
    m["name"] = "folded-x3-hot"
    for cam in ("wide", "tele"):
        m[cam]["heating_drift_px"] = [2.0 * v for v in m[cam]["heating_drift_px"]]
    m["wide"]["sag_px_per_g"], m["tele"]["sag_px_per_g"] = 0.5, 1.2  # preset 0 and 0.5
    m["handheld"] = {"rotation_deg": 0.6, "translation_mm": 4.0}  # preset 0.3°, 2 mm
    m["autofocus"] = {"error_dioptre": 0.06, "failure_rate": 0.10}  # preset 0.03 D, 5 %
    noise = m["calibration"]["noise"]  # factory noise ×2.5
    for key in ("focal_rel", "principal_point_px", "translation_mm"):
        noise[key] = [2.5 * v for v in noise[key]]
    noise["rotation_deg"] *= 2.5
    m["reports"]["temperature"] = True
    path.write_text(json.dumps(m))
    return path


@pytest.mark.slow  # ~2.5 min on one core: 33 captures rendered, learned and applied
def test_hot_folded_module_meets_the_random_modules_lines(tmp_path) -> None:
    spec = load_module(hot_folded_module(tmp_path / "hot.json"))
    bench = BenchConfig(LearningConfig(distances_m=(1.0, 2.0, 3.0), attempts=1),
                        VerificationConfig(attempts=2))  # `demo`'s quick bench
    out = tmp_path / "set"
    write_capture_set(out, plan_scenario("thesis-bench", spec, 7, config=bench), workers=1)
    res = run_bench(out)
    full = res["stages"]["full"]
    caps = [c for c in res["captures"] if c["ok"]]
    z = np.array([abs(c["depth_m"] - c["z_true_m"]) / c["sigma_m"] for c in caps])
    # The random modules' acceptance lines (issue #18): median ≤ 1 %, p90 ≤ 2.5 %, ≥ 80 %
    # measured, no capture beyond 4σ; within σ at least the band's lower end (50 %).
    # Measured 0.21 % / 0.49 %, 18/18, max 1.3σ, 78 % (module docstring).
    assert full["median_rel_err"] <= 0.01 and full["p90_rel_err"] <= 0.025, full
    assert len(caps) >= 0.8 * len(res["captures"]), [c["reason"] for c in res["captures"]]
    assert z.max() <= 4.0, z
    assert res["stages"]["within_sigma"] >= 0.5, res["stages"]
    # the heating it was built for is there: the naive error is far larger than the preset's
    assert res["stages"]["naive"]["median_rel_err"] > 0.2, res["stages"]["naive"]
