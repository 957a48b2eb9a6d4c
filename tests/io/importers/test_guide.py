"""The "Use your own phone" guide runs as written on the virtual phone's dumps, and the
imported Android set scores like the native one."""

from __future__ import annotations

import os
import shlex
import shutil
from pathlib import Path
from typing import Any

import pytest
from typer.testing import CliRunner

from phonestereo.cli import app

GUIDE = Path(__file__).resolve().parents[3] / "docs" / "own-phone.md"
MARK = "<!-- guide:virtual-phone -->"


def guide_commands() -> list[list[str]]:
    """The shell lines of the guide's marked block, split like a shell."""
    text = GUIDE.read_text(encoding="utf-8")
    block = text[text.index(MARK) :].split("```sh\n", 1)[1].split("```", 1)[0]
    return [shlex.split(line) for line in block.splitlines() if line.strip()]


def test_the_guide_block_holds_the_whole_path() -> None:
    verbs = [cmd[1] for cmd in guide_commands()]
    assert all(cmd[0] == "phonestereo" for cmd in guide_commands())
    assert verbs == ["simulate", "import", "check-set", "learn", "depth", "import"]


@pytest.fixture(scope="module")
def guide_run(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, list[Any]]:
    cwd = tmp_path_factory.mktemp("guide")
    old = Path.cwd()
    os.chdir(cwd)
    try:
        results = [CliRunner().invoke(app, cmd[1:]) for cmd in guide_commands()]
    finally:
        os.chdir(old)
    return cwd, results


@pytest.mark.slow  # renders the quick thesis bench (~1-2 min)
def test_every_guide_command_succeeds(guide_run: tuple[Path, list[Any]]) -> None:
    cwd, results = guide_run
    for cmd, r in zip(guide_commands(), results, strict=True):
        # `depth` exits 1 when a capture is gated (docs/own-phone.md says so): the quick
        # virtual phone learns its faces at one distance, so the charts far from it are gated
        # `extrapolation` with the learned range in the reason instead of answered (issue #18)
        ok = (0, 1) if cmd[1] == "depth" else (0,)
        assert r.exit_code in ok, (cmd, r.output)
    assert "extrapolation" in results[4].output or results[4].exit_code == 0
    assert (cwd / "my_set" / "calibration.json").is_file()
    assert (cwd / "my_iphone_set" / "manifest.json").is_file()
    assert "m" in results[4].output  # depth printed its table


@pytest.mark.slow  # scores both sets (~40 s)
def test_imported_android_set_scores_like_the_native_set(guide_run: tuple[Path, list[Any]]) -> None:
    from phonestereo.evaluation.bench import run_bench

    cwd, _ = guide_run
    shutil.copy(cwd / "virtual_phone" / "ground_truth.json", cwd / "my_set")  # this test only
    native, imported = run_bench(cwd / "virtual_phone"), run_bench(cwd / "my_set")
    for stage in ("naive", "measured", "full"):
        for stat in ("median_rel_err", "p90_rel_err"):
            a, b = native["stages"][stage][stat], imported["stages"][stage][stat]
            if a is None or b is None:  # every capture of the stage gated: in both sets
                assert a is None and b is None, (stage, stat, a, b)
                continue
            assert abs(a - b) <= 0.0005, (stage, stat, a, b)  # 0.05 percentage points
    for a, b in zip(native["captures"], imported["captures"], strict=True):
        assert a["capture_id"] == b["capture_id"] and a["ok"] == b["ok"]
        if a["ok"]:
            assert abs(a["rel_err"] - b["rel_err"]) <= 0.0005
