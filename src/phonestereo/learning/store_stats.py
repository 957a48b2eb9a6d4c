"""Reading a fix store: ``store stats`` and ``store export`` (docs/fix-store.md).

Kept apart from :mod:`phonestereo.learning.store` (the file and its transactions) so each
module stays one concept; :meth:`FixStore.stats` and :meth:`FixStore.export` call these.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from contextlib import AbstractContextManager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from phonestereo.errors import InputError
from phonestereo.learning.observation import write_observations
from phonestereo.learning.store_contexts import ContextInfo


class ReadableStore(Protocol):
    """What these summaries read from a :class:`~phonestereo.learning.store.FixStore` (a
    protocol, so this module does not import the store: no import cycle)."""

    path: Path

    @property
    def schema_version(self) -> int: ...

    def query(self, sql: str, args: Sequence[Any] = ()) -> list[tuple[Any, ...]]: ...

    def snapshot(self) -> AbstractContextManager[None]: ...

    def observations(self) -> np.ndarray: ...

    def contexts(self) -> list[ContextInfo]: ...

    def size_bytes(self) -> int: ...


@dataclass(frozen=True)
class StoreStats:
    """What a fix store holds (``phonestereo store stats``).

    ``contexts`` lists what the observations were learned under
    (:meth:`~phonestereo.learning.store_contexts.ContextInfo.to_dict`), ``sets`` the capture
    sets learned (context, fingerprint, folder, captures, observations, last learned).
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
    contexts: list[dict[str, Any]]
    sets: list[dict[str, Any]]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict."""
        return asdict(self)


def store_stats(store: ReadableStore) -> StoreStats:
    """Counts per orientation bucket, focus group and source, and value ranges."""
    by_o = {
        o: {"n": n, "correction_mean_px": m, "correction_std_px": math.sqrt(max(v - m * m, 0))}
        for o, n, m, v in store.query(
            "SELECT orientation, COUNT(*), AVG(d_expected_px - d_measured_px), "
            "AVG((d_expected_px - d_measured_px) * (d_expected_px - d_measured_px)) "
            "FROM observations GROUP BY orientation ORDER BY orientation"
        )
    }
    counts = {
        col: dict(store.query(f"SELECT {col}, COUNT(*) FROM observations GROUP BY {col}"))
        for col in ("focus_group", "source")
    }
    ranges: dict[str, list[float] | None] = {}
    for col in ("x_px", "y_px", "d_measured_px", "depth_m", "time_s", "temperature_c"):
        lo, hi = store.query(f"SELECT MIN({col}), MAX({col}) FROM observations")[0]
        ranges[col] = None if lo is None else [float(lo), float(hi)]
    sets = [
        {
            "context_id": c,
            "fingerprint": f,
            "folder": d,
            "n_captures": n,
            "n_observations": int(k),
            "last_learned_unix": t,
        }
        for c, f, d, n, k, t in store.query(
            "SELECT context_id, set_fingerprint, MAX(set_folder), COUNT(*), "
            "SUM(n_observations), MAX(learned_unix) FROM captures "
            "GROUP BY context_id, set_fingerprint ORDER BY context_id, MIN(learned_unix)"
        )
    ]
    return StoreStats(
        path=str(store.path),
        schema_version=store.schema_version,
        journal_mode=str(store.query("PRAGMA journal_mode")[0][0]),
        size_bytes=store.size_bytes(),
        n_captures=int(store.query("SELECT COUNT(*) FROM captures")[0][0]),
        n_observations=int(store.query("SELECT COUNT(*) FROM observations")[0][0]),
        by_orientation=by_o,
        by_focus_group=counts["focus_group"],
        by_source=counts["source"],
        ranges=ranges,
        contexts=[c.to_dict() for c in store.contexts()],
        sets=sets,
    )


def export_store(store: ReadableStore, out: str | os.PathLike[str]) -> int:
    """Write every observation to ``out`` (``.csv`` or ``.json``); returns the row count.

    The file is written beside its destination and renamed into place, so a failed export
    never leaves half a file. JSON holds ``schema_version``, ``captures`` and
    ``observations`` (unknown values as null); CSV one observation per row, unknown empty.
    """
    dest = Path(out)
    if dest.suffix.lower() not in (".csv", ".json"):
        raise InputError(f"export file must end in .csv or .json, got '{dest}'")
    with store.snapshot():  # one read snapshot for every query
        obs = store.observations()
        caps = store.query(
            "SELECT capture_id, learned_unix, n_observations, context_id, set_fingerprint "
            "FROM captures"
        )
        contexts = [c.to_dict() for c in store.contexts()]
    meta = {
        "format": "phonestereo-fix-store",
        "schema_version": store.schema_version,
        "store": str(store.path),
        "contexts": contexts,
        "captures": [
            {
                "capture_id": c,
                "learned_unix": t,
                "n_observations": n,
                "context_id": k,
                "set_fingerprint": f,
            }
            for c, t, n, k, f in caps
        ],
    }
    write_observations(dest, obs, meta)
    return int(obs.shape[0])


__all__ = ["ReadableStore", "StoreStats", "export_store", "store_stats"]
