"""The factory calibration file ``calibration.json`` (docs/calibration.md, thesis §1.3.2).

It holds both cameras (size, K, lens model name and coefficients), ``T_tele_wide`` (R as 3×3,
t in metres, p_tele = R·p_wide + t), the conditions the calibration was made under and, when
the calibration produced them, the parameter covariance and the RMS reprojection error.
Loading validates every field; a non-physical value raises the typed error geometry raises
(:class:`~phonestereo.errors.PhysicsError` for a negative focal length or zero baseline, ...)
with the file and field named. Saving is deterministic: equal calibrations give equal bytes,
and every float is written with ``repr`` so a load gives back the same bits.

Examples
--------
>>> from phonestereo.geometry import Camera, Rig, Transform
>>> wide = Camera((2000, 1500), 1500.0, 1500.0, 999.5, 749.5)
>>> cal = Calibration(Rig(wide, wide.scaled(3.0), Transform.from_rotvec([0, 0, 0], [0, -0.012, 0])))
>>> calibration_from_dict(calibration_to_dict(cal)).rig.baseline_m
0.012
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError
from phonestereo.geometry import Camera, Rig, Transform, lens_from_dict
from phonestereo.io.json_text import read_json

FORMAT_NAME = "phonestereo-calibration"
SCHEMA_VERSION = 1
_TOP_KEYS = (
    "format",
    "schema_version",
    "wide",
    "tele",
    "T_tele_wide",
    "conditions",
    "rms_px",
    "parameter_names",
    "covariance",
)


@dataclass(frozen=True)
class CalibrationConditions:
    """The conditions a calibration was made under (thesis §3.1, §3.4, §3.5)."""

    #: Focus distance of both cameras in metres (> 0), e.g. 0.6 for the factory calibration.
    focus_distance_m: float | None = None
    #: Module temperature in °C, if known.
    temperature_c: float | None = None
    #: Orientation label, e.g. "landscape".
    orientation: str | None = None
    #: Free text.
    note: str = ""
    #: The wide lens's physical focal length in millimetres (0 < f < 100), as the phone reports it
    #: (Camera2 ``LENS_INFO_AVAILABLE_FOCAL_LENGTHS``, EXIF ``FocalLength``). With
    #: ``focus_distance_m`` it gives the wide's focus breathing between calibration and use
    #: (:mod:`phonestereo.fixes.breathing`); None when unknown.
    wide_focal_length_mm: float | None = None

    def __post_init__(self) -> None:
        if self.focus_distance_m is not None:
            v = float(self.focus_distance_m)
            if not np.isfinite(v) or v <= 0:
                raise InputError(f"focus_distance_m must be a positive number of metres, got {v}")
            object.__setattr__(self, "focus_distance_m", v)
        if self.temperature_c is not None:
            v = float(self.temperature_c)
            if not np.isfinite(v):
                raise InputError(f"temperature_c must be finite, got {v}")
            object.__setattr__(self, "temperature_c", v)
        if self.orientation is not None and not isinstance(self.orientation, str):
            raise InputError(f"orientation must be a label string, got {self.orientation!r}")
        if not isinstance(self.note, str):
            raise InputError(f"note must be a string, got {self.note!r}")
        if self.wide_focal_length_mm is not None:
            v = float(self.wide_focal_length_mm)
            if not (np.isfinite(v) and 0 < v < 100):
                raise InputError(
                    f"wide_focal_length_mm must be the lens's focal length in millimetres "
                    f"(0–100), got {v}"
                )
            object.__setattr__(self, "wide_focal_length_mm", v)


@dataclass(frozen=True, eq=False)
class Calibration:
    """A stereo calibration: the rig, its conditions and optional uncertainty."""

    #: Wide and tele cameras and T_tele_wide (metres).
    rig: Rig
    conditions: CalibrationConditions = field(default_factory=CalibrationConditions)
    #: ndarray, shape (P, P), or None. Parameter covariance over ``parameter_names`` (units of the
    #: named parameters).
    covariance: NDArray[np.float64] | None = None
    #: tuple of str. The P parameter names, e.g. ``("wide.fx", "wide.cx", ...)``.
    parameter_names: tuple[str, ...] = ()
    #: RMS reprojection error in pixels.
    rms_px: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.rig, Rig):
            raise InputError(f"Calibration needs a Rig, got {type(self.rig).__name__}")
        if not isinstance(self.conditions, CalibrationConditions):
            raise InputError("Calibration conditions must be a CalibrationConditions")
        names = tuple(str(n) for n in self.parameter_names)
        if len(set(names)) != len(names):
            raise InputError(f"parameter_names must be unique, got {list(names)}")
        object.__setattr__(self, "parameter_names", names)
        if self.covariance is None:
            if names:
                raise InputError("parameter_names given without a covariance; give both or none")
        else:
            cov = np.array(self.covariance, dtype=np.float64)
            p = len(names)
            if cov.shape != (p, p):
                raise ShapeError(
                    f"covariance must have shape (P, P) = ({p}, {p}) for the {p} "
                    f"parameter_names, got {cov.shape}"
                )
            if not np.all(np.isfinite(cov)):
                raise InputError("covariance must be finite")
            scale = max(float(np.max(np.abs(cov))), 1e-300) if p else 1.0
            if p and float(np.max(np.abs(cov - cov.T))) > 1e-9 * scale:
                raise InputError("covariance must be symmetric")
            if p and float(np.min(np.diag(cov))) < 0:
                raise InputError("covariance diagonal (variances) must be >= 0")
            cov.setflags(write=False)
            object.__setattr__(self, "covariance", cov)
        if self.rms_px is not None:
            v = float(self.rms_px)
            if not np.isfinite(v) or v < 0:
                raise InputError(f"rms_px must be a finite number >= 0, got {v}")
            object.__setattr__(self, "rms_px", v)

    def std(self, name: str) -> float:
        """Standard deviation of one named parameter (sqrt of its covariance diagonal)."""
        if self.covariance is None or name not in self.parameter_names:
            raise InputError(
                f"no covariance for parameter '{name}'; known: {list(self.parameter_names)}"
            )
        i = self.parameter_names.index(name)
        return float(np.sqrt(self.covariance[i, i]))


# --- dict form --------------------------------------------------------------------------------
def calibration_to_dict(cal: Calibration) -> dict[str, Any]:
    """JSON-ready dict of a calibration, keys in a fixed order."""
    c = cal.conditions
    out: dict[str, Any] = {
        "format": FORMAT_NAME,
        "schema_version": SCHEMA_VERSION,
        "wide": cal.rig.wide.to_dict(),
        "tele": cal.rig.tele.to_dict(),
        "T_tele_wide": cal.rig.T_tele_wide.to_dict(),
        "conditions": {
            "focus_distance_m": c.focus_distance_m,
            "temperature_c": c.temperature_c,
            "orientation": c.orientation,
            "note": c.note,
            **({} if c.wide_focal_length_mm is None
               else {"wide_focal_length_mm": c.wide_focal_length_mm}),
        },
        "rms_px": cal.rms_px,
    }
    if cal.covariance is not None:
        out["parameter_names"] = list(cal.parameter_names)
        out["covariance"] = cal.covariance.tolist()
    return out


@contextmanager
def _field(source: str, name: str) -> Iterator[None]:
    """Re-raise errors inside the block with the file and field named, keeping the type."""
    try:
        yield
    except InputError as exc:
        raise type(exc)(f"{source}: field '{name}': {exc}") from exc
    except (KeyError, TypeError, ValueError, IndexError) as exc:
        raise InputError(f"{source}: field '{name}': malformed value ({exc})") from exc


def _require(data: dict[str, Any], key: str, source: str, prefix: str = "") -> Any:
    if key not in data:
        raise InputError(f"{source}: field '{prefix}{key}': required field is missing")
    return data[key]


def _check_keys(data: Any, allowed: tuple[str, ...], source: str, prefix: str) -> dict[str, Any]:
    if not isinstance(data, dict):
        what = f"field '{prefix.rstrip('.')}'" if prefix else "the document"
        raise InputError(f"{source}: {what} must be a JSON object, got {type(data).__name__}")
    extra = sorted(set(data) - set(allowed))
    if extra:
        raise InputError(
            f"{source}: field '{prefix}{extra[0]}': unknown field; allowed fields are "
            f"{list(allowed)} (check the spelling)"
        )
    return data


def _camera(data: Any, source: str, name: str) -> Camera:
    d = _check_keys(data, ("size", "K", "lens"), source, f"{name}.")
    size = _require(d, "size", source, f"{name}.")
    with _field(source, f"{name}.size"):
        if (
            not isinstance(size, list)
            or len(size) != 2
            or not all(isinstance(v, int) and not isinstance(v, bool) for v in size)
        ):
            raise InputError(f"must be [width, height] in pixels (two integers), got {size!r}")
    k = _require(d, "K", source, f"{name}.")
    with _field(source, f"{name}.K"):
        k_arr = np.asarray(k, dtype=np.float64)
    lens_d = _require(d, "lens", source, f"{name}.")
    with _field(source, f"{name}.lens"):
        _check_keys(lens_d, ("model", "coefficients"), source, f"{name}.lens.")
        lens = lens_from_dict(lens_d)
    with _field(source, f"{name}.K"):
        return Camera.from_matrix((size[0], size[1]), k_arr, lens)


def calibration_from_dict(data: Any, source: str = "calibration.json") -> Calibration:
    """Build a :class:`Calibration` from its dict form, validating every field.

    Raises
    ------
    InputError
        (or its subclasses ShapeError / PhysicsError) naming ``source`` and the field.
    """
    d = _check_keys(data, _TOP_KEYS, source, "")
    fmt = d.get("format", FORMAT_NAME)
    if fmt != FORMAT_NAME:
        raise InputError(f"{source}: field 'format': expected '{FORMAT_NAME}', got {fmt!r}")
    version = _require(d, "schema_version", source)
    if version != SCHEMA_VERSION:
        raise InputError(
            f"{source}: field 'schema_version': this phonestereo reads schema_version "
            f"{SCHEMA_VERSION}, got {version!r}; convert the file or upgrade phonestereo"
        )
    wide = _camera(_require(d, "wide", source), source, "wide")
    tele = _camera(_require(d, "tele", source), source, "tele")
    t_d = _check_keys(_require(d, "T_tele_wide", source), ("R", "t"), source, "T_tele_wide.")
    with _field(source, "T_tele_wide.R"):
        R = np.asarray(_require(t_d, "R", source, "T_tele_wide."), dtype=np.float64)
        if R.shape != (3, 3):
            raise ShapeError(f"must be a 3×3 rotation matrix, got shape {R.shape}")
    with _field(source, "T_tele_wide.t"):
        t = np.asarray(_require(t_d, "t", source, "T_tele_wide."), dtype=np.float64)
        if t.shape != (3,):
            raise ShapeError(f"must be 3 numbers in metres, got shape {t.shape}")
        if not np.all(np.isfinite(t)):
            raise InputError(f"must be 3 finite numbers in metres, got {t.tolist()}")
    with _field(source, "T_tele_wide.R"):
        T = Transform(R, t)
    with _field(source, "T_tele_wide.t"):
        rig = Rig(wide, tele, T)
    cond_keys = ("focus_distance_m", "temperature_c", "orientation", "note",
                 "wide_focal_length_mm")
    c_d = _check_keys(d.get("conditions", {}), cond_keys, source, "conditions.")
    conditions = CalibrationConditions()
    for key in cond_keys:
        with _field(source, f"conditions.{key}"):
            value = c_d.get(key)
            if value is None:
                continue
            if key == "note" or key == "orientation":
                if not isinstance(value, str):
                    raise InputError(f"must be a string, got {value!r}")
            elif isinstance(value, bool) or not isinstance(value, int | float):
                raise InputError(f"must be a number, got {value!r}")
            conditions = CalibrationConditions(**{**conditions.__dict__, key: value})
    with _field(source, "rms_px"):
        rms = d.get("rms_px")
        if rms is not None and (isinstance(rms, bool) or not isinstance(rms, int | float)):
            raise InputError(f"must be a number of pixels, got {rms!r}")
        Calibration(rig, rms_px=rms)
    names = d.get("parameter_names")
    names = [] if names is None else names  # null or absent: no covariance names
    with _field(source, "parameter_names"):
        if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
            raise InputError(f"must be a list of strings, got {names!r}")
    cov = d.get("covariance")
    with _field(source, "covariance"):
        cov_arr = None if cov is None else np.asarray(cov, dtype=np.float64)
        return Calibration(rig, conditions, cov_arr, tuple(names), rms)


# --- JSON file --------------------------------------------------------------------------------
def _dumps(obj: Any, level: int = 0) -> str:
    """JSON with indent 2 where lists holding only scalars stay on one line (matrix rows)."""
    pad, inner = "  " * level, "  " * (level + 1)
    if isinstance(obj, dict):
        if not obj:
            return "{}"
        items = [f"{inner}{json.dumps(str(k))}: {_dumps(v, level + 1)}" for k, v in obj.items()]
        return "{\n" + ",\n".join(items) + "\n" + pad + "}"
    if isinstance(obj, list):
        if all(not isinstance(v, dict | list) for v in obj):
            return "[" + ", ".join(_dumps(v) for v in obj) + "]"
        return "[\n" + ",\n".join(inner + _dumps(v, level + 1) for v in obj) + "\n" + pad + "]"
    return json.dumps(obj, ensure_ascii=False, allow_nan=False)


def calibration_json(cal: Calibration) -> str:
    """Deterministic JSON text: indent 2, matrix rows on one line, floats by ``repr``."""
    return _dumps(calibration_to_dict(cal)) + "\n"


def save_calibration(path: str | os.PathLike[str], cal: Calibration) -> Path:
    """Write ``cal`` as JSON to ``path`` (parent folders created); equal input, equal bytes."""
    if not isinstance(cal, Calibration):
        raise InputError(f"save_calibration needs a Calibration, got {type(cal).__name__}")
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
    tmp.write_text(calibration_json(cal), encoding="utf-8")
    os.replace(tmp, p)
    return p


def load_calibration(path: str | os.PathLike[str]) -> Calibration:
    """Read and validate a ``calibration.json``.

    Raises
    ------
    InputError
        Missing file, invalid JSON (with line and column) or an invalid field (named); a
        non-physical value keeps geometry's type (:class:`~phonestereo.errors.PhysicsError`,
        :class:`~phonestereo.errors.ShapeError`).
    """
    p = Path(path)
    if p.is_dir():
        raise InputError(f"calibration file '{p}' is a folder; give the calibration.json in it")
    if not p.is_file():
        raise InputError(
            f"calibration file '{p}' not found; give the path of a calibration.json (convert an "
            "OpenCV YAML with `phonestereo convert-calibration FILE.yml calibration.json`)"
        )
    return calibration_from_dict(read_json(p, "calibration file"), p.name)


__all__ = [
    "Calibration",
    "CalibrationConditions",
    "calibration_from_dict",
    "calibration_json",
    "calibration_to_dict",
    "load_calibration",
    "save_calibration",
]
