"""Fix-store and lookup benchmark: durability, write speed, lookup speed, Figure 3-31 table.

Durability (issue #6 acceptance): 4 writer processes × 500 observations (50 captures × 10)
into one new file → all 2000 present; a writer SIGKILLed mid-learning, repeatedly → every
reported commit present, no partial capture, ``integrity_check`` ok.

Speed: ``FixStore.add_capture`` (10 observations, one WAL transaction, synchronous=FULL, with
validation) against a bare ``sqlite3`` ``executemany`` of the same rows per capture with
SQLite's defaults (ratio = ours / bare); ``nearest`` lookups (k = 4, cKDTree) against a
brute-force NumPy search (ratio = ours / brute force); field fit and prediction in seconds.

Accuracy: the strategies of thesis Figure 3-31 and the smooth field on synthetic learning
(faces at 1–3 m, 5 % wrong-IPD faces) and verification (chart corners at 0.8–4 m) sets drawn
from a known smooth correction, over several seeds.

Run: ``.venv/bin/python benchmarks/bench_store.py [--seeds 5] [--kills 10] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import os
import signal
import sqlite3
import tempfile
import time
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import numpy as np

from phonestereo.learning.compare import ROWS, compare_strategies
from phonestereo.learning.field import fit_field
from phonestereo.learning.lookup import DictionaryLookup
from phonestereo.learning.observation import FIELDS, Observation, observations_to_array
from phonestereo.learning.store import FixStore

FB, PP = 18.0, (1000.0, 750.0)


def _obs(cid: str, n: int = 10) -> list[Observation]:
    return [
        Observation(10.0 * i, 5.0 * i, 8.6, 9.0, 2.0, "landscape", "g", 190.0 + i, None, cid)
        for i in range(n)
    ]


def _writer(path: str, wid: int) -> None:
    with FixStore(path) as st:
        for c in range(50):
            st.add_capture(f"w{wid}-{c}", _obs(f"w{wid}-{c}"))


def _endless(path: str, pipe: Connection) -> None:
    with FixStore(path) as st:
        i = 0
        while True:
            st.add_capture(f"k{i:05d}", _obs(f"k{i:05d}"))
            pipe.send(i + 1)
            i += 1


def durability(tmp: Path, kills: int) -> dict[str, Any]:
    ctx = mp.get_context("spawn")
    path = tmp / "concurrent.db"
    t0 = time.perf_counter()
    procs = [ctx.Process(target=_writer, args=(str(path), w)) for w in range(4)]
    for p in procs:
        p.start()
    for p in procs:
        p.join()
    wall = time.perf_counter() - t0
    with FixStore(path) as st:
        n_conc = st.stats().n_observations
    rng = np.random.default_rng(0)
    path = tmp / "killed.db"
    ok = 0
    for _ in range(kills):
        parent, child = ctx.Pipe(duplex=False)
        proc = ctx.Process(target=_endless, args=(str(path), child))
        proc.start()
        target, got = int(rng.integers(5, 40)), 0
        while got < target:
            got = parent.recv()
        time.sleep(float(rng.uniform(0, 0.01)))  # land anywhere in the next transaction
        os.kill(proc.pid, signal.SIGKILL)
        proc.join()
        while parent.poll():
            got = parent.recv()
        with FixStore(path) as st:
            obs, ids = st.observations(), st.capture_ids()
            counts = np.unique(obs["capture_id"], return_counts=True)[1]
            good = st.integrity() == "ok" and len(ids) >= got and set(counts) == {10}
        ok += bool(good)
    return {
        "concurrent_observations": n_conc,
        "concurrent_expected": 2000,
        "concurrent_wall_s": wall,
        "sigkill_rounds_ok": ok,
        "sigkill_rounds": kills,
    }


def write_speed(tmp: Path, n: int = 200) -> dict[str, float]:
    caps = [(f"c{i}", _obs(f"c{i}")) for i in range(n)]
    with FixStore(tmp / "speed.db") as st:
        t0 = time.perf_counter()
        for cid, obs in caps:
            st.add_capture(cid, obs)
        ours = (time.perf_counter() - t0) / n
    conn = sqlite3.connect(tmp / "bare.db")
    conn.execute(f"CREATE TABLE o ({', '.join(FIELDS)})")
    t0 = time.perf_counter()
    for _, obs in caps:
        with conn:
            conn.executemany(
                f"INSERT INTO o VALUES ({','.join('?' * len(FIELDS))})", [o.as_row() for o in obs]
            )
    bare = (time.perf_counter() - t0) / n
    conn.close()
    return {"add_capture_ms": 1e3 * ours, "bare_sqlite_ms": 1e3 * bare, "ratio": ours / bare}


def faces(seed: int, n_captures: int = 40) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rows = []
    for ci in range(n_captures):
        for _ in range(5):
            fx, fy, z = rng.uniform([150, 150, 1.0], [1850, 1350, 3.0])
            err = (
                rng.normal(0, 0.005)
                if rng.random() > 0.05
                else rng.choice([-1, 1]) * rng.uniform(0.1, 0.2)
            )
            x, y = fx + rng.normal(0, 30, 4), fy + rng.normal(0, 30, 4)
            d = FB / z - truth(x, y, FB / z) + rng.normal(0, 0.04, 4)
            rows += [
                Observation(
                    x[i],
                    y[i],
                    d[i],
                    FB / (z * (1 + err)),
                    z * (1 + err),
                    "landscape",
                    "g1",
                    0.0,
                    None,
                    f"f{ci}",
                )
                for i in range(4)
            ]
    return observations_to_array(rows)


def charts(seed: int, n: int = 400) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x, y = rng.uniform([50, 50], [1950, 1450], (n, 2)).T
    z = rng.uniform(0.8, 4.0, n)
    d = FB / z - truth(x, y, FB / z) + rng.normal(0, 0.02, n)
    return observations_to_array(
        Observation(x[i], y[i], d[i], FB / z[i], z[i], "landscape", "g1", 0.0, None, f"v{i // 50}")
        for i in range(n)
    )


def truth(x: np.ndarray, y: np.ndarray, d: np.ndarray) -> np.ndarray:
    u, v = (x - PP[0]) / 1000, (y - PP[1]) / 1000
    return (
        0.35
        + 0.15 * u
        - 0.1 * v
        + 0.12 * u * u
        - 0.06 * u * v
        + 0.05 * v * v
        + (0.02 + 0.015 * u - 0.01 * v) * d
    )


def lookup_speed(n_obs: int = 5000, n_q: int = 100_000) -> dict[str, float]:
    rng = np.random.default_rng(0)
    obs = faces(1, n_captures=n_obs // 20)
    q = np.c_[rng.uniform(0, 2000, n_q), rng.uniform(0, 1500, n_q), rng.uniform(6, 18, n_q)]
    lut = DictionaryLookup(obs, PP)
    t0 = time.perf_counter()
    lut.correct(q, "landscape", "nearest")
    ours = time.perf_counter() - t0
    pts = np.c_[obs["x_px"], obs["y_px"], obs["d_measured_px"]]
    norm = np.array([max(pts[:, 0].std(), pts[:, 1].std())] * 2 + [pts[:, 2].std()])
    sub = q[: n_q // 10]  # brute force on a tenth of the queries, scaled (it is linear in N)
    t0 = time.perf_counter()
    for chunk in np.array_split(sub, 10):  # 1000 × N distances at a time
        d2 = (((chunk[:, None, :] - pts[None]) / norm) ** 2).sum(-1)
        np.argpartition(d2, 4, axis=1)[:, :4]
    brute = (time.perf_counter() - t0) * len(q) / len(sub)
    t0 = time.perf_counter()
    fit = fit_field(obs, PP)
    t_fit = time.perf_counter() - t0
    assert fit.field is not None
    t0 = time.perf_counter()
    fit.field.predict(q)
    t_pred = time.perf_counter() - t0
    return {
        "n_obs": len(obs),
        "n_queries": n_q,
        "nearest_s": ours,
        "brute_force_s": brute,
        "ratio": ours / brute,
        "field_fit_s": t_fit,
        "field_predict_s": t_pred,
    }


def accuracy(seeds: int) -> dict[str, Any]:
    tables = [compare_strategies(faces(s), charts(100 + s), PP) for s in range(seeds)]
    out: dict[str, Any] = {}
    for name in ROWS:
        rows = [t.row(name) for t in tables]
        out[name] = {
            k: float(np.mean([getattr(r, k) for r in rows]))
            for k in (
                "median_abs_px",
                "rms_px",
                "median_rel_depth",
                "p90_rel_depth",
                "coverage_2sigma",
            )
        }
    out["field_le_best_dictionary_rms"] = sum(
        t.row("field").rms_px <= t.best_dictionary().rms_px for t in tables
    )
    out["seeds"] = seeds
    out["field_degrees"] = [t.field_degrees["landscape"] for t in tables]
    out["table_seed0"] = tables[0].to_markdown()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--kills", type=int, default=10)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        res = {
            "durability": durability(Path(tmp), args.kills),
            "write": write_speed(Path(tmp)),
            "lookup": lookup_speed(),
            "accuracy": accuracy(args.seeds),
        }
    if args.json:  # NaN (e.g. σ coverage of "none") → null: strict JSON
        print(json.dumps(res).replace("NaN", "null"))
        return
    d, w, lk, acc = res["durability"], res["write"], res["lookup"], res["accuracy"]
    print(
        f"concurrent: {d['concurrent_observations']}/2000 in {d['concurrent_wall_s']:.2f} s; "
        f"SIGKILL rounds ok {d['sigkill_rounds_ok']}/{d['sigkill_rounds']}"
    )
    print(
        f"add_capture {w['add_capture_ms']:.2f} ms vs bare sqlite "
        f"{w['bare_sqlite_ms']:.2f} ms (×{w['ratio']:.2f})"
    )
    print(
        f"nearest {lk['n_queries']} queries over {lk['n_obs']} obs: {lk['nearest_s']:.3f} s "
        f"vs brute {lk['brute_force_s']:.3f} s (×{lk['ratio']:.3f}); "
        f"field fit {lk['field_fit_s']:.2f} s, "
        f"predict {lk['field_predict_s']:.3f} s"
    )
    print(
        f"Figure 3-31, mean over {acc['seeds']} seeds (field ≤ best dictionary RMS in "
        f"{acc['field_le_best_dictionary_rms']}/{acc['seeds']}; degrees {acc['field_degrees']}):"
    )
    for name in ROWS:
        r = acc[name]
        print(
            f"  {name:8s} median {r['median_abs_px']:.3f} px  rms {r['rms_px']:.3f} px  "
            f"rel depth median {100 * r['median_rel_depth']:.2f} %  "
            f"p90 {100 * r['p90_rel_depth']:.2f} %"
        )
    print("seed 0:\n" + acc["table_seed0"])


if __name__ == "__main__":
    main()
