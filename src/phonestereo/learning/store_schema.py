"""The fix store's schema, migrations and SQLite error handling (docs/fix-store.md).

Kept apart from :mod:`phonestereo.learning.store` so the schema history reads in one place:
:data:`MIGRATIONS` entry i takes a file from version i to i + 1 (version 0 = an empty file);
each runs inside the write transaction that records the new version, so it applies fully or
not at all. To change the schema, append a migration and bump :data:`SCHEMA_VERSION`.
"""

from __future__ import annotations

import os
import random
import sqlite3
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

from phonestereo.errors import StoreError

T = TypeVar("T")

#: The schema this code writes; older files are migrated on open.
SCHEMA_VERSION = 6
#: The first 16 bytes of every SQLite database file.
SQLITE_MAGIC = b"SQLite format 3\x00"

#: The set fingerprint and context note of captures learned before schema v3.
UNRECORDED = "unrecorded"
LEGACY_NOTE = (
    "learned before schema v3: the calibration, lens model, rectification mode and flow "
    "configuration were not recorded"
)

MIGRATIONS: tuple[tuple[str, ...], ...] = (
    (  # 0 → 1: the thesis's observation (sensor position, disparities, depth, conditions)
        "CREATE TABLE schema_version (version INTEGER NOT NULL, applied_unix REAL NOT NULL)",
        "CREATE TABLE captures (capture_id TEXT PRIMARY KEY, learned_unix REAL NOT NULL, "
        "n_observations INTEGER NOT NULL)",
        "CREATE TABLE observations (id INTEGER PRIMARY KEY, capture_id TEXT NOT NULL "
        "REFERENCES captures(capture_id) ON DELETE CASCADE, x_px REAL NOT NULL, "
        "y_px REAL NOT NULL, d_measured_px REAL NOT NULL, d_expected_px REAL NOT NULL, "
        "depth_m REAL NOT NULL, orientation TEXT NOT NULL, focus_group TEXT NOT NULL, "
        "time_s REAL NOT NULL, temperature_c REAL)",
        "CREATE INDEX observations_capture ON observations(capture_id)",
        "CREATE INDEX observations_bucket ON observations(orientation, focus_group)",
    ),
    (  # 1 → 2: per-observation uncertainty and where the expected disparity came from
        "ALTER TABLE observations ADD COLUMN sigma_px REAL",
        "ALTER TABLE observations ADD COLUMN source TEXT NOT NULL DEFAULT 'unknown'",
    ),
    (  # 2 → 3: provenance. Contexts (calibration, lens model, rectification mode, flow
        # config) and captures keyed by (context, capture-set fingerprint, capture id). What
        # older versions learned goes into context 1 with every field unrecorded (NULL) and
        # the set fingerprint 'unrecorded'; nothing is dropped.
        "CREATE TABLE contexts (id INTEGER PRIMARY KEY, created_unix REAL NOT NULL, "
        "calibration_sha256 TEXT, calibration TEXT, lens_model TEXT, rectification_mode TEXT, "
        "flow_config_sha256 TEXT, flow_config TEXT, note TEXT NOT NULL DEFAULT '')",
        "INSERT INTO contexts (id, created_unix, note) SELECT 1, MIN(learned_unix), "
        f"'{LEGACY_NOTE}' FROM captures HAVING COUNT(*) > 0",
        "CREATE TABLE captures_v3 (context_id INTEGER NOT NULL REFERENCES contexts(id), "
        "set_fingerprint TEXT NOT NULL, capture_id TEXT NOT NULL, "
        "set_folder TEXT NOT NULL DEFAULT '', learned_unix REAL NOT NULL, "
        "n_observations INTEGER NOT NULL, PRIMARY KEY (context_id, set_fingerprint, capture_id))",
        f"INSERT INTO captures_v3 SELECT 1, '{UNRECORDED}', capture_id, '', learned_unix, "
        "n_observations FROM captures",
        "CREATE TABLE observations_v3 (id INTEGER PRIMARY KEY, context_id INTEGER NOT NULL, "
        "set_fingerprint TEXT NOT NULL, capture_id TEXT NOT NULL, x_px REAL NOT NULL, "
        "y_px REAL NOT NULL, d_measured_px REAL NOT NULL, d_expected_px REAL NOT NULL, "
        "depth_m REAL NOT NULL, orientation TEXT NOT NULL, focus_group TEXT NOT NULL, "
        "time_s REAL NOT NULL, temperature_c REAL, sigma_px REAL, "
        "source TEXT NOT NULL DEFAULT 'unknown', "
        "FOREIGN KEY (context_id, set_fingerprint, capture_id) REFERENCES "
        "captures_v3 (context_id, set_fingerprint, capture_id) ON DELETE CASCADE)",
        f"INSERT INTO observations_v3 SELECT id, 1, '{UNRECORDED}', capture_id, x_px, y_px, "
        "d_measured_px, d_expected_px, depth_m, orientation, focus_group, time_s, "
        "temperature_c, sigma_px, source FROM observations",
        "DROP TABLE observations",
        "DROP TABLE captures",
        "ALTER TABLE captures_v3 RENAME TO captures",  # also renames the foreign key's target
        "ALTER TABLE observations_v3 RENAME TO observations",
        "CREATE INDEX observations_key ON observations(context_id, set_fingerprint, capture_id)",
        "CREATE INDEX observations_bucket ON observations(context_id, orientation, focus_group)",
    ),
    (  # 3 → 4: each capture's residual radial distortion (FlowConfig.radial_residual), JSON
        "ALTER TABLE captures ADD COLUMN radial TEXT",
    ),
    (  # 4 → 5: the radial shift each observation's d had taken out (NULL: not recorded)
        "ALTER TABLE observations ADD COLUMN radial_px REAL",
    ),
    (  # 5 → 6: the row error e each observation was measured with (NULL: not recorded)
        "ALTER TABLE observations ADD COLUMN e_measured_px REAL",
    ),
)
#: The current schema from nothing (a new file gets it directly, not through every migration:
#: no dropped tables, compact pages). tests/learning/test_store_migration.py checks that it
#: equals what the migrations build.
CURRENT_SCHEMA: tuple[str, ...] = (
    "CREATE TABLE schema_version (version INTEGER NOT NULL, applied_unix REAL NOT NULL)",
    MIGRATIONS[2][0],  # contexts
    *(
        sql.replace("captures_v3", "captures").replace("observations_v3", "observations")
        for sql in (MIGRATIONS[2][2], MIGRATIONS[2][4])
    ),
    *MIGRATIONS[2][-2:],
    *MIGRATIONS[3],
    *MIGRATIONS[4],
    *MIGRATIONS[5],
)
if len(MIGRATIONS) != SCHEMA_VERSION:  # pragma: no cover - a developer error
    raise RuntimeError("store_schema: one migration per schema version is required")


def read_schema_version(conn: sqlite3.Connection, path: Path) -> int:
    """The version recorded in the file (0 for an empty database).

    Raises
    ------
    StoreError
        The database holds other tables but no version (not a fix store).
    """
    tables = {r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type='table'")}
    if "schema_version" not in tables:
        if tables:
            raise corrupt_error(path, f"it has tables {sorted(tables)} but no schema_version")
        return 0
    v = conn.execute("SELECT MAX(version) FROM schema_version").fetchone()[0]
    if v is None:
        raise corrupt_error(path, "its schema_version table is empty")
    return int(v)


def migrate(conn: sqlite3.Connection, path: Path, target: int = SCHEMA_VERSION) -> int:
    """Apply the migrations from the file's version up to ``target``; call inside a write
    transaction (the version is re-read under the lock: another process may have migrated).

    Returns the version the file had.
    """
    v = read_schema_version(conn, path)
    if v == 0 and target == SCHEMA_VERSION:
        for sql in CURRENT_SCHEMA:
            conn.execute(sql)
        conn.execute("INSERT INTO schema_version VALUES (?, ?)", (target, time.time()))
        return v
    for i in range(v, target):
        for sql in MIGRATIONS[i]:
            conn.execute(sql)
        conn.execute("INSERT INTO schema_version VALUES (?, ?)", (i + 1, time.time()))
    return v


def backup_file(conn: sqlite3.Connection, path: Path, version: int) -> Path:
    """Copy the store to ``<name>.v<version>.bak`` before migrating it (kept if present)."""
    dest = path.with_name(f"{path.name}.v{version}.bak")
    if dest.exists():
        return dest
    try:
        out = sqlite3.connect(str(dest))
        try:
            conn.backup(out)
        finally:
            out.close()
    except sqlite3.Error as exc:
        raise StoreError(
            f"cannot back up the fix store '{path}' to '{dest}' before migrating it ({exc}); "
            "free space or make the folder writable. The store is untouched."
        ) from exc
    return dest


def is_busy(exc: BaseException) -> bool:
    """True for SQLITE_BUSY / SQLITE_LOCKED (another connection holds the lock)."""
    if not isinstance(exc, sqlite3.OperationalError):
        return False
    code = getattr(exc, "sqlite_errorcode", None)
    if code is not None:
        return (code & 0xFF) in (sqlite3.SQLITE_BUSY, sqlite3.SQLITE_LOCKED)
    return "locked" in str(exc) or "busy" in str(exc)


def retry_busy(fn: Callable[[], T], timeout_s: float) -> T:
    """Call ``fn`` until it does not fail with a busy/locked error, backing off exponentially
    (2 ms doubling to 200 ms, jittered) for at most ``timeout_s``; then re-raise."""
    deadline = time.monotonic() + timeout_s
    delay = 0.002
    while True:
        try:
            return fn()
        except sqlite3.OperationalError as exc:
            if not is_busy(exc) or time.monotonic() > deadline:
                raise
        time.sleep(delay * (0.5 + random.random()))
        delay = min(2 * delay, 0.2)


def corrupt_error(path: Path, detail: str) -> StoreError:
    """The error for a damaged file: name it, say it was not touched, and what to do."""
    return StoreError(
        f"the fix store '{path}' is damaged or is not a phonestereo fix store: {detail}. "
        f"It was left untouched (a store is never recreated over an existing file): move it "
        f"aside (e.g. rename it to '{path.name}.corrupt') and learn into a new store, or salvage "
        f"what SQLite can still read with `sqlite3 '{path}' .recover > salvage.sql`."
    )


def filesystem_read_only(path: Path) -> bool:
    """True when ``path`` lies on a file system mounted read-only (chmod cannot help there)."""
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def store_error(path: Path, exc: BaseException, action: str, timeout_s: float) -> StoreError:
    """Translate an SQLite error raised while doing ``action`` into a StoreError with the fix.

    Only a write (``action`` starting with "write", "migrate" or "vacuum") can have rolled
    something back; a read says that nothing was changed.
    """
    msg = str(exc)
    code = getattr(exc, "sqlite_errorcode", 0) & 0xFF
    where = f"cannot {action} the fix store '{path}'"
    writing = action.split()[0] in ("write", "migrate", "vacuum")
    if code == sqlite3.SQLITE_READONLY or "readonly" in msg:
        if filesystem_read_only(path.parent):
            return StoreError(
                f"{where}: it is on a read-only file system ({msg}); copy it to a writable "
                "folder to learn into it. Nothing was changed."
            )
        return StoreError(
            f"{where}: it is read-only ({msg}); make the file and its folder writable. "
            "Nothing was changed."
        )
    if is_busy(exc):
        return StoreError(
            f"{where}: another process held its lock for more than {timeout_s:g} s; retry later. "
            "Nothing was changed."
        )
    if code == sqlite3.SQLITE_FULL:
        return StoreError(
            f"{where}: the disk is full; free space and retry. The last transaction was rolled "
            "back; earlier captures are intact."
        )
    if code in (sqlite3.SQLITE_CORRUPT, sqlite3.SQLITE_NOTADB) or "malformed" in msg:
        return corrupt_error(path, msg)
    if code == sqlite3.SQLITE_CANTOPEN and not writing:
        return StoreError(
            f"{where}: SQLite cannot open it for reading ({msg}); a store in WAL mode needs its "
            "folder writable (or the file on a read-only mount) to be read. Copy it to a "
            "writable folder. Nothing was changed."
        )
    if not writing:
        return StoreError(f"{where}: {msg}. Nothing was changed.")
    return StoreError(
        f"{where}: {msg}. The transaction was rolled back; earlier captures are intact."
    )


def _connect(p: Path, mode: str, timeout_s: float, immutable: bool = False) -> sqlite3.Connection:
    extra = "&immutable=1" if immutable else ""
    try:
        return sqlite3.connect(
            f"{p.resolve().as_uri()}?mode={mode}{extra}",
            uri=True,
            timeout=min(timeout_s, 5.0),  # busy handler per attempt; retry_busy bounds the total
            isolation_level=None,
        )
    except sqlite3.Error as exc:
        raise StoreError(f"cannot open the fix store '{p}': {exc}; check the path") from exc


def _not_writable(p: Path, what: str) -> StoreError:
    if filesystem_read_only(p if p.is_dir() else p.parent):
        return StoreError(
            f"the fix store '{p}' is on a read-only file system; chmod cannot help: copy it to "
            "a writable folder to learn into it (commands that only read it, such as `depth` "
            "and `store stats`, work where it is). Its contents are untouched."
        )
    if what == "file":
        return StoreError(
            f"the fix store '{p}' is not writable; make it writable (chmod u+w '{p}') or "
            "open it read-only to inspect it. Its contents are untouched."
        )
    return StoreError(
        f"the folder '{p.parent}' of the fix store '{p}' is not writable (SQLite keeps "
        "its journal beside the file); make the folder writable or choose another path"
    )


def verify_integrity(conn: sqlite3.Connection, path: Path, timeout_s: float) -> None:
    """``PRAGMA integrity_check``; a damaged file raises the StoreError saying what to do."""
    try:
        rows = [r[0] for r in conn.execute("PRAGMA integrity_check(20)")]
    except sqlite3.DatabaseError as exc:
        err = store_error(path, exc, "check", timeout_s)
        if "damaged" in str(err):  # the check itself could not read the file
            raise corrupt_error(path, f"PRAGMA integrity_check fails ({exc})") from exc
        raise err from exc
    if rows != ["ok"]:
        lines = [ln.strip() for r in rows for ln in str(r).splitlines() if ln[:3] != "***"]
        more = f" (+{len(lines) - 3} more)" if len(lines) > 3 else ""
        raise corrupt_error(path, f"PRAGMA integrity_check reports {'; '.join(lines[:3])}{more}")


def open_connection(
    path: Path, readonly: bool, timeout_s: float, verify: bool = True
) -> sqlite3.Connection:
    """Check the path, then connect in autocommit mode (transactions are explicit), with
    foreign keys on and, for writing, the WAL journal and ``synchronous=FULL``.

    Creates the file (and missing parent folders) only when it does not exist and
    ``readonly`` is false. An existing file is first opened read-only and checked to be a
    fix store (or an empty database): another application's SQLite file is refused before
    anything is written to it (its journal mode is never switched to WAL); with ``verify``
    its integrity is checked first (:func:`verify_integrity`). On a read-only
    file system a read-only store is opened ``immutable`` (no -shm file is needed).

    Raises
    ------
    StoreError
        The path is a folder, unreadable, not writable, not an SQLite file or not a fix
        store, or absent when ``readonly``; the message names the path and the fix.
    """
    p = path
    if p.is_dir():
        raise StoreError(f"fix store path '{p}' is a folder; give a file such as '{p}/fixes.db'")
    if p.exists():
        try:
            with p.open("rb") as fh:
                head = fh.read(len(SQLITE_MAGIC))
        except OSError as exc:
            raise StoreError(
                f"cannot read the fix store '{p}' ({exc.strerror}); check its permissions"
            ) from exc
        if head and head != SQLITE_MAGIC:
            raise corrupt_error(p, "it is not an SQLite database (wrong file header)")
        if not readonly and not os.access(p, os.W_OK):
            raise _not_writable(p, "file")
        if head:  # a database: make sure it is ours before writing anything to it
            ro = _connect(p, "ro", timeout_s, immutable=filesystem_read_only(p.parent))
            try:
                if verify:
                    verify_integrity(ro, p, timeout_s)
                retry_busy(lambda: read_schema_version(ro, p), timeout_s)
            except sqlite3.DatabaseError as exc:
                ro.close()
                raise store_error(p, exc, "open", timeout_s) from exc
            except BaseException:
                ro.close()
                raise
            if readonly:
                ro.execute("PRAGMA foreign_keys = ON")
                return ro
            ro.close()
        mode = "ro" if readonly else "rw"
    elif readonly:
        raise StoreError(f"the fix store '{p}' does not exist; learn into it to create it")
    else:
        mode = "rwc"
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StoreError(
                f"cannot create the folder '{p.parent}' for the fix store '{p}' "
                f"({exc.strerror or exc}); choose a path in a writable folder"
            ) from exc
    if not readonly and not os.access(p.parent, os.W_OK | os.X_OK):
        raise _not_writable(p, "folder")
    conn = _connect(p, mode, timeout_s)
    try:
        conn.execute("PRAGMA foreign_keys = ON")
        if not readonly:
            retry_busy(lambda: conn.execute("PRAGMA journal_mode = WAL").fetchone(), timeout_s)
            conn.execute("PRAGMA synchronous = FULL")
    except sqlite3.DatabaseError as exc:
        conn.close()
        raise store_error(p, exc, "open", timeout_s) from exc
    return conn
