"""What the Android and Apple exporters share: a capture file's labels, and writing a dump
folder from its documents."""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from phonestereo.errors import InputError
from phonestereo.io import CaptureEntry, Manifest


def capture_doc(
    fmt: str, c: CaptureEntry, motion: dict[str, list[float]], cams: dict[str, Any]
) -> dict[str, Any]:
    """A capture file's JSON: ``format`` ``fmt`` version 1, the capture's id and kind, the
    platform's motion vector (``motion``: its one key named as the platform names it), focus
    group and attempt, temperature and ROI, and the per-camera results ``cams``; labels the
    capture does not have are left out."""
    doc = {
        "format": fmt,
        "version": 1,
        "id": c.id,
        "kind": c.kind,
        **motion,
        "focus_group": c.focus_group,
        "focus_attempt": c.focus_attempt,
        "temperature_c": c.temperature_c,
        "roi": list(c.roi) if c.roi is not None else None,
        "cameras": cams,
    }
    return {k: v for k, v in doc.items() if v is not None}


def capture_docs(
    fmt: str,
    manifest: Manifest,
    dump: str,
    motion: Callable[[np.ndarray], dict[str, list[float]]],
    camera: Callable[[CaptureEntry, str, float], dict[str, Any]],
    ids: dict[str, str],
) -> dict[str, Any]:
    """The capture files of a dump: {``<capture id>.json``: :func:`capture_doc`} for every
    capture of ``manifest``.

    ``motion(g)`` is the platform's motion vector from the capture's gravity ``g`` (shape (3,),
    m/s² in the device frame); ``camera(c, role, time_s)`` the ``role`` camera's results, to
    which the image (``images/``:func:`image_name`) is prepended; ``ids`` maps ``wide``/``tele``
    to the platform's camera ids. ``dump`` names the dump in the errors (``a Camera2 dump``).

    Raises
    ------
    InputError
        A capture without gravity or ``time_s``: every platform dump records both.
    """
    docs = {}
    for c in manifest.captures:
        if c.gravity is None:
            raise InputError(f"capture '{c.id}' has no gravity to export: {dump} needs one")
        g = np.asarray(c.gravity, dtype=np.float64)
        if c.time_s is None:
            raise InputError(f"capture '{c.id}' has no time_s: {dump} needs a timestamp")
        cams = {
            ids[role]: {"image": f"images/{image_name(c, role, ids)}", **camera(c, role, c.time_s)}
            for role in ("wide", "tele")
        }
        docs[f"{c.id}.json"] = capture_doc(fmt, c, motion(g), cams)
    return docs


def image_name(c: CaptureEntry, role: str, ids: dict[str, str]) -> str:
    """The dump's image file of capture ``c``'s ``role`` camera (``wide`` or ``tele``):
    ``<capture id>_<platform camera id>.<the set's image suffix>``, in ``images/``."""
    return f"{c.id}_{ids[role]}{Path(c.wide if role == 'wide' else c.tele).suffix}"


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
            dst = out / "images" / image_name(c, role, ids)
            if src.is_file() and not dst.exists():
                try:
                    os.link(src, dst)
                except OSError:
                    shutil.copy2(src, dst)
    return out
