"""The fix store: learned observations in one SQLite file (docs/fix-store.md, thesis §3.6).

Durable and shared: WAL journal with ``synchronous=FULL``, one ``BEGIN IMMEDIATE``
transaction per learned capture (so a writer killed mid-capture leaves every earlier capture
and no part of the one it was writing), retries with backoff while another process holds the
write lock, a ``schema_version`` table with a list of migrations (the file is backed up as
``<name>.v<N>.bak`` before an old one is migrated). A damaged file or one that is not a fix
store raises :class:`~phonestereo.errors.StoreError` naming the file and what to do — it is
never recreated — and so does a path that cannot be written.

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
(1, 2)
"""

from __future__ import annotations

import math
import os
import sqlite3
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from phonestereo.errors import InputError, StoreError
from phonestereo.learning.observation import (
    FIELDS,
    TEXT_FIELDS,
    Observation,
    _rows_to_array,
    write_observations,
)
from phonestereo.learning.store_schema import (
    SCHEMA_VERSION,
    backup_file,
    corrupt_error,
    migrate,
    open_connection,
    read_schema_version,
    retry_busy,
    store_error,
)

T = TypeVar("T")

_COLS = ", ".join(FIELDS)
_INSERT = f"INSERT INTO observations ({_COLS}) VALUES ({', '.join('?' * len(FIELDS))})"


@dataclass(frozen=True)
class StoreStats:
    """What a fix store holds (``phonestereo store stats``).

    ``by_orientation`` maps each bucket to its count and the mean and standard deviation of
    its corrections (px); ``ranges`` maps a column to its [min, max] (None when empty/unknown).
    """

    path: str
    schema_version: int
    journal_mode: str
    size_bytes: int
    n_captures: int
    n_observations: int
    by_orientation: dict[str, dict[str, float]]
    by_focus_group: dict[str, int]
    by_source: dict[str, int]
    ranges: dict[str, list[float] | None]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return asdict(self)


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
        self._conn = open_connection(self.path, self.readonly, self.timeout_s)
        try:
            if verify:
                self._verify()
            self._upgrade()
        except BaseException:
            self._conn.close()
            raise

    # --- opening --------------------------------------------------------------------------
    def _verify(self) -> None:
        try:
            rows = [r[0] for r in self._conn.execute("PRAGMA integrity_check(20)")]
        except sqlite3.DatabaseError as exc:
            raise self._error(exc, "check") from exc
        if rows != ["ok"]:
            lines = [ln.strip() for r in rows for ln in str(r).splitlines() if ln[:3] != "***"]
            more = f" (+{len(lines) - 3} more)" if len(lines) > 3 else ""
            detail = "; ".join(lines[:3]) + more
            raise corrupt_error(self.path, f"PRAGMA integrity_check reports {detail}")

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
            raise StoreError(
                f"the fix store '{self.path}' has the old schema version {v}; open it writable "
                f"once to migrate it to version {SCHEMA_VERSION} (a backup is kept)"
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
    def add_capture(self, capture_id: str, observations: Sequence[Observation]) -> int:
        """Store the observations learned from one capture, in one transaction.

        Re-learning a capture replaces its earlier observations (idempotent per capture id).
        An empty list records the capture as learned with no observations.

        Returns
        -------
        int
            The number of observations stored.
        """
        cid = str(capture_id)
        if not cid.strip():
            raise InputError("capture_id must be a non-empty string")
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

        def write(conn: sqlite3.Connection) -> int:
            conn.execute("DELETE FROM observations WHERE capture_id = ?", (cid,))
            conn.execute(
                "INSERT INTO captures VALUES (?, ?, ?) ON CONFLICT(capture_id) DO UPDATE SET "
                "learned_unix = excluded.learned_unix, n_observations = excluded.n_observations",
                (cid, time.time(), len(rows)),
            )
            conn.executemany(_INSERT, rows)
            return len(rows)

        return self._transaction(write, "write to")

    def remove_capture(self, capture_id: str) -> bool:
        """Forget one capture and its observations; True if it was there."""

        def delete(conn: sqlite3.Connection) -> bool:
            conn.execute("DELETE FROM observations WHERE capture_id = ?", (capture_id,))
            cur = conn.execute("DELETE FROM captures WHERE capture_id = ?", (capture_id,))
            return cur.rowcount > 0

        return self._transaction(delete, "write to")

    # --- reading --------------------------------------------------------------------------
    def _read(self, sql: str, args: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        try:
            return self._retry(lambda: self._conn.execute(sql, tuple(args)).fetchall())
        except sqlite3.Error as exc:
            raise self._error(exc, "read") from exc

    @property
    def schema_version(self) -> int:
        """The schema version of the open file."""
        return read_schema_version(self._conn, self.path)

    def capture_ids(self) -> list[str]:
        """Ids of the learned captures, sorted."""
        return [r[0] for r in self._read("SELECT capture_id FROM captures ORDER BY capture_id")]

    def observations(
        self,
        orientation: str | None = None,
        focus_group: str | None = None,
        source: str | None = None,
        capture_id: str | None = None,
    ) -> np.ndarray:
        """Learned observations matching every given filter, in insertion order.

        Returns
        -------
        ndarray, shape (N,), structured
            Fields :data:`~phonestereo.learning.observation.FIELDS`; unknown temperature and
            sigma are NaN (see :func:`~phonestereo.learning.observation.observations_to_array`).
        """
        filt = {
            "orientation": orientation,
            "focus_group": focus_group,
            "source": source,
            "capture_id": capture_id,
        }
        where = [f"{k} = ?" for k, v in filt.items() if v is not None]
        sql = f"SELECT {_COLS} FROM observations"
        if where:
            sql += " WHERE " + " AND ".join(where)
        rows = self._read(sql + " ORDER BY id", [v for v in filt.values() if v is not None])
        text = {FIELDS.index(n) for n in TEXT_FIELDS}
        clean = [
            tuple(v if i in text else (math.nan if v is None else v) for i, v in enumerate(r))
            for r in rows
        ]
        return _rows_to_array(clean)

    def integrity(self) -> str:
        """``"ok"`` or the problems ``PRAGMA integrity_check`` reports."""
        return "; ".join(r[0] for r in self._read("PRAGMA integrity_check(20)"))

    def size_bytes(self) -> int:
        """Bytes on disk: the file plus its WAL."""
        wal = self.path.with_name(self.path.name + "-wal")
        return self.path.stat().st_size + (wal.stat().st_size if wal.exists() else 0)

    def stats(self) -> StoreStats:
        """Counts per orientation bucket, focus group and source, and value ranges."""
        by_o = {
            o: {"n": n, "correction_mean_px": m, "correction_std_px": math.sqrt(max(v - m * m, 0))}
            for o, n, m, v in self._read(
                "SELECT orientation, COUNT(*), AVG(d_expected_px - d_measured_px), "
                "AVG((d_expected_px - d_measured_px) * (d_expected_px - d_measured_px)) "
                "FROM observations GROUP BY orientation ORDER BY orientation"
            )
        }
        counts = {
            col: dict(self._read(f"SELECT {col}, COUNT(*) FROM observations GROUP BY {col}"))
            for col in ("focus_group", "source")
        }
        ranges: dict[str, list[float] | None] = {}
        for col in ("x_px", "y_px", "d_measured_px", "depth_m", "time_s", "temperature_c"):
            lo, hi = self._read(f"SELECT MIN({col}), MAX({col}) FROM observations")[0]
            ranges[col] = None if lo is None else [float(lo), float(hi)]
        return StoreStats(
            path=str(self.path),
            schema_version=self.schema_version,
            journal_mode=str(self._read("PRAGMA journal_mode")[0][0]),
            size_bytes=self.size_bytes(),
            n_captures=int(self._read("SELECT COUNT(*) FROM captures")[0][0]),
            n_observations=int(self._read("SELECT COUNT(*) FROM observations")[0][0]),
            by_orientation=by_o,
            by_focus_group=counts["focus_group"],
            by_source=counts["source"],
            ranges=ranges,
        )

    # --- maintenance ----------------------------------------------------------------------
    def export(self, out: str | os.PathLike[str]) -> int:
        """Write every observation to ``out`` (``.csv`` or ``.json``); returns the row count.

        The file is written beside its destination and renamed into place, so a failed export
        never leaves half a file. JSON holds ``schema_version``, ``captures`` and
        ``observations`` (unknown values as null); CSV one observation per row, unknown empty.
        """
        dest = Path(out)
        if dest.suffix.lower() not in (".csv", ".json"):
            raise InputError(f"export file must end in .csv or .json, got '{dest}'")
        self._conn.execute("BEGIN")  # one read snapshot for both queries (WAL readers never wait)
        try:
            obs = self.observations()
            caps = self._read("SELECT capture_id, learned_unix, n_observations FROM captures")
        finally:
            self._conn.execute("COMMIT")
        meta = {
            "format": "phonestereo-fix-store",
            "schema_version": self.schema_version,
            "store": str(self.path),
            "captures": [
                {"capture_id": c, "learned_unix": t, "n_observations": n} for c, t, n in caps
            ],
        }
        write_observations(dest, obs, meta)
        return int(obs.shape[0])

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
