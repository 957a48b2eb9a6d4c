"""Resumable task runs on Dask: one record file per task, written as each task completes.

The scale-out of docs/architecture.md (batch runs, tolerance studies) is this one function on top of
``dask.distributed``: :func:`run_tasks` submits every task whose record is missing with
``client.submit`` and collects them with ``as_completed``; each finished task's record (status,
reason, seconds, result) is written atomically to ``<record_dir>/<key>.json`` at once, so an
interrupted run loses nothing finished and a rerun does only what is missing. Dask reschedules
the tasks of a worker that dies. The cluster is a :class:`~distributed.LocalCluster` (one
thread per worker process) or any running scheduler (``--scheduler ADDRESS``): the same code.

A task that raises is a record with ``status: "failed"`` and the reason, not a stopped run.
"""

from __future__ import annotations

import contextlib
import json
import os
import time
import traceback
import uuid
from collections.abc import Callable, Iterator, Mapping
from pathlib import Path
from typing import Any

from phonestereo.errors import InputError

#: How long to wait for a ``--scheduler`` address before giving up, seconds.
CONNECT_TIMEOUT_S = 5.0
Progress = Callable[[int, int, str], None]
Task = tuple[Callable[..., Any], tuple[Any, ...]]


def guarded(key: str, fn: Callable[..., Any], *args: Any) -> dict[str, Any]:
    """Run ``fn(*args)`` and return its record: ``{key, status, reason, seconds, result}``.

    Any exception becomes ``status: "failed"`` with ``reason`` (type and message) and the
    traceback text; the run goes on.

    >>> guarded("k", int, "12")["result"], guarded("k", int, "x")["status"]
    (12, 'failed')
    """
    t0 = time.perf_counter()
    try:
        result = fn(*args)
        status, reason, tb = "ok", "", ""
    except Exception as exc:
        result, status = None, "failed"
        reason = f"{type(exc).__name__}: {exc}"
        tb = traceback.format_exc(limit=8)
    return {
        "key": key,
        "status": status,
        "reason": reason,
        "traceback": tb,
        "seconds": time.perf_counter() - t0,
        "host": os.uname().nodename,
        "pid": os.getpid(),
        "result": result,
    }


def record_path(record_dir: Path, key: str) -> Path:
    """The record file of a task."""
    return record_dir / f"{key}.json"


def write_record(record_dir: Path, record: dict[str, Any]) -> Path:
    """Write a record atomically (temporary file + rename): a record file is whole or absent."""
    path = record_path(record_dir, str(record["key"]))
    tmp = path.with_suffix(f".tmp{os.getpid()}")
    tmp.write_text(json.dumps(record, indent=1, sort_keys=True, default=str) + "\n")
    os.replace(tmp, path)
    return path


def read_records(record_dir: Path) -> dict[str, dict[str, Any]]:
    """Every complete record in a folder, by key (unreadable files are ignored: redone)."""
    out: dict[str, dict[str, Any]] = {}
    if not record_dir.is_dir():
        return out
    for p in sorted(record_dir.glob("*.json")):
        try:
            rec = json.loads(p.read_text())
        except (OSError, json.JSONDecodeError):
            continue
        if isinstance(rec, dict) and "key" in rec and "status" in rec:
            out[str(rec["key"])] = rec
    return out


def pending_keys(
    keys: list[str], done: Mapping[str, dict[str, Any]], retry_failed: bool
) -> list[str]:
    """Keys still to run: no record, or a failed one when ``retry_failed``."""
    return [k for k in keys if k not in done or (retry_failed and done[k].get("status") != "ok")]


def guarded_chunk(items: list[tuple[str, Callable[..., Any], tuple[Any, ...]]]) -> list[dict]:
    """:func:`guarded` over a chunk of (key, function, args): one record per item."""
    return [guarded(k, fn, *args) for k, fn, args in items]


def auto_chunk(n_tasks: int, n_workers: int, per_worker: int = 8, largest: int = 16) -> int:
    """Tasks per chunk: at least ``per_worker`` chunks per worker, at most ``largest`` each.

    >>> auto_chunk(200, 2), auto_chunk(10, 2), auto_chunk(100_000, 100)
    (13, 1, 16)
    """
    return int(max(1, min(largest, -(-n_tasks // max(1, n_workers * per_worker)))))


def _n_workers(client: Any) -> int:
    try:
        return max(1, len(client.scheduler_info().get("workers", {})))
    except Exception:  # pragma: no cover - scheduler_info is best effort
        return 1


def run_tasks(
    tasks: Mapping[str, Task],
    record_dir: str | os.PathLike[str],
    *,
    client: Any = None,
    progress: Progress | None = None,
    retry_failed: bool = True,
    chunk: int = 0,
) -> tuple[dict[str, dict[str, Any]], int]:
    """Run the tasks whose records are missing; return (all records by key, number run now).

    Parameters
    ----------
    tasks : mapping key → (function, args)
        Functions and arguments must pickle (module-level functions) for a Dask cluster.
    record_dir : path
        One ``<key>.json`` per finished task (created).
    client : distributed.Client, optional
        Runs the tasks on its cluster; None runs them here, one after another (the serial
        reference with the same records).
    progress : callable, optional
        ``progress(done, total, key)`` after each finished task (done counts earlier runs too).
    retry_failed : bool
        Run again the tasks whose record says ``failed``.
    chunk : int
        Tasks per Dask task (records are still written per task); 0 picks
        :func:`auto_chunk`. Chunks keep the scheduler's per-task cost (~ms) small against
        short tasks.

    Returns
    -------
    records : dict
        Key → record, for every key in ``tasks``.
    n_run : int
        Tasks run in this call (0 when everything was already done).
    """
    folder = Path(record_dir)
    folder.mkdir(parents=True, exist_ok=True)
    keys = list(tasks)
    records = {k: r for k, r in read_records(folder).items() if k in tasks}
    todo = pending_keys(keys, records, retry_failed)
    done = len(keys) - len(todo)

    def finish(record: dict[str, Any]) -> None:
        nonlocal done
        write_record(folder, record)
        records[str(record["key"])] = record
        done += 1
        if progress is not None:
            progress(done, len(keys), str(record["key"]))

    if client is None:
        for k in todo:
            fn, args = tasks[k]
            finish(guarded(k, fn, *args))
        return {k: records[k] for k in keys}, len(todo)

    from distributed import as_completed

    size = chunk if chunk > 0 else auto_chunk(len(todo), _n_workers(client))
    chunks = [todo[i : i + size] for i in range(0, len(todo), size)]
    futures = {
        client.submit(
            guarded_chunk,
            [(k, tasks[k][0], tasks[k][1]) for k in ks],
            key=f"phonestereo-{ks[0]}-{len(ks)}-{uuid.uuid4().hex[:8]}",
            pure=False,
        ): ks
        for ks in chunks
    }
    try:
        for fut in as_completed(list(futures)):
            ks = futures[fut]
            try:
                chunk_records = fut.result()
            except Exception as exc:  # the task could not run (e.g. killed too often)
                chunk_records = [
                    {
                        "key": k,
                        "status": "failed",
                        "reason": f"{type(exc).__name__}: {exc}",
                        "traceback": "",
                        "seconds": float("nan"),
                        "result": None,
                    }
                    for k in ks
                ]
            for record in chunk_records:
                finish(record)
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
    return {k: records[k] for k in keys}, len(todo)


def write_table(rows: list[dict[str, Any]], base: Path) -> dict[str, str]:
    """Write a table as ``<base>.csv`` and, when pyarrow can be imported, ``<base>.parquet``.

    Returns the written files by format (``{"csv": ..., "parquet": ...}``).
    """
    import pandas as pd

    table = pd.DataFrame(rows)
    files = {"csv": str(base.with_suffix(".csv"))}
    table.to_csv(files["csv"], index=False)
    try:
        import pyarrow  # noqa: F401
    except ImportError:  # e.g. a pyarrow built for NumPy 2 beside NumPy 1.26
        return files
    files["parquet"] = str(base.with_suffix(".parquet"))
    table.to_parquet(files["parquet"], index=False)
    return files


def check_address(address: str) -> str:
    """A scheduler address as ``tcp://host:port`` (a bare ``host:port`` gets ``tcp://``)."""
    text = address.strip()
    if "://" not in text:
        text = "tcp://" + text
    hostport = text.split("://", 1)[1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise InputError(
            f"--scheduler '{address}' is not a scheduler address; use HOST:PORT or "
            "tcp://HOST:PORT (e.g. tcp://10.0.0.5:8786)"
        )
    return text


@contextlib.contextmanager
def dask_client(
    scheduler: str | None = None,
    workers: int = 2,
    *,
    timeout_s: float = CONNECT_TIMEOUT_S,
) -> Iterator[Any]:
    """A Dask client: on a running scheduler, or on a fresh LocalCluster of ``workers``
    single-threaded processes (closed on exit).

    Raises
    ------
    InputError
        A malformed or unreachable scheduler address (within ``timeout_s``), or workers < 1.
    """
    from distributed import Client, LocalCluster

    if scheduler is not None:
        address = check_address(scheduler)
        try:
            client = Client(address, timeout=f"{timeout_s}s")
        except (OSError, TimeoutError) as exc:
            raise InputError(
                f"cannot reach the Dask scheduler at {address} within {timeout_s:g} s ({exc}); "
                "start one with `dask scheduler` and workers with `dask worker ADDRESS`, or "
                "leave out --scheduler to run a local cluster"
            ) from None
        try:
            yield client
        finally:
            client.close()
        return
    if workers < 1:
        raise InputError(f"--workers must be >= 1, got {workers}")
    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # a free port: several clusters may run at once
        silence_logs=40,
    )
    client = Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


__all__ = [
    "CONNECT_TIMEOUT_S",
    "auto_chunk",
    "check_address",
    "dask_client",
    "guarded",
    "guarded_chunk",
    "pending_keys",
    "read_records",
    "record_path",
    "run_tasks",
    "write_record",
    "write_table",
]
