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
SCHEMA_VERSION = 2
#: The first 16 bytes of every SQLite database file.
SQLITE_MAGIC = b"SQLite format 3\x00"

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


def store_error(path: Path, exc: BaseException, action: str, timeout_s: float) -> StoreError:
    """Translate an SQLite error raised while doing ``action`` into a StoreError with the fix."""
    msg = str(exc)
    code = getattr(exc, "sqlite_errorcode", 0) & 0xFF
    where = f"cannot {action} the fix store '{path}'"
    if code == sqlite3.SQLITE_READONLY or "readonly" in msg:
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
    return StoreError(
        f"{where}: {msg}. The transaction was rolled back; earlier captures are intact."
    )


def open_connection(path: Path, readonly: bool, timeout_s: float) -> sqlite3.Connection:
    """Check the path, then connect in autocommit mode (transactions are explicit), with
    foreign keys on and, for writing, the WAL journal and ``synchronous=FULL``.

    Creates the file (and missing parent folders) only when it does not exist and
    ``readonly`` is false; an existing file is opened with ``mode=rw`` so it is never recreated.

    Raises
    ------
    StoreError
        The path is a folder, unreadable, not writable, not an SQLite file, or absent when
        ``readonly``; the message names the path and the fix.
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
        mode = "ro" if readonly else "rw"
        if not readonly and not os.access(p, os.W_OK):
            raise StoreError(
                f"the fix store '{p}' is not writable; make it writable (chmod u+w '{p}') or "
                "open it read-only to inspect it. Its contents are untouched."
            )
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
        raise StoreError(
            f"the folder '{p.parent}' of the fix store '{p}' is not writable (SQLite keeps "
            "its journal beside the file); make the folder writable or choose another path"
        )
    try:
        conn = sqlite3.connect(
            f"{p.resolve().as_uri()}?mode={mode}",
            uri=True,
            timeout=min(timeout_s, 5.0),  # busy handler per attempt; retry_busy bounds the total
            isolation_level=None,
        )
    except sqlite3.Error as exc:
        raise StoreError(f"cannot open the fix store '{p}': {exc}; check the path") from exc
    try:
        conn.execute("PRAGMA foreign_keys = ON")
        if not readonly:
            retry_busy(lambda: conn.execute("PRAGMA journal_mode = WAL").fetchone(), timeout_s)
            conn.execute("PRAGMA synchronous = FULL")
    except sqlite3.DatabaseError as exc:
        conn.close()
        raise store_error(p, exc, "open", timeout_s) from exc
    return conn
