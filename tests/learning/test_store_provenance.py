"""Provenance in the fix store (issue #19 item 2): contexts, capture-set fingerprints, the
v2 → v3 migration of a file written by the old code, and foreign or read-only files."""

from __future__ import annotations

import shutil
import sqlite3
from pathlib import Path

import numpy as np
import pytest

from phonestereo.errors import ContextError, StoreError
from phonestereo.learning import store_schema
from phonestereo.learning.observation import Observation
from phonestereo.learning.provenance import StoreContext
from phonestereo.learning.store import FixStore
from phonestereo.learning.store_schema import MIGRATIONS, SCHEMA_VERSION, UNRECORDED

FIXTURE_V2 = Path(__file__).parents[1] / "data" / "fix_store_v2.sqlite"

CAL = '{"T_tele_wide":{"t":[0.012,0,0]},"tele":{"K":[[2800.0,0,1000]]},"wide":{"K":[[1500.0]]}}'
CTX = StoreContext(CAL, "opencv5/opencv5", "canonical", '{"warmup_s":180.0}')
CAL_1PC = CAL.replace("2800.0", "2828.0")  # tele focal length 1 % longer


def make_obs(cid: str, n: int, seed: int = 0) -> list[Observation]:
    """n observations at 1-3 m (f·B = 18 px·m), measured 0.4 px short."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(1.0, 3.0, n)
    return [
        Observation(
            float(rng.uniform(0, 2000)),
            float(rng.uniform(0, 1500)),
            18 / zi - 0.4,
            18 / zi,
            float(zi),
            "landscape",
            "g1",
            200.0,
            None,
            cid,
        )
        for zi in z
    ]


def _schema(conn: sqlite3.Connection) -> dict[str, object]:
    """Columns, indexes and foreign keys of every table (independent of the SQL text)."""
    tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")]
    return {
        t: (
            conn.execute(f"PRAGMA table_info({t})").fetchall(),
            sorted(
                conn.execute(f"PRAGMA index_info({i[1]})").fetchall()
                for i in conn.execute(f"PRAGMA index_list({t})").fetchall()
            ),
            conn.execute(f"PRAGMA foreign_key_list({t})").fetchall(),
        )
        for t in sorted(tables)
    }


def test_new_file_schema_equals_the_migrated_one(tmp_path: Path) -> None:
    # A new store is created from CURRENT_SCHEMA directly: it must be the schema the
    # migrations build, column for column (else old and new stores would drift apart).
    FixStore(tmp_path / "new.db").close()
    conn = sqlite3.connect(tmp_path / "mig.db")
    for i, step in enumerate(MIGRATIONS):
        if i == 0:
            conn.executescript(";".join(step))
        else:
            for sql in step:
                conn.execute(sql)
    conn.commit()
    new = sqlite3.connect(tmp_path / "new.db")
    assert _schema(new) == _schema(conn)


def test_store_written_by_old_main_is_migrated(tmp_path: Path) -> None:
    path = tmp_path / "fixes.sqlite"
    shutil.copy(FIXTURE_V2, path)
    with FixStore(path) as st:
        assert st.schema_version == SCHEMA_VERSION == 6
        assert st.backup_path == tmp_path / "fixes.sqlite.v2.bak"
        s = st.stats()
        # every row the old code wrote is kept: 3 captures (one empty), 5 + 4 observations
        assert (s.n_captures, s.n_observations) == (3, 9)
        assert [(c["recorded"], c["n_captures"]) for c in s.contexts] == [(False, 3)]
        assert s.sets == [
            {**s.sets[0], "context_id": 1, "fingerprint": UNRECORDED, "n_observations": 9}
        ]
        # applying the old observations is allowed (nothing else in the store) with a warning
        choice = st.context_for_applying(CTX)
        assert choice.id == 1 and "cannot be checked" in choice.warning
        assert st.observations(context_id=1).shape == (9,)
        # the radial shift the old code took out was not recorded: NaN, left as learned
        assert np.isnan(st.observations(context_id=1)["radial_px"]).all()
        # nor the row error each was measured with (schema 6): NaN, no row centring from them
        assert np.isnan(st.observations(context_id=1)["e_measured_px"]).all()
        # learning beside them needs a new context: their calibration is unknown
        with pytest.raises(ContextError, match=r"before contexts were recorded.*--new-context"):
            st.context_for_learning(CTX)
        new = st.context_for_learning(CTX, new=True)
        st.add_capture("IMG_0001", make_obs("IMG_0001", 2), context_id=new, set_fingerprint="a")
        assert st.context_for_applying(CTX).id == new
        assert st.observations(context_id=new).shape == (2,)
    bak = sqlite3.connect(tmp_path / "fixes.sqlite.v2.bak")
    assert bak.execute("SELECT MAX(version) FROM schema_version").fetchone()[0] == 2
    bak.close()


def test_colliding_capture_ids_from_two_sets_add_up(tmp_path: Path) -> None:
    # Real phones reuse IMG_0001: two sets with the same ids must not replace each other.
    with FixStore(tmp_path / "s.db") as st:
        cid = st.context_for_learning(CTX)
        for fp, seed in (("set-a", 0), ("set-b", 1)):
            for k in range(3):
                name = f"IMG_000{k}"
                st.add_capture(
                    name,
                    make_obs(name, 4, seed=seed + 10 * k),
                    context_id=cid,
                    set_fingerprint=fp,
                    set_folder=f"/sets/{fp}",
                )
        s = st.stats()
        assert (s.n_captures, s.n_observations) == (6, 24)  # 2 sets × 3 captures × 4
        assert [(x["fingerprint"], x["n_captures"], x["n_observations"]) for x in s.sets] == [
            ("set-a", 3, 12),
            ("set-b", 3, 12),
        ]
        # re-learning one set's capture replaces only that capture of that set
        st.add_capture("IMG_0000", make_obs("IMG_0000", 1), context_id=cid, set_fingerprint="set-a")
        assert st.stats().n_observations == 21


def test_learning_under_another_context_is_refused_naming_the_field(tmp_path: Path) -> None:
    with FixStore(tmp_path / "s.db") as st:
        a = st.context_for_learning(CTX)
        assert st.context_for_learning(CTX) == a  # the same context again: the same id
        st.add_capture("f01", make_obs("f01", 3), context_id=a, set_fingerprint="x")
        other = StoreContext(CAL_1PC, CTX.lens_model, CTX.rectification_mode, CTX.flow_config)
        want = r"calibration: tele\.K\[0\]\[0\] is 2800\.0 in the store, 2828\.0 given"
        with pytest.raises(ContextError, match=want + ".*--new-context.*Nothing was written"):
            st.context_for_learning(other)
        with pytest.raises(ContextError, match=r"calibration: tele\.K\[0\]\[0\] is 2800\.0"):
            st.context_for_applying(other)
        cfg = StoreContext(CAL, CTX.lens_model, CTX.rectification_mode, '{"warmup_s":60.0}')
        with pytest.raises(ContextError, match=r"flow config: warmup_s is 180\.0 in the store"):
            st.context_for_applying(cfg)
        mode = StoreContext(CAL, CTX.lens_model, "tele-to-wide", CTX.flow_config)
        with pytest.raises(ContextError, match="rectification mode: 'canonical' in the store"):
            st.context_for_applying(mode)
        b = st.context_for_learning(other, new=True)
        st.add_capture("f01", make_obs("f01", 5), context_id=b, set_fingerprint="x")
        assert st.context_for_applying(other).id == b and st.context_for_applying(CTX).id == a
        assert st.observations(context_id=b).shape == (5,)
        assert len(st.stats().contexts) == 2


def _foreign(path: Path) -> bytes:
    conn = sqlite3.connect(path)
    conn.execute("CREATE TABLE photos (id INTEGER, name TEXT)")
    conn.execute("INSERT INTO photos VALUES (1, 'a')")
    conn.commit()
    conn.close()
    return path.read_bytes()


@pytest.mark.parametrize("readonly", [False, True])
def test_foreign_sqlite_file_is_never_switched_to_wal(tmp_path: Path, readonly: bool) -> None:
    # Today's main switched another application's database to WAL (header bytes 18-19
    # become 2) before finding it was not a store; it must stay byte-identical.
    path = tmp_path / "photos.db"
    before = _foreign(path)
    with pytest.raises(StoreError, match=r"not a phonestereo fix store.*left untouched"):
        FixStore(path, readonly=readonly)
    assert path.read_bytes() == before
    assert not (tmp_path / "photos.db-wal").exists()


def test_read_only_mount_messages(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    path = tmp_path / "s.db"
    with FixStore(path) as st:
        st.add_capture("f01", make_obs("f01", 4))
    # A read-only mount as the store code sees it (containers cannot mount one): statvfs
    # reports ST_RDONLY and os.access denies writing.
    monkeypatch.setattr(store_schema, "filesystem_read_only", lambda p: True)
    real = store_schema.os.access
    monkeypatch.setattr(store_schema.os, "access", lambda p, m: real(p, m) and not m & 2)
    with pytest.raises(StoreError, match="read-only file system; chmod cannot help") as err:
        FixStore(path)
    assert "chmod u+w" not in str(err.value)
    with FixStore(path, readonly=True) as ro:  # opened immutable: no -shm file needed
        assert ro.stats().n_observations == 4
    exc = sqlite3.OperationalError("unable to open database file")
    exc.sqlite_errorcode = sqlite3.SQLITE_CANTOPEN  # type: ignore[attr-defined]
    msg = str(store_schema.store_error(path, exc, "read", 1.0))
    assert "rolled back" not in msg and "Nothing was changed" in msg
