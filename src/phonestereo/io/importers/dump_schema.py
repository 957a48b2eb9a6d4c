"""What the phone dumps' schemas share (docs/import-android.md, docs/import-apple.md): the
app-level labels every capture file carries (what the capture shows and how it was shot, as the
capture app tagged it), and the way a field's raw JSON value is checked.

The platform schemas (:mod:`.android_schema`, :mod:`.apple_schema`) derive their capture models
from :class:`CaptureLabels` and add their own format tag, motion sensor and per-camera results.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Literal

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field


def before(check: Callable[[Any], Any], *, optional: bool = False) -> BeforeValidator:
    """A field's check on its raw JSON value, for ``Annotated[type, before(check)]``: ``check``
    returns the value to validate as ``type`` or raises ValueError saying what is wrong (None
    is passed through unchecked when ``optional``)."""
    return BeforeValidator(lambda v: None if optional and v is None else check(v))


class CaptureLabels(BaseModel):
    """``captures/<name>.json``'s keys shared by the platforms; a platform's model narrows
    ``format`` to its own tag and adds the rest."""

    model_config = ConfigDict(frozen=True, extra="forbid", allow_inf_nan=False)

    #: The file's format tag (each platform narrows it to its own literal).
    format: str
    version: Literal[1]
    id: str = Field(min_length=1)
    kind: Literal["face", "verification", "scene", "calibration"]
    #: Orientation bucket label, when the motion sensor gives none.
    orientation: str | None = None
    #: ``focus_group``, ``focus_attempt``: the refocus stack (thesis §3.5.3) and the attempt.
    focus_group: str | None = None
    #: See ``focus_group`` above.
    focus_attempt: int | None = Field(None, ge=0)
    temperature_c: float | None = None
    #: [x, y, w, h] of the region of interest in the wide image, pixels.
    roi: tuple[int, int, int, int] | None = None
