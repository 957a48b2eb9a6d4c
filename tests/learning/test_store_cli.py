"""`phonestereo store stats|export|vacuum` (docs/fix-store.md)."""

from __future__ import annotations

import json
from pathlib import Path

from typer.testing import CliRunner

import phonestereo.cli.store  # noqa: F401  (registers `store` until cli/__init__ imports it)
from phonestereo.cli.app import app
from phonestereo.learning.observation import Observation
from phonestereo.learning.store import FixStore

runner = CliRunner()


def make_obs(cid: str, n: int, seed: int = 0, orientation: str = "landscape") -> list:
    """n observations at 2 m (9 px expected, 8.6 measured)."""
    return [
        Observation(100.0 * i, 50.0 * i + seed, 8.6, 9.0, 2.0, orientation, "g1", 200.0, None, cid)
        for i in range(n)
    ]


def _store(tmp_path: Path) -> Path:
    path = tmp_path / "fixes.db"
    with FixStore(path) as st:
        st.add_capture("f01", make_obs("f01", 6))
        st.add_capture("f02", make_obs("f02", 4, seed=1, orientation="landscape-flipped"))
    return path


def test_stats_text_and_json(tmp_path: Path) -> None:
    path = _store(tmp_path)
    res = runner.invoke(app, ["store", "stats", str(path)])
    assert res.exit_code == 0, res.output
    assert "2 captures, 10 observations" in res.output and "landscape-flipped" in res.output
    assert "integrity: ok" in res.output
    res = runner.invoke(app, ["store", "stats", str(path), "--json"])
    doc = json.loads(res.output)
    assert doc["n_observations"] == 10 and doc["by_orientation"]["landscape"]["n"] == 6
    assert doc["schema_version"] == 2 and doc["integrity"] == "ok"


def test_export_and_vacuum(tmp_path: Path) -> None:
    path = _store(tmp_path)
    res = runner.invoke(app, ["store", "export", str(path), "--out", str(tmp_path / "o.json")])
    assert res.exit_code == 0 and "wrote 10 observations" in res.output
    assert len(json.loads((tmp_path / "o.json").read_text())["observations"]) == 10
    res = runner.invoke(app, ["store", "export", str(path), "--out", str(tmp_path / "o.txt")])
    assert res.exit_code == 2 and ".csv or .json" in res.output
    res = runner.invoke(app, ["store", "vacuum", str(path)])
    assert res.exit_code == 0 and "vacuumed" in res.output
    with FixStore(path) as st:
        assert st.stats().n_observations == 10


def test_errors_exit_2_and_never_create(tmp_path: Path) -> None:
    missing = tmp_path / "nope.db"
    res = runner.invoke(app, ["store", "stats", str(missing)])
    assert res.exit_code == 2 and "does not exist" in res.output and not missing.exists()
    junk = tmp_path / "junk.db"
    junk.write_bytes(b"not a database at all" * 100)
    res = runner.invoke(app, ["store", "vacuum", str(junk)])
    assert res.exit_code == 2 and "not an SQLite database" in res.output
    assert junk.read_bytes() == b"not a database at all" * 100
