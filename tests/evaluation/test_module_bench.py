"""The generalization bench (issue #18 item 7): rows, distribution, figure, resume, errors.

The real per-module task renders and runs the whole demo flow (minutes per module); here it is
replaced by a stand-in that returns a row of the same keys, so the bookkeeping is tested in
seconds. The real task is exercised by `phonestereo bench modules` (README numbers).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from phonestereo.cli import app
from phonestereo.cli.demo import QUICK
from phonestereo.errors import InputError
from phonestereo.evaluation import module_bench as mb


def _fake_row(seed: int, ranges: dict[str, Any], work: str, keep_images: bool) -> dict[str, Any]:
    if seed == 13:
        raise RuntimeError("rendering crashed")
    Path(work).mkdir(parents=True, exist_ok=True)
    good = seed % 2 == 0
    return {
        "seed": seed, "module": f"random-{seed}", "focal_ratio": 2.0 + seed % 5,
        "size": "2000x1500",
        "median_rel_err": 0.004 if good else 0.02, "p90_rel_err": 0.01 if good else 0.05,
        "within_sigma": 0.7 if good else 0.3, "captures": 10, "measured": 9 if good else 6,
        "gated": 1 if good else 4, "gate_reasons": json.dumps({"measure: ZNCC": 1 if good else 4}),
        "max_abs_err_over_sigma": 2.0 if good else 5.0, "over_4_sigma": 0 if good else 1,
        "observations": 40,
    }


def test_parse_seeds_and_errors() -> None:
    assert mb.parse_seeds("1000-1019") == tuple(range(1000, 1020))
    assert mb.parse_seeds("5, 2-3") == (2, 3, 5)
    for bad in ("10-2", "a-b", "", "1-"):
        with pytest.raises(InputError, match="--seeds"):
            mb.parse_seeds(bad)


def test_demo_quick_config_is_the_demos() -> None:
    assert mb.demo_quick_config() == QUICK  # the bench runs what `phonestereo demo` runs


def test_bench_rows_distribution_figure_and_resume(tmp_path, monkeypatch) -> None:
    monkeypatch.setattr(mb, "module_row", _fake_row)
    res = mb.run_module_bench((10, 11, 12, 13), tmp_path / "b")
    assert res.n_run == 4
    by_seed = {r["seed"]: r for r in res.rows}
    assert by_seed[13]["status"] == "failed" and "rendering crashed" in by_seed[13]["reason"]
    acc = res.distribution["acceptance"]
    # seeds 10, 12 good; 11 bad; 13 failed (not counted among the 3 ok modules)
    assert acc == {"median_le_1pct": 2, "p90_le_2p5pct": 2, "within_sigma_50_90pct": 2,
                   "captures_over_4_sigma": 1, "measured_fraction": round(24 / 30, 4),
                   "of_modules": 3}
    assert res.distribution["gate_reasons"] == {"measure: ZNCC": 6}
    assert res.distribution["quantiles"]["median_rel_err"]["max"] == 0.02
    for name in ("modules.csv", "distribution.json", "modules.png"):
        assert (tmp_path / "b" / name).is_file()
    again = mb.run_module_bench((10, 11, 12, 13), tmp_path / "b", retry_failed=False)
    assert again.n_run == 0  # resumed: every record kept
    other = tmp_path / "r.json"
    other.write_text(json.dumps({"focal_ratio": [5, 5]}))
    with pytest.raises(InputError, match="other ranges"):
        mb.run_module_bench((10,), tmp_path / "b", ranges_path=other)


def test_cli_bad_seeds_exit_2(tmp_path) -> None:
    r = CliRunner().invoke(app, ["bench", "modules", "--seeds", "9-3", "--out", str(tmp_path)])
    assert r.exit_code == 2 and "--seeds" in r.output


def test_cli_bad_ranges_exit_2_before_any_work(tmp_path) -> None:
    bad = tmp_path / "r.json"
    bad.write_text('{"baseline_mm": [30, 10]}')
    out = tmp_path / "out"
    args = ["bench", "modules", "--seeds", "1", "--ranges", str(bad), "--out", str(out)]
    r = CliRunner().invoke(app, args)
    assert r.exit_code == 2 and "baseline_mm" in r.output
    assert not out.exists()
