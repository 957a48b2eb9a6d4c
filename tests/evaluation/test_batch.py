"""Batch runs and studies on a Dask LocalCluster with 2 workers (issue #8 acceptance).

Cluster results equal a serial run with the same seeds; a worker killed in the middle loses no
result (Dask reschedules its tasks); a rerun after an interruption does only what was missing;
bad input (empty glob, unavailable command, unreachable scheduler) fails before any work.
One LocalCluster (~3 s to start) is shared by the module.
"""

from __future__ import annotations

import json
import os
import signal
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

import phonestereo.cli.scaleout  # noqa: F401  (registers the commands)
from phonestereo.cli.app import app
from phonestereo.errors import InputError
from phonestereo.evaluation.batch import get_command, parse_params, run_batch
from phonestereo.evaluation.runner import dask_client
from phonestereo.evaluation.study import StudyConfig, run_study
from phonestereo.evaluation.tolerances import NormalSpec, Tolerance, ToleranceSet
from phonestereo.sim.module import load_module
from phonestereo.sim.scenarios import VerificationConfig, plan_scenario
from phonestereo.sim.writer import write_capture_set

TOL = ToleranceSet(
    tolerances=(
        Tolerance(parameter="wide.heating_drift_px.1", normal=NormalSpec(sigma=0.6)),
        Tolerance(parameter="tele.heating_drift_px.1", normal=NormalSpec(sigma=1.0)),
        Tolerance(parameter="tele.sag_px_per_g", normal=NormalSpec(sigma=0.15)),
    )
)


@pytest.fixture(scope="module")
def client():
    with dask_client(None, 2) as c:
        yield c


@pytest.fixture(scope="module")
def spec():
    return load_module("folded-x3")


@pytest.fixture(scope="module")
def sets(spec, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Four simulated phones (JSON only, no images) and one folder that is no capture set."""
    root = tmp_path_factory.mktemp("sets")
    cfg = VerificationConfig(distances_m=(1.0, 3.0), attempts=1)
    for seed in range(4):
        plan = plan_scenario("verification", spec, seed, config=cfg)
        write_capture_set(root / f"phone{seed}", plan, render=False)
    (root / "phone9-broken").mkdir()
    return root


def _metric(rows, key: str = "median_rel_err") -> dict[str, float]:
    return {r["key"]: r.get(key) for r in rows if r["status"] == "ok"}


# --- batch ---------------------------------------------------------------------------------
def test_batch_on_cluster_equals_serial_and_records_failures(sets: Path, client, tmp_path) -> None:
    serial = run_batch("naive", str(sets / "phone*"), tmp_path / "serial")
    dask = run_batch("naive", str(sets / "phone*"), tmp_path / "dask", client=client)
    assert serial.n_ok == dask.n_ok == 4 and serial.n_failed == dask.n_failed == 1
    assert _metric(serial.rows) == _metric(dask.rows)  # bit-identical: same seeds, same code
    # the naive error of a simulated phone is near the thesis's ~30 % (measured 27-33 %)
    assert all(0.15 < v < 0.45 for v in _metric(dask.rows).values())
    broken = next(r for r in dask.rows if r["status"] == "failed")
    assert "manifest.json" in broken["reason"]
    log = json.loads((tmp_path / "dask" / "inputs" / f"{broken['key']}.json").read_text())
    assert log["status"] == "failed" and "Traceback" in log["traceback"]
    assert (tmp_path / "dask" / "results.csv").read_text().count("\n") == 6  # header + 5


def test_batch_rerun_only_does_what_is_missing(sets: Path, tmp_path: Path) -> None:
    out = tmp_path / "b"
    first = run_batch("naive", str(sets / "phone*"), out)
    assert first.n_run == 5
    assert run_batch("naive", str(sets / "phone*"), out, retry_failed=False).n_run == 0
    assert run_batch("naive", str(sets / "phone*"), out).n_run == 1  # the failed one again
    ok_key = next(r["key"] for r in first.rows if r["status"] == "ok")
    (out / "inputs" / f"{ok_key}.json").unlink()  # as if interrupted before it finished
    again = run_batch("naive", str(sets / "phone*"), out, retry_failed=False)
    assert again.n_run == 1 and _metric(again.rows) == _metric(first.rows)
    with pytest.raises(InputError, match="another command"):
        run_batch("learn", str(sets / "phone*"), out)


def test_batch_bad_input_fails_before_work(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="matches no folder"):
        run_batch("naive", str(tmp_path / "nothing*"), tmp_path / "o")
    with pytest.raises(InputError, match="not available yet"):
        get_command("depth")
    with pytest.raises(InputError, match="no parameter"):
        parse_params(get_command("learn"), ["board=9x6"])
    with pytest.raises(InputError, match="cannot reach"):
        with dask_client("127.0.0.1:9", timeout_s=1.0):
            pass
    assert not (tmp_path / "o").exists()


def test_cli_batch_errors_and_exit_codes(sets: Path, tmp_path: Path) -> None:
    runner = CliRunner()
    out = str(tmp_path / "o")
    r = runner.invoke(app, ["batch", "naive", "--inputs", str(tmp_path / "no*"), "--out", out])
    assert r.exit_code == 2 and "matches no folder" in r.output
    r = runner.invoke(app, ["batch", "evaluate", "--inputs", str(sets / "*"), "--out", out])
    assert r.exit_code == 2 and "not available yet" in r.output
    r = runner.invoke(
        app,
        ["batch", "naive", "--inputs", str(sets / "*"), "--out", out, "--scheduler", "x"],
    )
    assert r.exit_code == 2 and "scheduler address" in r.output


# --- studies on the cluster ----------------------------------------------------------------
N = 24


@pytest.fixture(scope="module")
def serial_study(spec, tmp_path_factory: pytest.TempPathFactory):
    out = tmp_path_factory.mktemp("serial")
    return run_study(spec, TOL, out, StudyConfig(N, seed=11)), out


def _samples(out: Path) -> dict[str, float]:
    recs = [json.loads(p.read_text()) for p in sorted((out / "samples").glob("*.json"))]
    return {r["key"]: r["result"]["median_rel_err"] for r in recs}


def test_study_on_cluster_equals_serial(spec, client, serial_study, tmp_path: Path) -> None:
    res, out = serial_study
    dres = run_study(spec, TOL, tmp_path, StudyConfig(N, seed=11), client=client)
    assert _samples(tmp_path) == _samples(out)
    assert dres.top == res.top
    pids = {json.loads(p.read_text())["pid"] for p in (tmp_path / "samples").glob("*.json")}
    assert len(pids) == 2  # both workers did some of it


def test_killed_worker_loses_no_result(spec, client, serial_study, tmp_path: Path) -> None:
    _res, out = serial_study
    pids = client.run(os.getpid)
    victim = sorted(pids.values())[0]
    killed: list[int] = []

    def kill_once(done: int, total: int, key: str) -> None:
        if done == 3 and not killed:
            os.kill(victim, signal.SIGKILL)
            killed.append(victim)

    res = run_study(spec, TOL, tmp_path, StudyConfig(N, seed=11), client=client, progress=kill_once)
    assert killed and res.n_ok == N and res.n_failed == 0
    assert _samples(tmp_path) == _samples(out)
    client.wait_for_workers(2, timeout=30)  # the nanny restarts the killed worker
    assert victim not in client.run(os.getpid).values()


def test_interrupted_study_resumes_with_only_the_missing(
    spec, client, serial_study, tmp_path: Path
) -> None:
    _res, out = serial_study

    def interrupt(done: int, total: int, key: str) -> None:
        if done == 10:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_study(spec, TOL, tmp_path, StudyConfig(N, seed=11), client=client, progress=interrupt)
    assert len(list((tmp_path / "samples").glob("*.json"))) == 10
    res = run_study(spec, TOL, tmp_path, StudyConfig(N, seed=11), client=client)
    assert res.n_run == N - 10 and res.n_ok == N
    assert _samples(tmp_path) == _samples(out)


def test_cli_study_runs_on_a_local_cluster(tmp_path: Path) -> None:
    tol = tmp_path / "tol.json"
    tol.write_text(TOL.model_dump_json())
    r = CliRunner().invoke(
        app,
        [
            "study", "--module", "folded-x3", "--tolerances", str(tol), "--samples", "12",
            "--out", str(tmp_path / "o"), "--quick", "--workers", "1", "--json",
        ],
    )
    assert r.exit_code == 0, r.output
    summary = json.loads(r.output)
    assert summary["n_ok"] == 12 and summary["top"][0].endswith("heating_drift_px.1")
    assert np.isfinite(summary["r_squared"])


@pytest.mark.slow
def test_batch_calibrate_on_a_rendered_calibration_set(spec, tmp_path: Path) -> None:
    from phonestereo.sim.calib_scenario import CalibrationConfig

    plan = plan_scenario("calibration", spec, 0, config=CalibrationConfig.quick())
    write_capture_set(tmp_path / "sets" / "cal0", plan)
    res = run_batch(
        "calibrate", str(tmp_path / "sets" / "*"), tmp_path / "out", ["board=9x6", "square_m=0.02"]
    )
    assert res.n_ok == 1, res.rows[0]["reason"]
    row = res.rows[0]
    # the folded module's baseline is 12.1 mm (|(0.4, 12, 1.5)| mm); a 6-view quick set is
    # good to a few tenths of a millimetre
    assert row["baseline_mm"] == pytest.approx(12.1, abs=0.5)
    assert row["wide_f_px"] == pytest.approx(1500, rel=0.03)  # focus breathing at 0.6 m: +0.7 %
    assert Path(row["calibration"]).is_file()
    # the solve's own account per set: through the module's phone ISP the views differ beyond
    # chance (measured: 5 of the 8 views given their own σ, 5 corners rejected)
    assert row["outliers"] >= 0
    assert 1 <= row["views_own_sigma"] <= row["views_wide"] + row["views_tele"]
