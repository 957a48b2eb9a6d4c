"""A fast, quiet command line: lazy command modules, the same top-level help, no native logs."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from phonestereo.cli import app
from phonestereo.cli.app import discover, import_all

DATA = Path(__file__).resolve().parents[3] / "shared" / "data" / "faces"
HEAVY = ("mediapipe", "dask", "scipy", "cv2", "matplotlib")


def test_lazy_listing_equals_every_registered_command() -> None:
    # The lazy listing (read from the sources) must name every command the modules register,
    # with the same short help: no command may go missing from `phonestereo --help`.
    lazy = {c.name: c.help for c in discover().values()}
    import_all()
    eager = typer.main.get_command(app)
    assert isinstance(eager, typer.core.TyperGroup)
    registered = dict(eager.commands)
    assert set(registered) - {"version"} == set(lazy)
    for name, cmd in registered.items():
        if name != "version":
            assert (cmd.help or "").strip().split("\n\n")[0] == lazy[name], name
    assert len(lazy) >= 18  # 18 commands and groups (+ version) on today's main


def test_top_level_help_lists_every_command() -> None:
    res = CliRunner().invoke(app, ["--help"], terminal_width=200)
    assert res.exit_code == 0, res.output
    for name in [*discover(), "version"]:
        assert f" {name} " in res.output, name


def test_help_and_version_import_no_heavy_module() -> None:
    # The start-up cost is the import of the command modules (MediaPipe, Dask, SciPy: ~2 s);
    # `--help` and `version` must not import any of them (checked in a fresh interpreter).
    code = (
        "import sys\n"
        "from typer.testing import CliRunner\n"
        "from phonestereo.cli import app\n"
        "for args in (['--help'], ['version']):\n"
        "    assert CliRunner().invoke(app, args).exit_code == 0\n"
        f"print(' '.join(sorted(m for m in sys.modules if m.split('.')[0] in {HEAVY!r})))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "", out.stdout


def test_a_command_still_runs_and_its_help_loads() -> None:
    res = CliRunner().invoke(app, ["store", "--help"])
    assert res.exit_code == 0 and "vacuum" in res.output
    res = CliRunner().invoke(app, ["no-such-command"])
    assert res.exit_code == 2 and "No such command" in res.output


@pytest.mark.skipif(not DATA.exists(), reason="shared/data not beside the clone")
def test_faces_prints_nothing_to_stderr() -> None:
    # A normal run is quiet: MediaPipe / TFLite / absl write ~6 lines to fd 2 unless --verbose.
    exe = Path(sys.executable).with_name("phonestereo")
    img = DATA / "interfaces_001.jpg"
    out = subprocess.run(
        [str(exe), "faces", str(img), "--json"], capture_output=True, text=True, check=True
    )
    assert out.stderr == ""
    assert json.loads(out.stdout)["n_faces"] == 1
    loud = subprocess.run(
        [str(exe), "--verbose", "faces", str(img), "--json"], capture_output=True, text=True
    )
    assert "TensorFlow Lite" in loud.stderr or "W0000" in loud.stderr  # --verbose shows them
