"""Capture sets: a folder with ``manifest.json`` and the images it lists (docs/capture-set.md).

A capture is one wide + tele image pair with what the phone reports about it: the time since
the camera app started (heating, thesis §3.1), gravity or an orientation label (§3.4), the
focus stack it belongs to and its focus mode (§3.5) and, when the module reports them, the
focus position and temperature. The manifest is validated on load; every invalid entry is
rejected with a message naming the capture and the field, e.g.::

    manifest.json: capture 'v03' field 'gravity': must be a unit vector (|g| = 1 ± 0.001),
    got [0.0, 2.0, 0.0]

Examples
--------
>>> entry = CaptureEntry(id="f01", wide="f01_wide.png", tele="f01_tele.png", time_s=185.0,
...                      gravity=(0.0, 1.0, 0.0), kind="face", focus_mode="manual")
>>> entry.focus_mode, entry.gravity
('manual', (0.0, 1.0, 0.0))
>>> CaptureEntry(id="f02", wide="w.png", tele="t.png", orientation=" Landscape ",
...              kind="face").orientation, entry.model_copy(update={"focus_mode": "unknown"}).time_s
('landscape', 185.0)

Nothing is guessed: a capture without ``focus_mode`` has focus mode "unknown" (the fixed-focus
gate then says so), one without ``time_s`` has time None (the heating gate falls back to the
drift-rate check and says so), and an ``orientation`` label must be one of
:data:`ORIENTATION_BUCKETS` (case and ``_``/space vs ``-`` are normalised).
"""

from __future__ import annotations

import json
import math
import os
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import pydantic
from pydantic import ConfigDict, Field, field_validator, model_validator

from phonestereo.errors import InputError
from phonestereo.io.json_text import parse_json, read_text
from phonestereo.io.manifest_fields import (
    ORIENTATION_BUCKETS,
    normalise_orientation,
    relative_path,
)

MANIFEST_NAME = "manifest.json"
SCHEMA_VERSION = 1
GRAVITY_TOL = 1e-3
Vec3 = tuple[float, float, float]

class CaptureEntry(pydantic.BaseModel):
    """One wide + tele capture of a capture set (docs/capture-set.md)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    #: Unique, non-empty identifier within the set.
    id: str
    #: ``wide``, ``tele``: Image paths relative to the capture-set folder.
    wide: str
    #: See ``wide`` above.
    tele: str
    #: Seconds since the camera app started (≥ 0; heating, thesis §3.1). None (left out) when
    #: unknown: the heating gate then falls back to the drift-rate check.
    time_s: float | None = Field(default=None, ge=0.0)
    #: Device-frame unit gravity vector (|g| = 1 ± 1e-3).
    gravity: tuple[float, float, float] | None = None
    #: Orientation bucket label, one of :data:`ORIENTATION_BUCKETS` ("landscape",
    #: "landscape-flipped", "portrait", ...; case-normalised); gravity or orientation must be given
    #: (thesis §3.4).
    orientation: str | None = None
    kind: Literal["face", "verification", "scene", "calibration"]
    #: Name of the refocus stack this capture belongs to (thesis §3.5.3).
    focus_group: str | None = None
    #: Index (≥ 0) of the attempt inside the stack.
    focus_attempt: int | None = Field(default=None, ge=0)
    #: "unknown" when left out: the fixed-focus gate then gates the capture, saying so.
    focus_mode: Literal["manual", "auto", "unknown"] = "unknown"
    #: Lens position as reported by the module (may be unreliable).
    focus_position: float | None = None
    #: Module temperature in °C, when reported.
    temperature_c: float | None = None
    #: Region of interest [x, y, w, h] in wide pixels, w, h > 0.
    roi: tuple[int, int, int, int] | None = None

    @field_validator("id")
    @classmethod
    def _id_non_empty(cls, v: str) -> str:
        if not v.strip():
            raise ValueError("must be a non-empty string")
        return v

    @field_validator("wide", "tele")
    @classmethod
    def _paths(cls, v: str) -> str:
        return relative_path(v)

    @field_validator("gravity")
    @classmethod
    def _unit_gravity(
        cls, v: tuple[float, float, float] | None
    ) -> tuple[float, float, float] | None:
        if v is not None:
            norm = math.sqrt(sum(c * c for c in v))
            if abs(norm - 1.0) > GRAVITY_TOL:
                raise ValueError(
                    f"must be a unit vector (|g| = 1 ± {GRAVITY_TOL}), got {list(v)} "
                    f"(|g| = {norm:.4g}); normalise the accelerometer reading"
                )
        return v

    @field_validator("orientation", "focus_group")
    @classmethod
    def _label(cls, v: str | None) -> str | None:
        if v is not None and not v.strip():
            raise ValueError("must be a non-empty label or be left out")
        return v

    @field_validator("orientation")
    @classmethod
    def _bucket(cls, v: str | None) -> str | None:
        if v is None:
            return v
        label = normalise_orientation(v)
        if label not in ORIENTATION_BUCKETS:
            raise ValueError(
                f"unknown orientation {v!r}; use one of {list(ORIENTATION_BUCKETS)}, or give "
                "'gravity' (the accelerometer's unit vector) instead"
            )
        return label

    @field_validator("roi")
    @classmethod
    def _roi(cls, v: tuple[int, int, int, int] | None) -> tuple[int, int, int, int] | None:
        if v is not None and (v[2] <= 0 or v[3] <= 0):
            raise ValueError(f"must be [x, y, w, h] with w, h > 0 (wide pixels), got {list(v)}")
        return v

    @model_validator(mode="after")
    def _gravity_or_orientation(self) -> CaptureEntry:
        if self.gravity is None and self.orientation is None:
            raise ValueError(
                "needs 'gravity' (device-frame unit vector) or 'orientation' (a label such as "
                "'landscape'); give at least one"
            )
        return self


class Manifest(pydantic.BaseModel):
    """The ``manifest.json`` of a capture set (docs/capture-set.md)."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    schema_version: Literal[1] = 1
    description: str = ""
    calibration: str = "calibration.json"
    captures: list[CaptureEntry]

    @field_validator("calibration")
    @classmethod
    def _calibration_path(cls, v: str) -> str:
        return relative_path(v)

    @field_validator("captures")
    @classmethod
    def _unique_ids(cls, v: list[CaptureEntry]) -> list[CaptureEntry]:
        dup = sorted(k for k, n in Counter(c.id for c in v).items() if n > 1)
        if dup:
            raise ValueError(f"capture ids must be unique; repeated: {dup}")
        return v


@dataclass(frozen=True)
class CaptureSet:
    """A loaded, validated capture set."""

    #: The capture-set folder; every path of the manifest is relative to it.
    root: Path
    manifest: Manifest

    def captures(self) -> tuple[CaptureEntry, ...]:
        """All captures in manifest order."""
        return tuple(self.manifest.captures)

    def get(self, capture_id: str) -> CaptureEntry:
        """The capture with this id; :class:`InputError` naming the known ids if absent."""
        for c in self.manifest.captures:
            if c.id == capture_id:
                return c
        ids = [c.id for c in self.manifest.captures]
        shown = ", ".join(repr(i) for i in ids[:20]) + (" ..." if len(ids) > 20 else "")
        raise InputError(
            f"no capture '{capture_id}' in {self.root / MANIFEST_NAME}; known ids: {shown}"
        )

    def image_paths(self, capture_id: str) -> tuple[Path, Path]:
        """(wide, tele) image paths of a capture: the set folder joined with the manifest paths."""
        c = self.get(capture_id)
        return self.root / c.wide, self.root / c.tele

    def calibration_path(self) -> Path:
        """Path of the factory calibration file of this set."""
        return self.root / self.manifest.calibration


# --- loading ----------------------------------------------------------------------------------
def _capture_label(raw: Any, index: int) -> str:
    captures = raw.get("captures") if isinstance(raw, dict) else None
    if isinstance(captures, list) and index < len(captures):
        entry = captures[index]
        if isinstance(entry, dict) and isinstance(entry.get("id"), str) and entry["id"].strip():
            return f"capture '{entry['id']}'"
    return f"capture #{index} (no valid id)"


def _format_error(err: Any, raw: Any, source: str) -> str:
    loc = tuple(err["loc"])
    msg = str(err["msg"]).removeprefix("Value error, ").replace("Input should", "should")
    kind = err["type"]
    where = ""
    if len(loc) >= 2 and loc[0] == "captures" and isinstance(loc[1], int):
        where = _capture_label(raw, loc[1])
        loc = loc[2:]
    field = ""
    if loc:
        field = str(loc[0]) + "".join(f"[{p}]" for p in loc[1:])
    if kind == "extra_forbidden":
        allowed = CaptureEntry.model_fields if where else Manifest.model_fields
        msg = f"unknown field; allowed fields are {sorted(allowed)} (check the spelling)"
    elif kind == "missing" and len(loc) > 1:
        field = str(loc[0])
        msg = f"too few values, got {err['input']!r}"
    elif kind == "missing":
        msg = "required field is missing"
    elif kind == "literal_error" and field == "schema_version":
        msg = (
            f"this phonestereo reads schema_version {SCHEMA_VERSION}, got {err['input']!r}; "
            "convert the manifest or upgrade phonestereo"
        )
    elif kind not in ("value_error", "assertion_error"):
        msg = f"{msg}, got {err['input']!r}"
    parts = [source + ":"]
    if where:
        parts.append(where)
    if field:
        parts.append(f"field '{field}':")
    elif where:
        parts[-1] += ":"
    return " ".join([*parts, msg])


def parse_manifest(text: str, source: str = MANIFEST_NAME) -> Manifest:
    """Validate manifest JSON text; :class:`InputError` naming capture and field on bad input.

    Parameters
    ----------
    text : str
        The JSON document.
    source : str
        Name used at the start of every error message.
    """
    raw = parse_json(text, source)
    if not isinstance(raw, dict):
        raise InputError(f"{source}: must be a JSON object with a 'captures' list")
    try:
        return Manifest.model_validate_json(text, strict=True)
    except pydantic.ValidationError as exc:
        errors = exc.errors()
        lines = [_format_error(e, raw, source) for e in errors[:10]]
        more = f"\n(and {len(errors) - 10} more errors)" if len(errors) > 10 else ""
        raise InputError("\n".join(lines) + more) from None


def load_capture_set(folder: str | os.PathLike[str], *, check_images: bool = True) -> CaptureSet:
    """Load and validate a capture set.

    Parameters
    ----------
    folder : path
        The capture-set folder (or its ``manifest.json``).
    check_images : bool
        Also check that every image file and the calibration file exist.

    Returns
    -------
    CaptureSet

    Raises
    ------
    InputError
        Missing folder or manifest, invalid JSON (with line and column), an invalid entry
        (naming the capture and field), a missing image or calibration file.
    """
    path = Path(folder)
    if path.is_file():
        root, manifest_path = path.parent, path
    else:
        root, manifest_path = path, path / MANIFEST_NAME
    if not root.is_dir():
        raise InputError(f"capture-set folder '{root}' does not exist; check the path")
    if not manifest_path.is_file():
        raise InputError(
            f"no {MANIFEST_NAME} in '{root}'; a capture set is a folder with {MANIFEST_NAME} "
            "and the images it lists (docs/capture-set.md)"
        )
    text = read_text(manifest_path, "the manifest")
    manifest = parse_manifest(text, str(manifest_path.name))
    cs = CaptureSet(root, manifest)
    if check_images:
        problems = []
        for c in manifest.captures:
            for field in ("wide", "tele"):
                p = root / getattr(c, field)
                if not p.is_file():
                    problems.append(
                        f"{manifest_path.name}: capture '{c.id}' field '{field}': image file not "
                        f"found: '{p}'; copy the image there or fix the path (relative to the "
                        "capture-set folder)"
                    )
        if not cs.calibration_path().is_file():
            problems.append(
                f"{manifest_path.name}: field 'calibration': calibration file not found: "
                f"'{cs.calibration_path()}'; put the factory calibration there (see "
                "`load_calibration`) or fix the path"
            )
        if problems:
            more = f"\n(and {len(problems) - 10} more)" if len(problems) > 10 else ""
            raise InputError("\n".join(problems[:10]) + more)
    return cs


def manifest_json(manifest: Manifest) -> str:
    """The deterministic JSON text of a manifest (indent 2, fields in model order, None omitted)."""
    data = manifest.model_dump(mode="json", exclude_none=True)
    return json.dumps(data, indent=2, ensure_ascii=False, allow_nan=False) + "\n"


def write_manifest(folder: str | os.PathLike[str], manifest: Manifest) -> Path:
    """Write ``manifest.json`` into ``folder`` (created if needed); byte-identical for equal input.

    Returns
    -------
    Path
        The written manifest path.
    """
    if not isinstance(manifest, Manifest):
        raise InputError(f"write_manifest needs a Manifest, got {type(manifest).__name__}")
    root = Path(folder)
    root.mkdir(parents=True, exist_ok=True)
    path = root / MANIFEST_NAME
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(manifest_json(manifest), encoding="utf-8")
    os.replace(tmp, path)
    return path
