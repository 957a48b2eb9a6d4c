"""Opening an existing fix store to read it (``depth``, ``store stats``, docs/fix-store.md)."""

from __future__ import annotations

import os
from pathlib import Path

from phonestereo.errors import StoreError
from phonestereo.learning.store import FixStore


def refuse_empty(path: Path) -> None:
    """Refuse an empty (0-byte) file as a store: SQLite would make a new store in it, and a
    command that reads or maintains a store (``depth``, ``store stats|export|vacuum``) never
    makes one.

    Raises
    ------
    StoreError
        ``path`` is an empty file.
    """
    if path.is_file() and path.stat().st_size == 0:
        raise StoreError(
            f"the fix store '{path}' is an empty file, not a fix store; it was left untouched "
            "(a command that only reads a store never makes one): check the path, or learn a "
            "store with `phonestereo learn CAPTURE_SET --calibration FILE --store FILE`"
        )


def open_for_reading(path: str | os.PathLike[str], timeout_s: float = 60.0) -> FixStore:
    """Open an existing store to read it (``depth``, ``store stats``): writable when the file
    and its folder are (an old schema is then migrated, with a backup), read-only otherwise
    (a read-only mount or file), never created.

    Raises
    ------
    StoreError
        The file does not exist, is empty (a read never makes a store), or cannot be opened
        (the message names the fix).
    """
    p = Path(path)
    if not p.exists():
        raise StoreError(
            f"the fix store '{p}' does not exist; check the path, or learn one with "
            "`phonestereo learn CAPTURE_SET --calibration FILE --store FILE`"
        )
    refuse_empty(p)
    writable = os.access(p, os.W_OK) and os.access(p.parent, os.W_OK | os.X_OK)
    return FixStore(p, readonly=not writable, timeout_s=timeout_s)


__all__ = ["open_for_reading", "refuse_empty"]
