"""What the Android and Apple exporters share: writing a dump folder from its documents."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path
from typing import Any

from phonestereo.io import Manifest


def write_dump(
    folder: str | os.PathLike[str],
    session: dict[str, Any],
    captures: dict[str, dict[str, Any]],
    manifest: Manifest,
    set_root: Path,
    ids: dict[str, str],
) -> Path:
    """Write ``session.json``, ``captures/<id>.json`` and ``images/<id>_<camera id>.<ext>``.

    The images are hard-linked from the capture set at ``set_root`` (copied where a link is
    not possible, e.g. across file systems); ``ids`` maps ``wide``/``tele`` to the platform's
    camera id used in the image names.
    """
    out = Path(folder)
    (out / "captures").mkdir(parents=True, exist_ok=True)
    (out / "images").mkdir(exist_ok=True)
    (out / "session.json").write_text(json.dumps(session, indent=1) + "\n", encoding="utf-8")
    for name, doc in captures.items():
        (out / "captures" / name).write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
    for c in manifest.captures:
        for role, rel in (("wide", c.wide), ("tele", c.tele)):
            src = set_root / rel
            dst = out / "images" / f"{c.id}_{ids[role]}{Path(rel).suffix}"
            if src.is_file() and not dst.exists():
                try:
                    os.link(src, dst)
                except OSError:
                    shutil.copy2(src, dst)
    return out
