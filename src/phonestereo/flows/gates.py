"""The gates of the Phase 0 flows (thesis §4.1.1): heated, fixed focus, orientation known,
enough learned observations. A gated-out request is a result naming the gate and why.

Each gate is a small function of a capture's manifest entry (and, for the last, the store's
count), returning a :class:`Gate`; :func:`capture_gates` runs the capture gates in the order
of Fig. 4-2 / 4-3.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from phonestereo.fixes.warmup import WarmupGate
from phonestereo.io import CaptureEntry
from phonestereo.learning.learn import capture_orientation


@dataclass(frozen=True)
class Gate:
    """One gate's decision: ``name``, ``passed`` and, when not, ``reason``."""

    name: str
    passed: bool
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {"gate": self.name, "passed": self.passed, "reason": self.reason}


def heated_gate(entry: CaptureEntry, warmup_s: float) -> Gate:
    """§3.1: the module must be warm (time since the camera started ≥ ``warmup_s``).

    A capture without ``time_s`` falls back to the drift-rate check
    (:meth:`~phonestereo.fixes.warmup.WarmupGate.check`); a capture set holds no measured
    drift rate, so such a capture is gated out with a reason that names the check and the
    way out (record ``time_s``).
    """
    g = WarmupGate(min_time_s=warmup_s).check({"time_s": entry.time_s})
    if g.passed:
        return Gate("heated", True)
    prefix = "cold capture: " if entry.time_s is not None else "heating unknown: "
    return Gate("heated", False, prefix + g.reason)


def fixed_focus_gate(entry: CaptureEntry) -> Gate:
    """§3.5: a manual (locked) focus; an autofocus capture may have refocused anywhere.

    ``focus_mode`` "unknown" (the manifest did not say) is gated out too: a user who leaves it
    out has not said the focus was locked, and a refocused lens moves the disparity by more
    than the learned fixes correct (§3.5.2). The reason says to record the mode.
    """
    if entry.focus_mode == "auto":
        return Gate(
            "fixed-focus", False,
            "autofocus capture: the lens may sit anywhere (§3.5.2); lock a manual focus",
        )
    if entry.focus_mode != "manual":
        return Gate(
            "fixed-focus",
            False,
            "focus mode unknown (no 'focus_mode' in the manifest): cannot tell whether the "
            "focus was locked (§3.5.2); set focus_mode to \"manual\" if it was, or \"auto\"",
        )
    return Gate("fixed-focus", True)


def orientation_gate(entry: CaptureEntry) -> Gate:
    """§3.4: the orientation bucket must be known (gravity or an orientation label)."""
    if capture_orientation(entry) == "unknown":
        return Gate(
            "orientation", False,
            "no gravity vector or orientation label: the orientation bucket is unknown (§3.4)",
        )
    return Gate("orientation", True)


def learned_gate(n_observations: int, min_observations: int, bucket: str) -> Gate:
    """§4.1.1: enough learned observations in the capture's orientation bucket."""
    if n_observations < min_observations:
        return Gate(
            "learned", False,
            f"{n_observations} learned observations in orientation bucket '{bucket}' (< "
            f"{min_observations}); run `phonestereo learn` on face captures in this "
            "orientation first",
        )
    return Gate("learned", True)


def capture_gates(
    entry: CaptureEntry,
    *,
    warmup_s: float,
    heating: bool = True,
    focus: bool = True,
    heating_corrected: bool = False,
) -> list[Gate]:
    """The capture gates in order (heated, fixed focus, orientation); switched-off gates are
    reported as passed with the reason "off". ``heating_corrected``: the capture's reported
    temperature indexes a learned heating term, so a cold capture passes the heated gate (its
    drift is corrected, not waited out)."""
    if not heating:
        heat = Gate("heated", True, "off")
    elif heating_corrected:
        heat = Gate(
            "heated",
            True,
            f"{entry.temperature_c:.2f} °C: the drift is corrected by the learned heating term, "
            "not waited out",
        )
    else:
        heat = heated_gate(entry, warmup_s)
    gates = [
        heat,
        fixed_focus_gate(entry) if focus else Gate("fixed-focus", True, "off"),
        orientation_gate(entry),
    ]
    return gates


def first_failed(gates: list[Gate]) -> Gate | None:
    """The first gate that did not pass, or None."""
    return next((g for g in gates if not g.passed), None)


__all__ = [
    "Gate",
    "capture_gates",
    "first_failed",
    "fixed_focus_gate",
    "heated_gate",
    "learned_gate",
    "orientation_gate",
]
