"""The fix store (docs/fix-store.md): round trips, re-learning, migration, damaged files."""

from __future__ import annotations

import csv
import json
import math
import os
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from phonestereo.errors import InputError, StoreError
from phonestereo.learning import store as store_mod
from phonestereo.learning.observation import Observation, array_to_observations
from phonestereo.learning.store import FixStore
from phonestereo.learning.store_schema import SCHEMA_VERSION

# The v1 schema exactly as the first release wrote it (a frozen snapshot, not the migration
# code): a store written by that release must open, migrate and keep every row.
V1_SQL = """
CREATE TABLE schema_version (version INTEGER NOT NULL, applied_unix REAL NOT NULL);
CREATE TABLE captures (capture_id TEXT PRIMARY KEY, learned_unix REAL NOT NULL,
  n_observations INTEGER NOT NULL);
CREATE TABLE observations (id INTEGER PRIMARY KEY, capture_id TEXT NOT NULL
  REFERENCES captures(capture_id) ON DELETE CASCADE, x_px REAL NOT NULL, y_px REAL NOT NULL,
  d_measured_px REAL NOT NULL, d_expected_px REAL NOT NULL, depth_m REAL NOT NULL,
  orientation TEXT NOT NULL, focus_group TEXT NOT NULL, time_s REAL NOT NULL,
  temperature_c REAL);
CREATE INDEX observations_capture ON observations(capture_id);
CREATE INDEX observations_bucket ON observations(orientation, focus_group);
INSERT INTO schema_version VALUES (1, 0.0);
"""


def make_obs(cid: str, n: int, seed: int = 0, orientation: str = "landscape") -> list[Observation]:
    """n face observations at 1–3 m (f·B = 18 px·m) with a small offset."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(1.0, 3.0, n)
    d_exp = 18.0 / z
    return [
        Observation(
            x_px=float(rng.uniform(0, 2000)),
            y_px=float(rng.uniform(0, 1500)),
            d_measured_px=float(d_exp[i] - 0.4 + rng.normal(0, 0.05)),
            d_expected_px=float(d_exp[i]),
            depth_m=float(z[i]),
            orientation=orientation,
            focus_group="g1",
            time_s=200.0 + i,
            temperature_c=None if i % 2 else 41.5,
            capture_id=cid,
            source="face-chart",
            sigma_px=0.05 if i % 3 else math.nan,
        )
        for i in range(n)
    ]


def test_round_trip_and_wal(tmp_path: Path) -> None:
    obs = make_obs("f01", 7)
    with FixStore(tmp_path / "a" / "fixes.db") as st:  # missing parent folder is created
        assert st.add_capture("f01", obs) == 7
        back = array_to_observations(st.observations())
        stats = st.stats()
    # every field bit-exact, None temperature and NaN sigma included (repr: NaN != NaN)
    assert [repr(o) for o in back] == [repr(o) for o in obs]
    assert stats.journal_mode == "wal" and stats.schema_version == SCHEMA_VERSION
    assert (stats.n_captures, stats.n_observations) == (1, 7)
    assert stats.by_orientation["landscape"]["correction_mean_px"] == pytest.approx(0.4, abs=0.05)


def test_relearning_replaces_and_filters(tmp_path: Path) -> None:
    with FixStore(tmp_path / "s.db") as st:
        st.add_capture("f01", make_obs("f01", 5))
        st.add_capture("f02", make_obs("f02", 4, seed=1, orientation="landscape-flipped"))
        st.add_capture("f01", make_obs("f01", 3, seed=2))  # re-learn: replaces, not appends
        assert st.stats().n_observations == 7
        assert st.observations(capture_id="f01").shape == (3,)
        assert st.observations(orientation="landscape-flipped").shape == (4,)
        assert st.observations(orientation="landscape", focus_group="nope").shape == (0,)
        assert st.capture_ids() == ["f01", "f02"]
        st.add_capture("f03", [])  # learned, nothing found: recorded as such
        assert st.stats().n_captures == 3
        assert st.remove_capture("f02") and not st.remove_capture("f02")
        assert st.stats().n_observations == 3


def test_add_capture_rejects_bad_input(tmp_path: Path) -> None:
    with FixStore(tmp_path / "s.db") as st:
        with pytest.raises(InputError, match="own id"):
            st.add_capture("f02", make_obs("f01", 2))
        with pytest.raises(InputError, match="non-empty"):
            st.add_capture(" ", [])
    with pytest.raises(InputError, match="depth_m"):
        Observation(0, 0, 8.0, 9.0, -2.0, "landscape", "", 0.0, None, "c")


def test_failed_write_rolls_back(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "s.db"
    with FixStore(path) as st:
        st.add_capture("f01", make_obs("f01", 5))
        monkeypatch.setattr(store_mod, "_INSERT", "INSERT INTO no_such_table VALUES (?)")
        with pytest.raises(StoreError, match="rolled back"):
            st.add_capture("f02", make_obs("f02", 5))
        with pytest.raises(StoreError):  # re-learning f01 fails: its old rows must survive
            st.add_capture("f01", make_obs("f01", 5, seed=9))
    with FixStore(path) as st:
        assert st.capture_ids() == ["f01"] and st.stats().n_observations == 5
        assert np.allclose(
            st.observations()["x_px"], [o.x_px for o in make_obs("f01", 5)], rtol=0, atol=0
        )


def test_export_csv_json_and_vacuum(tmp_path: Path) -> None:
    with FixStore(tmp_path / "s.db") as st:
        st.add_capture("f01", make_obs("f01", 6))
        assert st.export(tmp_path / "o.csv") == 6
        assert st.export(tmp_path / "o.json") == 6
        with pytest.raises(InputError, match=r"\.csv or \.json"):
            st.export(tmp_path / "o.txt")
        before, after = st.vacuum()
        assert after > 0 and before > 0
    rows = list(csv.DictReader((tmp_path / "o.csv").open()))
    assert len(rows) == 6 and rows[1]["temperature_c"] == "" and rows[0]["orientation"]
    doc = json.loads((tmp_path / "o.json").read_text())
    assert doc["schema_version"] == SCHEMA_VERSION and doc["captures"][0]["n_observations"] == 6
    assert doc["observations"][0]["sigma_px"] is None  # NaN → null, valid JSON


def _write_v1(path: Path) -> None:
    conn = sqlite3.connect(path)
    conn.executescript(V1_SQL)
    conn.execute("INSERT INTO captures VALUES ('old1', 1.0, 2)")
    rows = [("old1", 10.0, 20.0, 8.0, 9.0, 2.0, "landscape", "g", 190.0, None)] * 2
    conn.executemany(
        "INSERT INTO observations (capture_id, x_px, y_px, d_measured_px, d_expected_px, "
        "depth_m, orientation, focus_group, time_s, temperature_c) VALUES (?,?,?,?,?,?,?,?,?,?)",
        rows,
    )
    conn.commit()
    conn.close()


def test_v1_store_is_migrated_with_backup(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    _write_v1(path)
    with FixStore(path) as st:
        assert st.schema_version == 2 and st.backup_path == tmp_path / "old.db.v1.bak"
        old = st.observations()
        assert old.shape == (2,) and set(old["source"]) == {"unknown"}
        assert np.isnan(old["sigma_px"]).all() and np.isnan(old["temperature_c"]).all()
        st.add_capture("new", make_obs("new", 3))
        assert st.stats().n_observations == 5
    bak = sqlite3.connect(st.backup_path)
    assert bak.execute("SELECT MAX(version) FROM schema_version").fetchone()[0] == 1
    assert bak.execute("SELECT COUNT(*) FROM observations").fetchone()[0] == 2
    bak.close()


def test_readonly_open_of_old_or_missing_store(tmp_path: Path) -> None:
    path = tmp_path / "old.db"
    _write_v1(path)
    with pytest.raises(StoreError, match="open it writable once to migrate"):
        FixStore(path, readonly=True)
    with pytest.raises(StoreError, match="does not exist"):
        FixStore(tmp_path / "none.db", readonly=True)
    assert not (tmp_path / "none.db").exists()


def test_newer_schema_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "s.db"
    FixStore(path).close()
    conn = sqlite3.connect(path)
    conn.execute("INSERT INTO schema_version VALUES (?, 0)", (SCHEMA_VERSION + 1,))
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match="upgrade phonestereo"):
        FixStore(path)


def test_not_a_database_is_reported_and_kept(tmp_path: Path) -> None:
    path = tmp_path / "fixes.db"
    junk = np.random.default_rng(0).bytes(8192)
    path.write_bytes(junk)
    with pytest.raises(StoreError, match=r"fixes\.db.*not an SQLite database.*move it"):
        FixStore(path)
    assert path.read_bytes() == junk  # never recreated


def test_damaged_pages_are_reported_and_kept(tmp_path: Path) -> None:
    path = tmp_path / "fixes.db"
    with FixStore(path) as st:
        for i in range(40):
            st.add_capture(f"c{i}", make_obs(f"c{i}", 20, seed=i))
    assert not (tmp_path / "fixes.db-wal").exists()  # checkpointed on close
    data = bytearray(path.read_bytes())
    page = 4096
    rng = np.random.default_rng(1)
    data[2 * page : 2 * page + 3 * page] = rng.bytes(3 * page)  # header page intact
    path.write_bytes(bytes(data))
    with pytest.raises(StoreError, match=r"damaged.*integrity_check.*\.recover"):
        FixStore(path)
    assert path.read_bytes() == bytes(data)
    half = bytes(data[: len(data) // 2])  # a truncated copy
    path.write_bytes(half)
    with pytest.raises(StoreError, match=r"damaged.*malformed"):
        FixStore(path)
    assert path.read_bytes() == half


def test_foreign_sqlite_database_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "other.db"
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE photos (id INTEGER)")
    conn.commit()
    conn.close()
    with pytest.raises(StoreError, match="no schema_version"):
        FixStore(path)


def test_unwritable_paths_give_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(StoreError, match="is a folder"):
        FixStore(tmp_path)
    blocker = tmp_path / "file"
    blocker.write_text("x")
    with pytest.raises(StoreError, match="cannot create the folder"):
        FixStore(blocker / "sub" / "fixes.db")
    path = tmp_path / "s.db"
    with FixStore(path) as st:
        st.add_capture("f01", make_obs("f01", 4))
    with FixStore(path, readonly=True) as ro:
        with pytest.raises(StoreError, match="read-only"):
            ro.add_capture("f02", make_obs("f02", 4))
        assert ro.stats().n_observations == 4


def test_unwritable_file_or_folder_simulated(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # root (this CI) ignores permissions, so deny write access the way os.access reports it
    path = tmp_path / "s.db"
    with FixStore(path) as st:
        st.add_capture("f01", make_obs("f01", 4))
    real = os.access
    monkeypatch.setattr(os, "access", lambda p, mode: real(p, mode) and Path(p) != path)
    with pytest.raises(StoreError, match=r"s\.db' is not writable.*chmod u\+w.*untouched"):
        FixStore(path)
    monkeypatch.setattr(os, "access", lambda p, mode: real(p, mode) and Path(p) != tmp_path)
    with pytest.raises(StoreError, match=r"folder .* is not writable"):
        FixStore(path)
    with pytest.raises(StoreError, match=r"folder .* is not writable"):
        FixStore(tmp_path / "new.db")
    monkeypatch.undo()
    with FixStore(path) as st:  # nothing learned was lost
        assert st.stats().n_observations == 4


@pytest.mark.skipif(os.geteuid() == 0, reason="root ignores file permissions")
def test_read_only_file_keeps_its_contents(tmp_path: Path) -> None:
    path = tmp_path / "s.db"
    with FixStore(path) as st:
        st.add_capture("f01", make_obs("f01", 4))
    path.chmod(0o444)
    try:
        with pytest.raises(StoreError, match="not writable"):
            FixStore(path)
        with FixStore(path, readonly=True) as ro:
            assert ro.stats().n_observations == 4
    finally:
        path.chmod(0o644)


def test_busy_store_times_out_with_message(tmp_path: Path) -> None:
    path = tmp_path / "s.db"
    FixStore(path).close()
    other = sqlite3.connect(path, isolation_level=None)
    other.execute("BEGIN IMMEDIATE")  # another process holding the write lock
    try:
        with FixStore(path, timeout_s=0.3) as st:
            with pytest.raises(StoreError, match="held its lock"):
                st.add_capture("f01", make_obs("f01", 2))
            other.execute("COMMIT")
            assert st.add_capture("f01", make_obs("f01", 2)) == 2
    finally:
        other.close()
