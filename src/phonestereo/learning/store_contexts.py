"""The contexts table of the fix store: find, create and choose a context (docs/fix-store.md).

A context (:class:`~phonestereo.learning.provenance.StoreContext`) is what a store's
observations were learned under. The rules, for a user who keeps one store for months across
phones and firmware versions:

* **learning** goes into the context equal to the one given; when the store holds
  observations only under other contexts it refuses and names what differs, unless a new
  context is asked for (``learn --new-context``), which is then kept beside the others;
* **applying** (``depth``, ``evaluate``) uses only the observations of the equal context;
  without one it refuses and names the field that differs from the closest context;
* observations learned before contexts were recorded (schema < 3) sit in an *unrecorded*
  context: applying them is allowed when the store holds nothing else, with a warning (the
  calibration they were learned on cannot be checked); learning beside them needs
  ``--new-context``.
"""

from __future__ import annotations

import sqlite3
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from phonestereo.errors import ContextError
from phonestereo.learning.provenance import StoreContext
from phonestereo.learning.store_schema import LEGACY_NOTE


@dataclass(frozen=True)
class ContextInfo:
    """One row of the contexts table with what it holds.

    ``context`` is None for an unrecorded (pre-v3) context.
    """

    id: int
    context: StoreContext | None
    created_unix: float
    n_sets: int
    n_captures: int
    n_observations: int
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (hashes shortened to 12 hex digits)."""
        return {
            "id": self.id,
            "recorded": self.context is not None,
            **(self.context.summary() if self.context is not None else {}),
            "created_unix": self.created_unix,
            "n_sets": self.n_sets,
            "n_captures": self.n_captures,
            "n_observations": self.n_observations,
            "note": self.note,
        }


@dataclass(frozen=True)
class ContextChoice:
    """The context to read: its id and a warning to show (empty when exact)."""

    id: int | None
    warning: str = ""


def list_contexts(conn: sqlite3.Connection) -> list[ContextInfo]:
    """Every context with its counts, by id."""
    rows = conn.execute(
        "SELECT c.id, c.created_unix, c.calibration, c.lens_model, c.rectification_mode, "
        "c.flow_config, c.note, "
        "(SELECT COUNT(DISTINCT set_fingerprint) FROM captures k WHERE k.context_id = c.id), "
        "(SELECT COUNT(*) FROM captures k WHERE k.context_id = c.id), "
        "(SELECT COUNT(*) FROM observations o WHERE o.context_id = c.id) "
        "FROM contexts c ORDER BY c.id"
    ).fetchall()
    out = []
    for cid, created, cal, lens, mode, cfg, note, n_sets, n_caps, n_obs in rows:
        ctx = None if cal is None else StoreContext(cal, lens, mode, cfg)
        out.append(ContextInfo(cid, ctx, created, n_sets, n_caps, n_obs, note))
    return out


def insert_context(conn: sqlite3.Connection, ctx: StoreContext | None) -> int:
    """Add a context row (None: an unrecorded one); returns its id."""
    if ctx is None:
        cur = conn.execute(
            "INSERT INTO contexts (created_unix, note) VALUES (?, ?)", (time.time(), LEGACY_NOTE)
        )
    else:
        cur = conn.execute(
            "INSERT INTO contexts (created_unix, calibration_sha256, calibration, lens_model, "
            "rectification_mode, flow_config_sha256, flow_config) VALUES (?, ?, ?, ?, ?, ?, ?)",
            (
                time.time(),
                ctx.calibration_sha256,
                ctx.calibration,
                ctx.lens_model,
                ctx.rectification_mode,
                ctx.flow_config_sha256,
                ctx.flow_config,
            ),
        )
    return int(cur.lastrowid or 0)


def _closest(infos: list[ContextInfo], ctx: StoreContext) -> tuple[ContextInfo, list[str]] | None:
    recorded = [(i, i.context.differences(ctx)) for i in infos if i.context is not None]
    if not recorded:
        return None
    return min(recorded, key=lambda t: (len(t[1]), -t[0].n_observations))


def _mismatch(path: Path, infos: list[ContextInfo], ctx: StoreContext, action: str) -> str:
    used = [i for i in infos if i.n_captures > 0] or infos
    best = _closest(used, ctx)
    if best is None:
        head = (
            f"the fix store '{path}' holds only observations learned before contexts were "
            "recorded (its calibration and flow configuration are unknown)"
        )
    else:
        info, diffs = best
        many = f" (closest of its {len(used)} contexts)" if len(used) > 1 else ""
        head = (
            f"the fix store '{path}' was learned under another context{many}, #{info.id}: "
            + "; ".join(diffs)
        )
    if action == "learn":
        fix = (
            "use the calibration and --config it was learned with, or another store, or pass "
            "--new-context to `phonestereo learn` to keep these observations as a separate "
            "context in the same file. Nothing was written."
        )
    else:
        fix = (
            "pass the calibration and --config the store was learned with, or learn this "
            "calibration's face captures into it first (`phonestereo learn ... --new-context`)."
        )
    return f"{head}. To {action} with this store, {fix}"


def context_for_learning(conn: sqlite3.Connection, path: Path, ctx: StoreContext, new: bool) -> int:
    """The id of the context to learn into (created when needed); call inside a write
    transaction.

    Raises
    ------
    ContextError
        The store's observations were learned under other contexts and ``new`` is False.
    """
    infos = list_contexts(conn)
    for i in infos:
        if i.context == ctx:
            return i.id
    if new or not any(i.n_captures for i in infos):
        return insert_context(conn, ctx)
    raise ContextError(_mismatch(path, infos, ctx, "learn"))


def context_for_applying(conn: sqlite3.Connection, path: Path, ctx: StoreContext) -> ContextChoice:
    """The context whose observations apply under ``ctx`` (module docstring).

    Returns ``ContextChoice(None)`` for a store with no observations at all.

    Raises
    ------
    ContextError
        No context equals ``ctx``; the message names the field that differs.
    """
    infos = [i for i in list_contexts(conn) if i.n_observations > 0]
    if not infos:
        return ContextChoice(None)
    for i in infos:
        if i.context == ctx:
            return ContextChoice(i.id)
    if all(i.context is None for i in infos) and len(infos) == 1:
        return ContextChoice(
            infos[0].id,
            f"the fix store '{path}' was learned before contexts were recorded: its "
            "observations are applied, but the calibration and flow configuration they were "
            "learned under cannot be checked; re-learn them to record it",
        )
    raise ContextError(_mismatch(path, infos, ctx, "apply"))


__all__ = [
    "ContextChoice",
    "ContextInfo",
    "context_for_applying",
    "context_for_learning",
    "insert_context",
    "list_contexts",
]
