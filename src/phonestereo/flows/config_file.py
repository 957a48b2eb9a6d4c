"""``--config FLOW.json``: the flow configuration as a documented, validated file.

The schema is a pydantic model built from the dataclasses
(:class:`~phonestereo.flows.config.FlowConfig`, :class:`~phonestereo.flows.roi_disparity.RoiConfig`,
:class:`~phonestereo.features.match_config.MatchConfig`): their defaults, with each knob's
unit, meaning and reason from :data:`~phonestereo.flows.config_knobs.KNOBS` as its
description. A file may give any subset of the knobs (the rest keep their defaults); an
unknown key, a wrong type or a value the dataclasses refuse is an
:class:`~phonestereo.errors.InputError` naming the key. ``phonestereo config show`` prints the
defaults in this format.

Examples
--------
>>> cfg = flow_config_from_dict({"warmup_s": 240, "roi": {"match": {"radius": 9}}})
>>> cfg.warmup_s, cfg.roi.match.radius, cfg.roi.expand
(240.0, 9, 1.6)
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import typing
from functools import cache
from pathlib import Path
from typing import Any

import pydantic

from phonestereo.errors import InputError
from phonestereo.features.match_config import MatchConfig
from phonestereo.flows.config import FlowConfig
from phonestereo.flows.config_knobs import KNOBS
from phonestereo.flows.roi_disparity import RoiConfig
from phonestereo.io.json_text import read_text

#: Each dataclass with a nested dataclass field: (field name, its class, its KNOBS section).
_NESTED: dict[type[Any], tuple[str, type[Any], str]] = {
    RoiConfig: ("match", MatchConfig, "match"),
    FlowConfig: ("roi", RoiConfig, "roi"),
}


def describe(section: str, name: str) -> str:
    """``"[unit] meaning Default: why."`` of one knob."""
    unit, meaning, why = KNOBS[section][name]
    return f"[{unit}] {meaning} Default: {why}"


def _model(cls: type[Any], default: Any, section: str) -> type[pydantic.BaseModel]:
    """The pydantic model of ``cls`` whose defaults are the values of ``default`` (an
    instance: RoiConfig's MatchConfig has the flow's 450 keypoints, not the matcher's 2000)."""
    hints = typing.get_type_hints(cls)
    nested = _NESTED.get(cls)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        value = getattr(default, f.name)
        if nested is not None and f.name == nested[0]:
            sub = _model(nested[1], value, nested[2])
            fields[f.name] = (sub, pydantic.Field(default_factory=sub))
        else:
            desc = describe(section, f.name)
            fields[f.name] = (hints[f.name], pydantic.Field(value, description=desc))
    model: type[pydantic.BaseModel] = pydantic.create_model(  # type: ignore[call-overload]
        f"{cls.__name__}File",
        __config__=pydantic.ConfigDict(extra="forbid"),
        __doc__=(cls.__doc__ or "").split("\n")[0],
        **fields,
    )
    return model


@cache
def flow_model() -> type[pydantic.BaseModel]:
    """The pydantic model of a ``--config`` file (the top level is :class:`FlowConfig`)."""
    return _model(FlowConfig, FlowConfig(), "flow")


def _build(cls: type[Any], data: dict[str, Any]) -> Any:
    nested = _NESTED.get(cls)
    if nested is not None:
        name, sub, _ = nested
        data = {**data, name: _build(sub, data[name])}
    return cls(**data)


def flow_config_from_dict(data: Any, source: str = "the flow config") -> FlowConfig:
    """Validate a dict of knobs (any subset) and build the :class:`FlowConfig`.

    Raises
    ------
    InputError
        Not an object, an unknown key, a wrong type or a refused value; the message names
        the key path and points to ``phonestereo config show``.
    """
    if not isinstance(data, dict):
        raise InputError(f"{source} must be a JSON object of knobs; see `phonestereo config show`")
    bad = _non_finite(data)
    if bad is not None:
        raise InputError(
            f"{source}: knob {bad[0]} is {bad[1]}; every knob is a finite number "
            "(`phonestereo config show` prints the defaults)"
        )
    try:
        model = flow_model().model_validate(data)
    except pydantic.ValidationError as exc:
        lines = [f"{'.'.join(str(p) for p in e['loc'])}: {e['msg']}" for e in exc.errors()[:5]]
        raise InputError(
            f"{source} is not a valid flow configuration: {'; '.join(lines)}. "
            "`phonestereo config show` prints every knob with its default."
        ) from None
    try:
        cfg: FlowConfig = _build(FlowConfig, model.model_dump())
    except InputError as exc:
        raise InputError(f"{source}: {exc}") from None
    return cfg


def load_flow_config(path: str | os.PathLike[str] | None) -> FlowConfig:
    """The :class:`FlowConfig` of a ``--config`` file (None: the defaults).

    Raises
    ------
    InputError
        The file is missing, unreadable, not JSON or not a valid configuration.
    """
    if path is None:
        return FlowConfig()
    p = Path(path)
    if p.is_dir():
        raise InputError(f"--config {p} is a folder; give a JSON file (phonestereo config show)")
    text = read_text(p, "--config", "write one with `phonestereo config show > flow.json` and "
                     "edit it")
    try:
        data = json.loads(text)
    except ValueError as exc:
        raise InputError(f"--config {p} is not valid JSON ({exc})") from None
    return flow_config_from_dict(data, f"--config {p}")


def _non_finite(data: Any, path: str = "") -> tuple[str, float] | None:
    """The first knob (dotted path) of a parsed config whose value is NaN or ±Infinity.

    >>> _non_finite({"warmup_s": 240, "roi": {"match": {"radius": float("inf")}}})
    ('roi.match.radius', inf)
    """
    if isinstance(data, float) and not math.isfinite(data):
        return path, data
    items = data.items() if isinstance(data, dict) else enumerate(data) if isinstance(
        data, list) else ()
    for key, value in items:
        found = _non_finite(value, f"{path}.{key}" if path else str(key))
        if found is not None:
            return found
    return None


def flow_config_json(cfg: FlowConfig | None = None) -> str:
    """The configuration as a ``--config`` file (every knob; the defaults when None)."""
    d = dataclasses.asdict(cfg if cfg is not None else FlowConfig())
    return json.dumps(d, indent=1)


def flow_config_schema() -> dict[str, Any]:
    """The JSON schema of the file, with every knob's description."""
    return flow_model().model_json_schema()


def knobs_markdown() -> str:
    """The knob tables of docs/flow-config.md (one per section, defaults from the code)."""
    parts = []
    titles = {
        "flow": ("Top level: `FlowConfig`", FlowConfig(), ""),
        "roi": ("`roi`: `RoiConfig` (the ROI measurement)", FlowConfig().roi, "roi."),
        "match": ("`roi.match`: `MatchConfig` (the matcher)", FlowConfig().roi.match, "roi.match."),
    }
    for section, (title, inst, prefix) in titles.items():
        header = "| knob | default | unit | meaning | why the default |"
        rows = [f"### {title}", "", header, "|---|---|---|---|---|"]
        for name, (unit, meaning, why) in KNOBS[section].items():
            value = json.dumps(getattr(inst, name))
            rows.append(f"| `{prefix}{name}` | `{value}` | {unit} | {meaning} | {why} |")
        parts.append("\n".join(rows))
    return "\n\n".join(parts) + "\n"


__all__ = [
    "describe",
    "flow_config_from_dict",
    "flow_config_json",
    "flow_config_schema",
    "flow_model",
    "knobs_markdown",
    "load_flow_config",
]
