"""Manufacturing tolerances of the virtual module: the tolerances file, sampling, applying.

A tolerances file (JSON, or YAML when PyYAML is installed) lists parameters of a
:class:`~phonestereo.sim.module.ModuleSpec` by their dotted path and a distribution of the
*offset* from the module's nominal value (docs/architecture.md, tolerance studies)::

    {"schema_version": 1,
     "description": "folded-x3 production spread",
     "tolerances": [
        {"parameter": "tele.sag_px_per_g", "normal": {"sigma": 0.2}},
        {"parameter": "extrinsics.tele_center_mm.2", "uniform": {"low": -0.3, "high": 0.3}}]}

A path walks the spec's fields (``wide``, ``tele``, ``extrinsics``, ``heating``, ...); an
integer step indexes a tuple field (``wide.heating_drift_px.1`` is the wide camera's y drift
amplitude). Only float-valued leaves are parameters (no switches, sizes or names); every
name is checked against the spec before any work, and the error lists the valid ones.

Sample ``i`` of a study with seed ``s`` draws its offsets from its own stream
``default_rng([s, i])``, so a sample is the same whatever order or worker computes it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError, model_validator

from phonestereo.errors import InputError
from phonestereo.io.json_text import read_text
from phonestereo.sim.module import ModuleSpec, parse_module

_STRICT = ConfigDict(extra="forbid", frozen=True)
#: Fields that are not manufacturing parameters (names, switches, schema, sensor format).
_EXCLUDED_ROOTS = ("schema_version", "name", "description", "effects", "reports")


class NormalSpec(BaseModel):
    """Normal offset with 1σ ``sigma`` (same unit as the parameter) and mean ``mean``."""

    model_config = _STRICT
    sigma: float = Field(gt=0)
    mean: float = 0.0


class UniformSpec(BaseModel):
    """Uniform offset in [low, high] (same unit as the parameter)."""

    model_config = _STRICT
    low: float
    high: float

    @model_validator(mode="after")
    def _ordered(self) -> UniformSpec:
        if not self.high > self.low:
            raise ValueError(f"uniform needs high > low, got low={self.low}, high={self.high}")
        return self


class Tolerance(BaseModel):
    """One toleranced parameter: its path and exactly one distribution of its offset."""

    model_config = _STRICT
    parameter: str = Field(min_length=1)
    normal: NormalSpec | None = None
    uniform: UniformSpec | None = None

    @model_validator(mode="after")
    def _one(self) -> Tolerance:
        if (self.normal is None) == (self.uniform is None):
            raise ValueError(
                f"tolerance '{self.parameter}' needs exactly one of 'normal': {{'sigma': ...}} "
                "or 'uniform': {'low': ..., 'high': ...}"
            )
        return self

    @property
    def mean(self) -> float:
        """Mean of the offset distribution."""
        if self.normal is not None:
            return self.normal.mean
        assert self.uniform is not None
        return (self.uniform.low + self.uniform.high) / 2

    @property
    def scale(self) -> float:
        """Standard deviation of the offset distribution (the unit of a standardised value)."""
        if self.normal is not None:
            return self.normal.sigma
        assert self.uniform is not None
        return (self.uniform.high - self.uniform.low) / np.sqrt(12.0)

    def draw(self, rng: np.random.Generator) -> float:
        """One offset (one normal or one uniform draw)."""
        if self.normal is not None:
            return float(self.normal.mean + self.normal.sigma * rng.normal())
        assert self.uniform is not None
        return float(rng.uniform(self.uniform.low, self.uniform.high))


class ToleranceSet(BaseModel):
    """The tolerances file schema."""

    model_config = _STRICT
    schema_version: int = 1
    description: str = ""
    tolerances: tuple[Tolerance, ...] = Field(min_length=1)

    @model_validator(mode="after")
    def _unique(self) -> ToleranceSet:
        names = [t.parameter for t in self.tolerances]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"parameters listed twice: {dup}")
        return self

    @property
    def names(self) -> tuple[str, ...]:
        """Parameter paths, in file order."""
        return tuple(t.parameter for t in self.tolerances)


def _leaves(data: Any, prefix: str) -> list[str]:
    if isinstance(data, dict):
        out: list[str] = []
        for k, v in data.items():
            out += _leaves(v, f"{prefix}.{k}" if prefix else str(k))
        return out
    if isinstance(data, list | tuple):
        out = []
        for i, v in enumerate(data):
            out += _leaves(v, f"{prefix}.{i}")
        return out
    return [prefix] if isinstance(data, float) and not isinstance(data, bool) else []


def parameter_names(spec: ModuleSpec) -> tuple[str, ...]:
    """Every toleranceable parameter path of a module (its float-valued leaves).

    Examples
    --------
    >>> from phonestereo.sim.module import load_module
    >>> names = parameter_names(load_module("folded-x3"))
    >>> "extrinsics.tele_center_mm.2" in names, "tele.sag_px_per_g" in names
    (True, True)
    """
    data = spec.model_dump(mode="json")
    return tuple(
        name
        for name in _leaves(data, "")
        if name.split(".", 1)[0] not in _EXCLUDED_ROOTS and ".sensor." not in name
    )


def _canonical(path: str) -> str:
    """``extrinsics.tele_center_mm[2]`` → ``extrinsics.tele_center_mm.2``."""
    return path.strip().replace("[", ".").replace("]", "")


def validate_tolerances(tolerances: ToleranceSet, spec: ModuleSpec) -> ToleranceSet:
    """Check every parameter path against the spec (canonicalising ``a.b[2]`` to ``a.b.2``).

    Raises
    ------
    InputError
        Unknown parameters, with the list of valid ones.
    """
    valid = parameter_names(spec)
    canon = [_canonical(t.parameter) for t in tolerances.tolerances]
    unknown = [
        t.parameter for t, c in zip(tolerances.tolerances, canon, strict=True) if c not in valid
    ]
    if unknown:
        raise InputError(
            f"tolerances name unknown module parameter(s) {unknown}; valid parameters of module "
            f"'{spec.name}' are: {', '.join(valid)}"
        )
    items = tuple(
        t.model_copy(update={"parameter": c})
        for t, c in zip(tolerances.tolerances, canon, strict=True)
    )
    return tolerances.model_copy(update={"tolerances": items})


def _read_text(path: Path) -> Any:
    text = read_text(path, "tolerances file", "pass a UTF-8 JSON (or YAML) file to --tolerances")
    if path.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml  # type: ignore[import-untyped]
        except ImportError as exc:  # pragma: no cover - depends on the environment
            raise InputError(
                f"{path} is YAML but PyYAML is not installed; install it or write the "
                "tolerances as JSON"
            ) from exc
        return yaml.safe_load(text)
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise InputError(
            f"tolerances file {path} is not valid JSON: {exc.msg} at line {exc.lineno}, "
            f"column {exc.colno}"
        ) from None


def load_tolerances(path: str | Path, spec: ModuleSpec | None = None) -> ToleranceSet:
    """Read and validate a tolerances file (and, given a spec, its parameter names).

    Raises
    ------
    InputError
        Missing or malformed file, a bad distribution, or unknown parameters.
    """
    p = Path(path)
    if p.is_dir():
        raise InputError(f"tolerances file {p} is a folder; pass --tolerances FILE.json")
    if not p.is_file():
        raise InputError(f"tolerances file {p} does not exist; pass --tolerances FILE.json")
    try:
        tol = ToleranceSet.model_validate(_read_text(p))
    except ValidationError as err:
        lines = [
            f"  field '{'.'.join(str(x) for x in e['loc'])}': "
            + e["msg"].removeprefix("Value error, ")
            for e in err.errors()
        ]
        raise InputError(f"tolerances file {p} is invalid:\n" + "\n".join(lines)) from None
    return tol if spec is None else validate_tolerances(tol, spec)


def draw_offsets(tolerances: ToleranceSet, seed: int, index: int) -> np.ndarray:
    """Offsets (K,) of sample ``index`` of a study with ``seed``, in the parameters' units.

    >>> tol = ToleranceSet(tolerances=[Tolerance(parameter="tele.sag_px_per_g",
    ...                                          normal=NormalSpec(sigma=0.2))])
    >>> bool(draw_offsets(tol, 7, 3)[0] == draw_offsets(tol, 7, 3)[0])
    True
    """
    if seed < 0 or index < 0:
        raise InputError(f"seed and sample index must be >= 0, got {seed}, {index}")
    rng = np.random.default_rng([int(seed), int(index)])
    return np.array([t.draw(rng) for t in tolerances.tolerances], dtype=np.float64)


def standardised(tolerances: ToleranceSet, offsets: np.ndarray) -> np.ndarray:
    """(offset − mean) / std per parameter, (..., K) → (..., K) (unitless)."""
    mean = np.array([t.mean for t in tolerances.tolerances])
    scale = np.array([t.scale for t in tolerances.tolerances])
    return (np.asarray(offsets, dtype=np.float64) - mean) / scale


def _set(data: Any, steps: list[str], delta: float) -> None:
    *head, last = steps
    node = data
    for s in head:
        node = node[int(s)] if isinstance(node, list) else node[s]
    key: Any = int(last) if isinstance(node, list) else last
    node[key] = float(node[key]) + delta


def apply_offsets(spec: ModuleSpec, tolerances: ToleranceSet, offsets: np.ndarray) -> ModuleSpec:
    """The module with each toleranced parameter moved by its offset (validated again).

    Raises
    ------
    PhysicsError, InputError
        The moved module is not physical (e.g. a negative noise level); a study records that
        sample as failed with the message.
    """
    data = spec.model_dump(mode="json")
    for t, delta in zip(tolerances.tolerances, np.asarray(offsets, dtype=float), strict=True):
        _set(data, _canonical(t.parameter).split("."), float(delta))
    return parse_module(data, f"module '{spec.name}' with sampled tolerances")


@dataclass(frozen=True)
class SampledModule:
    """One study sample: its index, offsets (K,), standardised offsets (K,) and the module."""

    index: int
    offsets: np.ndarray
    z: np.ndarray
    spec: ModuleSpec


def sample_module(
    spec: ModuleSpec, tolerances: ToleranceSet, seed: int, index: int
) -> SampledModule:
    """Draw sample ``index`` and apply it (raises like :func:`apply_offsets`)."""
    off = draw_offsets(tolerances, seed, index)
    return SampledModule(
        index, off, standardised(tolerances, off), apply_offsets(spec, tolerances, off)
    )


__all__ = [
    "NormalSpec",
    "SampledModule",
    "Tolerance",
    "ToleranceSet",
    "UniformSpec",
    "apply_offsets",
    "draw_offsets",
    "load_tolerances",
    "parameter_names",
    "sample_module",
    "standardised",
    "validate_tolerances",
]
