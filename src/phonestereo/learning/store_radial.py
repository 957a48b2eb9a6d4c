"""The learning captures' residual radial distortion, read back from a fix store (thesis §3.2,
:mod:`~phonestereo.fixes.radial_residual`; written by
:meth:`~phonestereo.learning.store.FixStore.add_capture`)."""

from __future__ import annotations

import json

from phonestereo.fixes.distortion import RadialResidualFix
from phonestereo.fixes.radial_residual import radial_from_dict
from phonestereo.learning.store import FixStore


def radial_fits(store: FixStore, context_id: int | None = None) -> list[RadialResidualFix]:
    """Every stored capture's radial fit (of one context when ``context_id`` is given), in the
    order learned; captures learned without one are left out."""
    sql = "SELECT radial FROM captures WHERE radial IS NOT NULL"
    args: tuple[int, ...] = ()
    if context_id is not None:
        sql, args = sql + " AND context_id = ?", (int(context_id),)
    rows = store.query(sql + " ORDER BY learned_unix", args)
    return [radial_from_dict(json.loads(r[0])) for r in rows]


__all__ = ["radial_fits"]
