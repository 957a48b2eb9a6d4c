"""What a fix store's observations were learned under: the *context* (docs/fix-store.md).

A learned correction is only valid for the geometry and the processing it was learned with:
the same calibration (the rig: both cameras' K, size and lens, and T_tele_wide), the same
lens model, the same rectification mode and the same learning-relevant flow configuration
(:meth:`phonestereo.flows.config.FlowConfig.context_dict`). A store records each context it
holds; ``learn`` into a store under another context refuses (unless a new context is asked
for), and ``depth`` / ``evaluate`` refuse to apply a store whose context differs from theirs,
naming the field that differs.

Examples
--------
>>> a = StoreContext('{"wide": {"f": 1}}', "opencv5/opencv5", "canonical", '{"warmup_s": 180}')
>>> b = StoreContext('{"wide": {"f": 2}}', "opencv5/opencv5", "canonical", '{"warmup_s": 180}')
>>> a.differences(b)
['calibration: wide.f is 1 in the store, 2 given']
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from phonestereo.geometry import Rig

#: The fields of a context, in the order differences are reported.
CONTEXT_FIELDS = ("lens_model", "rectification_mode", "calibration", "flow_config")


def canonical_json(obj: Any) -> str:
    """Compact JSON with sorted keys (the text a context stores and hashes)."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), allow_nan=True)


def sha256(text: str) -> str:
    """Hex SHA-256 of a text (UTF-8)."""
    return hashlib.sha256(text.encode()).hexdigest()


def _flatten(obj: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(obj, Mapping):
        out: dict[str, Any] = {}
        for k, v in obj.items():
            out.update(_flatten(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    if isinstance(obj, list):
        out = {}
        for i, v in enumerate(obj):
            out.update(_flatten(v, f"{prefix}[{i}]"))
        return out
    return {prefix: obj}


def json_differences(stored: str, given: str, limit: int = 3) -> list[str]:
    """The leaf paths where two JSON texts differ: ``"tele.K[0][0] is 2800 in the store, 2828
    given"``, at most ``limit`` of them (then ``"+N more"``)."""
    try:
        a, b = _flatten(json.loads(stored)), _flatten(json.loads(given))
    except ValueError:
        return ["(unreadable)"]
    keys = sorted(set(a) | set(b))
    missing = object()
    diffs = []
    for k in keys:
        va, vb = a.get(k, missing), b.get(k, missing)
        if va == vb:
            continue
        sa = "absent" if va is missing else repr(va)
        sb = "absent" if vb is missing else repr(vb)
        diffs.append(f"{k} is {sa} in the store, {sb} given")
    if len(diffs) > limit:
        diffs = [*diffs[:limit], f"+{len(diffs) - limit} more"]
    return diffs


@dataclass(frozen=True)
class StoreContext:
    """The conditions observations are learned under (module docstring)."""

    #: Canonical JSON of the rig: ``{"wide", "tele", "T_tele_wide"}`` as
    #: :meth:`~phonestereo.geometry.Rig.to_dict` writes them (metres, pixels). Conditions, RMS and
    #: covariance are not part of it: they do not change what is measured.
    calibration: str
    #: ``"<wide model>/<tele model>"``, e.g. ``"opencv5/opencv5"``.
    lens_model: str
    #: The reference rectification the observations' pixels live in.
    rectification_mode: str
    #: Canonical JSON of the learning-relevant flow configuration.
    flow_config: str

    @classmethod
    def build(
        cls, rig: Rig, rectification_mode: str, flow_config: Mapping[str, Any]
    ) -> StoreContext:
        """The context of learning on ``rig`` in ``rectification_mode`` under ``flow_config``."""
        return cls(
            calibration=canonical_json(rig.to_dict()),
            lens_model=f"{rig.wide.lens.name}/{rig.tele.lens.name}",
            rectification_mode=str(rectification_mode),
            flow_config=canonical_json(dict(flow_config)),
        )

    @property
    def calibration_sha256(self) -> str:
        """SHA-256 of :attr:`calibration`."""
        return sha256(self.calibration)

    @property
    def flow_config_sha256(self) -> str:
        """SHA-256 of :attr:`flow_config`."""
        return sha256(self.flow_config)

    def differences(self, given: StoreContext) -> list[str]:
        """What differs between this (stored) context and ``given``, one line per field, each
        naming the field and, for the JSON ones, the first differing entries."""
        out = []
        for name in CONTEXT_FIELDS:
            a, b = getattr(self, name), getattr(given, name)
            if a == b:
                continue
            if name in ("calibration", "flow_config"):
                out.append(f"{name.replace('_', ' ')}: " + "; ".join(json_differences(a, b)))
            else:
                out.append(f"{name.replace('_', ' ')}: {a!r} in the store, {b!r} given")
        return out

    def summary(self) -> dict[str, str]:
        """Short JSON-ready form: the two hashes (12 hex digits) and the two names."""
        return {
            "calibration_sha256": self.calibration_sha256[:12],
            "lens_model": self.lens_model,
            "rectification_mode": self.rectification_mode,
            "flow_config_sha256": self.flow_config_sha256[:12],
        }


__all__ = ["CONTEXT_FIELDS", "StoreContext", "canonical_json", "json_differences", "sha256"]
