"""Tolerance studies (issue #8): tolerances file, analytic bench, sensitivity, study outputs.

The Dask side (cluster runs equal serial runs, killed workers, resume) is in test_batch.py,
which shares one LocalCluster among its tests.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import phonestereo.cli.scaleout  # noqa: F401  (registers the commands)
from phonestereo.cli.app import app
from phonestereo.errors import InputError, PhysicsError
from phonestereo.evaluation.study import StudyConfig, run_study, sensitivity, study_sample
from phonestereo.evaluation.study_bench import AnalyticBenchConfig, analytic_bench, get_bench
from phonestereo.evaluation.tolerances import (
    NormalSpec,
    Tolerance,
    ToleranceSet,
    UniformSpec,
    apply_offsets,
    draw_offsets,
    load_tolerances,
    parameter_names,
    standardised,
    validate_tolerances,
)
from phonestereo.sim.module import load_module

SHIPPED = (
    Path(__file__).parents[2]
    / "src"
    / "phonestereo"
    / "evaluation"
    / "data"
    / "tolerances-folded-x3.json"
)
QUICK = AnalyticBenchConfig.quick()


@pytest.fixture(scope="module")
def spec():
    return load_module("folded-x3")


def _tol(*items: tuple[str, float]) -> ToleranceSet:
    return ToleranceSet(
        tolerances=tuple(Tolerance(parameter=p, normal=NormalSpec(sigma=s)) for p, s in items)
    )


def _write(path: Path, data: object) -> Path:
    path.write_text(json.dumps(data))
    return path


# --- tolerances file -----------------------------------------------------------------------
def test_shipped_tolerances_validate_against_folded_x3(spec) -> None:
    tol = load_tolerances(SHIPPED, spec)
    assert len(tol.tolerances) >= 10
    assert set(tol.names) <= set(parameter_names(spec))


def test_unknown_parameter_is_named_with_the_valid_list(spec, tmp_path: Path) -> None:
    f = _write(
        tmp_path / "t.json",
        {"tolerances": [{"parameter": "tele.warp_factor", "normal": {"sigma": 1.0}}]},
    )
    with pytest.raises(InputError) as err:
        load_tolerances(f, spec)
    msg = str(err.value)
    assert "tele.warp_factor" in msg and "extrinsics.tele_center_mm.2" in msg
    assert "tele.sag_px_per_g" in msg


@pytest.mark.parametrize(
    ("entry", "needle"),
    [
        ({"parameter": "tele.sag_px_per_g"}, "exactly one"),
        ({"parameter": "tele.sag_px_per_g", "uniform": {"low": 1.0, "high": 0.0}}, "high > low"),
        ({"parameter": "tele.sag_px_per_g", "normal": {"sigma": -1}}, "sigma"),
    ],
)
def test_malformed_distribution_is_rejected(tmp_path: Path, entry: dict, needle: str) -> None:
    f = _write(tmp_path / "t.json", {"tolerances": [entry]})
    with pytest.raises(InputError, match=needle):
        load_tolerances(f)


def test_bracket_paths_are_canonical_and_offsets_apply(spec) -> None:
    tol = validate_tolerances(_tol(("extrinsics.tele_center_mm[2]", 0.3)), spec)
    assert tol.names == ("extrinsics.tele_center_mm.2",)
    moved = apply_offsets(spec, tol, np.array([0.25]))
    assert moved.extrinsics.tele_center_mm[2] == pytest.approx(1.5 + 0.25)  # preset t_z 1.5 mm
    assert moved.tele == spec.tele  # nothing else moves


def test_draws_are_per_sample_reproducible_and_standardised() -> None:
    tol = ToleranceSet(
        tolerances=(
            Tolerance(parameter="tele.sag_px_per_g", normal=NormalSpec(sigma=0.2)),
            Tolerance(parameter="heating.tau_s", uniform=UniformSpec(low=-20, high=20)),
        )
    )
    a = np.array([draw_offsets(tol, 5, i) for i in range(2000)])
    # sample 7 alone equals sample 7 of the run: order and worker do not matter
    assert np.array_equal(draw_offsets(tol, 5, 7), a[7])
    z = standardised(tol, a)
    # unit variance within sampling error (2000 draws: sd of the sd ≈ 1.6 %)
    assert np.std(z, axis=0) == pytest.approx([1.0, 1.0], abs=0.06)
    assert np.all(np.abs(a[:, 1]) <= 20)


def test_non_physical_sample_raises(spec) -> None:
    with pytest.raises(PhysicsError):
        apply_offsets(spec, _tol(("wide.focal_length_mm", 1.0)), np.array([-5.0]))


# --- analytic bench ------------------------------------------------------------------------
def test_analytic_bench_ideal_module_is_exact(spec) -> None:
    # every effect off: the factory calibration is the true rig, so naive depth is exact
    out = analytic_bench(spec.all_effects_off(), 0, QUICK)
    assert out["median_rel_err"] < 1e-9  # measured 2e-13 (round-off)


def test_analytic_bench_lands_near_thesis_error(spec) -> None:
    out = analytic_bench(spec, 0)
    # docs/architecture.md: naive error near the thesis's ~30 % at 1-4 m
    # (measured 23 % median, 38 % p90)
    assert 0.15 < out["median_rel_err"] < 0.40
    assert out["p90_rel_err"] > out["median_rel_err"]
    assert out["n_points"] == 9 * 63  # 9 distances, a 9x7 grid, every point seen by both
    d = out["per_distance"]
    assert d["4"] > d["0.8"]  # δZ/Z grows with Z (eq. 4 sensitivity)
    assert out["stages"]["naive"]["median_rel_err"] == out["median_rel_err"]


def test_heating_drift_raises_the_bench_error(spec) -> None:
    tol = validate_tolerances(_tol(("wide.heating_drift_px.1", 0.6)), spec)
    lo = analytic_bench(apply_offsets(spec, tol, np.array([-1.0])), 3, QUICK)
    hi = analytic_bench(apply_offsets(spec, tol, np.array([1.0])), 3, QUICK)
    assert hi["median_rel_err"] > lo["median_rel_err"] + 0.03  # measured +9 pp for 2 px


def test_benches_by_name() -> None:
    assert callable(get_bench("flow")) and callable(get_bench("analytic"))
    with pytest.raises(InputError, match="analytic"):
        get_bench("nope")


# --- sensitivity and the study -------------------------------------------------------------
def test_sensitivity_recovers_known_linear_effects() -> None:
    rng = np.random.default_rng(1)
    z = rng.normal(size=(300, 3))
    y = 0.25 + 0.04 * z[:, 2] - 0.01 * z[:, 0] + 0.002 * rng.normal(size=300)
    sens, r2 = sensitivity(("a", "b", "c"), z, y)
    assert [s.parameter for s in sens] == ["c", "a", "b"]
    assert sens[0].coefficient == pytest.approx(0.04, abs=0.001)  # 3 se of 300 samples
    assert sens[1].coefficient == pytest.approx(-0.01, abs=0.001)
    assert sum(s.share_of_variance for s in sens) == pytest.approx(r2, abs=0.02)
    with pytest.raises(InputError, match="at least"):
        sensitivity(("a", "b", "c"), z[:3], y[:3])


TOL3 = (("wide.heating_drift_px.1", 0.6), ("tele.sag_px_per_g", 0.15), ("heating.tau_s", 10.0))


@pytest.fixture(scope="module")
def serial_study(spec, tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("study")
    res = run_study(spec, _tol(*TOL3), out, StudyConfig(24, seed=3, bench_config=QUICK))
    return res, out


def test_study_ranks_heating_first_and_writes_outputs(serial_study) -> None:
    res, out = serial_study
    assert res.n_ok == 24 and res.n_failed == 0 and res.n_run == 24
    # the wide's y drift moves the disparity of the vertical-baseline module directly
    assert res.top[0] == "wide.heating_drift_px.1"
    assert res.sensitivities[0].share_of_variance > 0.5
    for name in ("samples.csv", "sensitivity.csv", "sensitivity.json", "tornado.png"):
        assert (out / name).stat().st_size > 0
    summary = json.loads((out / "sensitivity.json").read_text())
    assert summary["top"][0] == "wide.heating_drift_px.1" and summary["n_ok"] == 24
    assert len(list((out / "samples").glob("*.json"))) == 24


def test_study_rerun_does_nothing_and_other_inputs_are_refused(spec, serial_study) -> None:
    res, out = serial_study
    again = run_study(spec, _tol(*TOL3), out, StudyConfig(24, seed=3, bench_config=QUICK))
    assert again.n_run == 0 and again.top == res.top
    with pytest.raises(InputError, match="other inputs"):
        run_study(spec, _tol(*TOL3), out, StudyConfig(24, seed=4, bench_config=QUICK))


def test_sample_is_a_pure_function_of_seed_and_index(spec, serial_study) -> None:
    _res, out = serial_study
    rec = json.loads((out / "samples" / "s000005.json").read_text())
    row = study_sample(spec, validate_tolerances(_tol(*TOL3), spec), 3, 5, "analytic", QUICK)
    assert row["median_rel_err"] == rec["result"]["median_rel_err"]


def test_failed_samples_are_recorded_not_fatal(spec, tmp_path: Path) -> None:
    # a focus-noise offset below −0.0002 makes the wide's noise negative: non-physical
    tol = ToleranceSet(
        tolerances=(
            Tolerance(parameter="wide.focus_noise_rel", uniform=UniformSpec(low=-4e-4, high=0)),
            Tolerance(parameter="wide.heating_drift_px.1", normal=NormalSpec(sigma=0.6)),
        )
    )
    res = run_study(spec, tol, tmp_path, StudyConfig(16, seed=0, bench_config=QUICK))
    assert res.n_failed > 0 and res.n_ok > 0 and res.n_ok + res.n_failed == 16
    failures = json.loads((tmp_path / "sensitivity.json").read_text())["failures"]
    assert "focus_noise_rel" in failures[0]["reason"]


def test_cli_study_rejects_bad_input_before_work(tmp_path: Path) -> None:
    runner = CliRunner()
    bad = _write(
        tmp_path / "t.json", {"tolerances": [{"parameter": "tele.nope", "normal": {"sigma": 1}}]}
    )
    args = ["study", "--module", "folded-x3", "--samples", "4", "--out", str(tmp_path / "o")]
    r = runner.invoke(app, [*args, "--tolerances", str(bad)])
    assert r.exit_code == 2 and "tele.nope" in r.output
    r = runner.invoke(app, [*args, "--tolerances", str(SHIPPED), "--bench", "nope"])
    assert r.exit_code == 2 and "analytic" in r.output
    r = runner.invoke(
        app, [*args, "--tolerances", str(SHIPPED), "--scheduler", "127.0.0.1:notaport"]
    )
    assert r.exit_code == 2 and "scheduler address" in r.output
    assert not (tmp_path / "o").exists()  # nothing started


def test_common_phone_by_default_independent_phones_on_request(
    spec, serial_study, tmp_path
) -> None:
    _res, out = serial_study
    seeds = {json.loads(p.read_text())["result"]["bench_seed"] for p in (out / "samples").glob("*")}
    assert len(seeds) == 1  # common random numbers: one simulated phone for every sample
    res = run_study(
        spec, _tol(*TOL3), tmp_path, StudyConfig(12, 3, bench_config=QUICK, common_phone=False)
    )
    seeds = {
        json.loads(p.read_text())["result"]["bench_seed"] for p in (tmp_path / "samples").glob("*")
    }
    assert len(seeds) == 12 and res.n_ok == 12
