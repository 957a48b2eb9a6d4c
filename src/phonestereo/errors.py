"""Typed errors of phonestereo (docs/conventions.md).

Bad input raises one of these with a message that says what to do. A failure caused by the
data (no chart found, too few faces) is *not* an exception: it is a result with a reason.
"""

from __future__ import annotations


class PhoneStereoError(Exception):
    """Base class of every error phonestereo raises on purpose."""


class InputError(PhoneStereoError, ValueError):
    """An argument, file or parameter is malformed; the message names it and the fix."""


class ShapeError(InputError):
    """An array has the wrong shape; the message names the array and the expected shape."""


class PhysicsError(InputError):
    """A parameter is non-physical (negative focal length, zero baseline, ...)."""


class ConvergenceError(PhoneStereoError, RuntimeError):
    """An iterative solver did not reach its documented accuracy."""


class StoreError(PhoneStereoError, RuntimeError):
    """The fix store cannot be opened, migrated or written; nothing learned is lost."""
