"""The fix store: learned observations in one SQLite file (docs/fix-store.md, thesis §3.6).

Durable and shared: WAL journal with ``synchronous=FULL``, one ``BEGIN IMMEDIATE``
transaction per learned capture, keyed by (context, capture-set fingerprint, capture id)
(:mod:`~phonestereo.learning.store_contexts`: what the observations were learned under;
:func:`~phonestereo.io.fingerprint.capture_set_fingerprint`: which bytes), so a writer
killed mid-capture leaves every earlier capture and no part of the one it was writing;
retries with backoff while another process holds the write lock; a ``schema_version``
table with a list of migrations (the file is backed up as ``<name>.v<N>.bak`` before an old
one is migrated). A damaged file or one that is not a fix store raises
:class:`~phonestereo.errors.StoreError` naming the file and what to do — it is never
recreated or written to — and so does a path that cannot be written.

Examples
--------
>>> import tempfile, pathlib
>>> from phonestereo.learning.observation import Observation
>>> path = pathlib.Path(tempfile.mkdtemp()) / "fixes.db"
>>> ob = Observation(1000.0, 750.0, 8.7, 9.0, 2.0, "landscape", "g1", 200.0, None, "f01")
>>> with FixStore(path) as store:
...     store.add_capture("f01", [ob])
...     store.stats().n_observations, store.schema_version
1
(1, 6)
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import sqlite3
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from phonestereo.errors import InputError, StoreError
from phonestereo.fixes.distortion import RadialResidualFix
from phonestereo.learning.observation import (
    FIELDS,
    TEXT_FIELDS,
    Observation,
    _rows_to_array,
)
from phonestereo.learning.provenance import StoreContext
from phonestereo.learning.store_contexts import (
    ContextChoice,
    ContextInfo,
    context_for_applying,
    context_for_learning,
    insert_context,
    list_contexts,
)
from phonestereo.learning.store_schema import (
    SCHEMA_VERSION,
    UNRECORDED,
    backup_file,
    filesystem_read_only,
    migrate,
    open_connection,
    read_schema_version,
    retry_busy,
    store_error,
)
from phonestereo.learning.store_stats import StoreStats, export_store, store_stats

T = TypeVar("T")

_COLS = ", ".join(FIELDS)
_INSERT = (
    f"INSERT INTO observations (context_id, set_fingerprint, {_COLS}) "
    f"VALUES (?, ?, {', '.join('?' * len(FIELDS))})"
)


class FixStore:
    """The SQLite file of learned observations (docs/fix-store.md).

    Parameters
    ----------
    path : str or Path
        The store file; created (with missing parent folders) when absent, unless ``readonly``.
    readonly : bool
        Open without writing anything (no migration, no WAL switch).
    timeout_s : float
        How long a write waits for another process's write lock before raising StoreError.
    verify : bool
        Run ``PRAGMA integrity_check`` on open (a damaged file raises StoreError).

    Raises
    ------
    StoreError
        The file is damaged or not a fix store, from a newer phonestereo, or the path is not
        writable; the message names the file and the fix. Nothing on disk is changed.
    """

    def __init__(
        self,
        path: str | os.PathLike[str],
        *,
        readonly: bool = False,
        timeout_s: float = 60.0,
        verify: bool = True,
    ) -> None:
        self.path = Path(path)
        self.readonly = bool(readonly)
        self.timeout_s = float(timeout_s)
        self.backup_path: Path | None = None
        self._conn = open_connection(self.path, self.readonly, self.timeout_s, verify)
        try:
            self._upgrade()
        except BaseException:
            self._conn.close()
            raise

    # --- opening --------------------------------------------------------------------------
    def _upgrade(self) -> None:
        try:
            v = read_schema_version(self._conn, self.path)
        except sqlite3.DatabaseError as exc:
            raise self._error(exc, "read") from exc
        if v > SCHEMA_VERSION:
            raise StoreError(
                f"the fix store '{self.path}' has schema version {v}, newer than this phonestereo "
                f"understands ({SCHEMA_VERSION}); upgrade phonestereo. The file is untouched."
            )
        if v == SCHEMA_VERSION:
            return
        if self.readonly:
            if v == 0:
                raise StoreError(f"'{self.path}' is an empty file, not yet a fix store")
            ro_fs = filesystem_read_only(self.path.parent)
            where = "copy it to a writable folder and " if ro_fs else ""
            raise StoreError(
                f"the fix store '{self.path}' has the old schema version {v}; {where}open it "
                f"writable once to migrate it to version {SCHEMA_VERSION} (a backup is kept)"
            )
        if v >= 1:  # keep the old file as it was
            self.backup_path = backup_file(self._conn, self.path, v)
        self._transaction(lambda conn: migrate(conn, self.path), "migrate")

    # --- transactions ---------------------------------------------------------------------
    def _error(self, exc: BaseException, action: str) -> StoreError:
        return store_error(self.path, exc, action, self.timeout_s)

    def _retry(self, fn: Callable[[], T]) -> T:
        return retry_busy(fn, self.timeout_s)

    def _transaction(self, fn: Callable[[sqlite3.Connection], T], action: str) -> T:
        if self.readonly:
            raise StoreError(
                f"cannot {action} the fix store '{self.path}': it was opened read-only"
            )
        conn = self._conn

        def attempt() -> T:
            conn.execute("BEGIN IMMEDIATE")
            try:
                out = fn(conn)
                conn.execute("COMMIT")
                return out
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise

        try:
            return self._retry(attempt)
        except sqlite3.Error as exc:
            raise self._error(exc, action) from exc

    # --- writing --------------------------------------------------------------------------
    def context_for_learning(self, context: StoreContext, *, new: bool = False) -> int:
        """The id of the context to learn ``context``'s observations into (created when the
        store has none that holds observations, or when ``new``).

        Raises
        ------
        ContextError
            The store was learned under another context (the message names what differs).
        """
        return self._transaction(
            lambda conn: context_for_learning(conn, self.path, context, new), "write to"
        )

    def context_for_applying(self, context: StoreContext) -> ContextChoice:
        """The context whose observations apply under ``context`` (read only).

        Raises
        ------
        ContextError
            No context of the store equals ``context``; the message names the field.
        """
        try:
            return self._retry(lambda: context_for_applying(self._conn, self.path, context))
        except sqlite3.Error as exc:
            raise self._error(exc, "read") from exc

    def contexts(self) -> list[ContextInfo]:
        """Every context of the store with its counts."""
        try:
            return self._retry(lambda: list_contexts(self._conn))
        except sqlite3.Error as exc:
            raise self._error(exc, "read") from exc

    def add_capture(
        self,
        capture_id: str,
        observations: Sequence[Observation],
        *,
        context_id: int | None = None,
        set_fingerprint: str = UNRECORDED,
        set_folder: str = "",
        radial: RadialResidualFix | None = None,
    ) -> int:
        """Store the observations learned from one capture, in one transaction.

        Re-learning a capture (same context, set fingerprint and id) replaces its earlier
        observations; the same id in another set is another capture. An empty list records
        the capture as learned with no observations. Only
        :func:`phonestereo.flows.learning.run` calls this in the product.

        ``context_id`` comes from :meth:`context_for_learning` (None: an unrecorded context,
        for tests and imports), ``set_fingerprint`` from
        :func:`~phonestereo.io.fingerprint.capture_set_fingerprint`; ``set_folder`` is shown
        by ``store stats``; ``radial``: the capture's radial fit (``store_radial`` reads it).

        Returns
        -------
        int
            The number of observations stored.
        """
        cid = str(capture_id)
        if not cid.strip():
            raise InputError("capture_id must be a non-empty string")
        if not str(set_fingerprint).strip():
            raise InputError("set_fingerprint must be a non-empty string")
        rows = []
        for ob in observations:
            if not isinstance(ob, Observation):
                raise InputError(f"add_capture takes Observation objects, got {type(ob).__name__}")
            if ob.capture_id != cid:
                raise InputError(
                    f"observation of capture '{ob.capture_id}' passed to add_capture('{cid}'); "
                    "store each capture's observations under its own id"
                )
            rows.append(
                tuple(None if isinstance(v, float) and math.isnan(v) else v for v in ob.as_row())
            )

        radial_json = None if radial is None else json.dumps(radial.to_dict())

        def write(conn: sqlite3.Connection) -> int:
            ctx = context_id
            if ctx is None:
                found = conn.execute(
                    "SELECT MIN(id) FROM contexts WHERE calibration IS NULL"
                ).fetchone()[0]
                ctx = found if found is not None else insert_context(conn, None)
            key = (ctx, set_fingerprint, cid)
            conn.execute(
                "DELETE FROM observations WHERE context_id = ? AND set_fingerprint = ? AND "
                "capture_id = ?",
                key,
            )
            conn.execute(
                "INSERT INTO captures VALUES (?, ?, ?, ?, ?, ?, ?) ON CONFLICT DO UPDATE SET "
                "set_folder = excluded.set_folder, learned_unix = excluded.learned_unix, "
                "n_observations = excluded.n_observations, radial = excluded.radial",
                (*key, str(set_folder), time.time(), len(rows), radial_json),
            )
            conn.executemany(_INSERT, [(ctx, set_fingerprint, *r) for r in rows])
            return len(rows)

        return self._transaction(write, "write to")

    def remove_capture(self, capture_id: str) -> bool:
        """Forget every capture of this id (in every set and context) and its observations;
        True if there was one."""

        def delete(conn: sqlite3.Connection) -> bool:
            conn.execute("DELETE FROM observations WHERE capture_id = ?", (capture_id,))
            cur = conn.execute("DELETE FROM captures WHERE capture_id = ?", (capture_id,))
            return cur.rowcount > 0

        return self._transaction(delete, "write to")

    # --- reading --------------------------------------------------------------------------
    @contextlib.contextmanager
    def snapshot(self) -> Iterator[None]:
        """Reads inside see one consistent snapshot (WAL readers never wait for writers)."""
        self._conn.execute("BEGIN")
        try:
            yield
        finally:
            self._conn.execute("COMMIT")

    def query(self, sql: str, args: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        """Rows of one read-only SQL query (retried while busy; errors as StoreError)."""
        try:
            return self._retry(lambda: self._conn.execute(sql, tuple(args)).fetchall())
        except sqlite3.Error as exc:
            raise self._error(exc, "read") from exc

    @property
    def schema_version(self) -> int:
        """The schema version of the open file."""
        return read_schema_version(self._conn, self.path)

    def capture_ids(self) -> list[str]:
        """Ids of the learned captures (each once, whatever its set), sorted."""
        return [
            r[0] for r in self.query("SELECT DISTINCT capture_id FROM captures ORDER BY 1")
        ]

    def observations(
        self,
        orientation: str | None = None,
        focus_group: str | None = None,
        source: str | None = None,
        capture_id: str | None = None,
        context_id: int | None = None,
    ) -> np.ndarray:
        """Learned observations matching every given filter, in insertion order.

        Returns
        -------
        ndarray, shape (N,), structured
            Fields :data:`~phonestereo.learning.observation.FIELDS` (``context_id``: only
            that context's, see :meth:`context_for_applying`); unknown temperature and
            sigma are NaN (see :func:`~phonestereo.learning.observation.observations_to_array`).
        """
        filt = {
            "orientation": orientation,
            "focus_group": focus_group,
            "source": source,
            "capture_id": capture_id,
            "context_id": context_id,
        }
        where = [f"{k} = ?" for k, v in filt.items() if v is not None]
        sql = f"SELECT {_COLS} FROM observations"
        if where:
            sql += " WHERE " + " AND ".join(where)
        rows = self.query(sql + " ORDER BY id", [v for v in filt.values() if v is not None])
        text = {FIELDS.index(n) for n in TEXT_FIELDS}
        clean = [
            tuple(v if i in text else (math.nan if v is None else v) for i, v in enumerate(r))
            for r in rows
        ]
        return _rows_to_array(clean)

    def integrity(self) -> str:
        """``"ok"`` or the problems ``PRAGMA integrity_check`` reports."""
        return "; ".join(r[0] for r in self.query("PRAGMA integrity_check(20)"))

    def size_bytes(self) -> int:
        """Bytes on disk: the file plus its WAL."""
        wal = self.path.with_name(self.path.name + "-wal")
        return self.path.stat().st_size + (wal.stat().st_size if wal.exists() else 0)

    def stats(self) -> StoreStats:
        """Counts per orientation bucket, focus group and source, value ranges, the contexts
        and the capture sets learned (:func:`~phonestereo.learning.store_stats.store_stats`)."""
        return store_stats(self)

    # --- maintenance ----------------------------------------------------------------------
    def export(self, out: str | os.PathLike[str]) -> int:
        """Write every observation to ``out`` (``.csv`` or ``.json``); the row count."""
        return export_store(self, out)

    def vacuum(self) -> tuple[int, int]:
        """Checkpoint the WAL and rebuild the file compactly; returns (bytes before, after)."""
        if self.readonly:
            raise StoreError(f"cannot vacuum the fix store '{self.path}': opened read-only")
        before = self.size_bytes()
        try:
            self._retry(lambda: self._conn.execute("VACUUM"))
            self._retry(lambda: self._conn.execute("PRAGMA wal_checkpoint(TRUNCATE)").fetchall())
        except sqlite3.Error as exc:
            raise self._error(exc, "vacuum") from exc
        return before, self.size_bytes()

    def close(self) -> None:
        """Close the connection (the last one to close checkpoints the WAL)."""
        self._conn.close()

    def __enter__(self) -> FixStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"FixStore('{self.path}', readonly={self.readonly})"

