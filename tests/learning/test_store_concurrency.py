"""Fix-store durability across processes (issue #6 acceptance): concurrent writers and SIGKILL.

Writers are real processes (multiprocessing, spawn), each with its own connection, as a
phone's learning service and a desktop tool would be.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import sqlite3
import time
from multiprocessing.connection import Connection
from pathlib import Path

import numpy as np
import pytest

from phonestereo.learning.observation import Observation
from phonestereo.learning.store import FixStore

PER_CAPTURE = 10


def _obs(cid: str, n: int) -> list[Observation]:
    return [
        Observation(10.0 * i, 5.0 * i, 8.6, 9.0, 2.0, "landscape", "g", 190.0 + i, None, cid)
        for i in range(n)
    ]


def _writer(path: str, wid: int, n_captures: int) -> None:
    with FixStore(path) as st:
        for c in range(n_captures):
            cid = f"w{wid}-c{c:03d}"
            st.add_capture(cid, _obs(cid, PER_CAPTURE))


def _endless_writer(path: str, pipe: Connection) -> None:
    with FixStore(path) as st:
        i = 0
        while True:
            cid = f"k{i:05d}"
            st.add_capture(cid, _obs(cid, PER_CAPTURE))
            pipe.send(i + 1)  # committed
            i += 1


def test_four_concurrent_writers_lose_nothing(tmp_path: Path) -> None:
    path = tmp_path / "fixes.db"  # created concurrently by the writers themselves
    ctx = mp.get_context("spawn")
    procs = [ctx.Process(target=_writer, args=(str(path), w, 50)) for w in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(120)
    assert [p.exitcode for p in procs] == [0, 0, 0, 0]
    with FixStore(path) as st:
        s = st.stats()
        # 4 writers × 50 captures × 10 = 2000, exactly: no lost or duplicated transaction
        assert (s.n_captures, s.n_observations) == (200, 2000)
        assert st.integrity() == "ok"


def _kill_during_learning(path: Path, n_before_kill: int, delay_s: float = 0.0) -> int:
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_endless_writer, args=(str(path), child))
    proc.start()
    committed = 0
    while committed < n_before_kill:
        assert parent.poll(60), "writer stalled"
        committed = parent.recv()
    time.sleep(delay_s)
    os.kill(proc.pid, signal.SIGKILL)  # mid-loop: often inside a transaction
    proc.join(10)
    while parent.poll():
        committed = parent.recv()  # commits reported before the kill landed
    assert proc.exitcode == -signal.SIGKILL
    return committed


def _check_after_kill(path: Path, committed: int) -> int:
    with FixStore(path) as st:  # opens (integrity_check on open) and recovers the WAL
        assert st.integrity() == "ok"
        ids = st.capture_ids()
        obs = st.observations()
    assert len(ids) >= committed  # every reported commit is there (maybe one more)
    assert set(ids) >= {f"k{i:05d}" for i in range(committed)}
    counts = {cid: int((obs["capture_id"] == cid).sum()) for cid in ids}
    assert set(counts.values()) == {PER_CAPTURE}  # no partial capture
    conn = sqlite3.connect(path)
    stored = dict(conn.execute("SELECT capture_id, n_observations FROM captures").fetchall())
    conn.close()
    assert stored == counts
    return len(ids)


def test_sigkill_mid_learning_keeps_every_commit(tmp_path: Path) -> None:
    path = tmp_path / "fixes.db"
    committed = _kill_during_learning(path, 25)
    _check_after_kill(path, committed)


@pytest.mark.slow
def test_sigkill_repeatedly(tmp_path: Path) -> None:
    path = tmp_path / "fixes.db"
    rng = np.random.default_rng(0)
    for round_ in range(15):  # the same store killed again and again, at varying points
        committed = _kill_during_learning(path, 5 + 3 * round_, float(rng.uniform(0, 0.01)))
        n = _check_after_kill(path, committed)
        assert n >= committed
