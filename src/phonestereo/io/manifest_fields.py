"""Checks of single manifest fields: paths that stay inside the set, orientation bucket labels.

Kept apart from :mod:`phonestereo.io.manifest` (the document model and its loading); both are
documented in docs/capture-set.md.
"""

from __future__ import annotations

from pathlib import PurePosixPath, PureWindowsPath

#: The orientation labels a manifest accepts: the buckets of
#: :func:`phonestereo.fixes.orientation.orientation_bucket` (same names, same order).
ORIENTATION_BUCKETS: tuple[str, ...] = (
    "landscape",
    "landscape-flipped",
    "portrait",
    "portrait-flipped",
    "face-up",
    "face-down",
)


def relative_path(value: str) -> str:
    """``value`` if it is a non-empty path relative to the set that stays inside it (else
    ValueError, which the manifest reports with the capture and field).

    >>> relative_path("images/w.png")
    'images/w.png'
    """
    if not value.strip():
        raise ValueError("must be a non-empty path relative to the capture-set folder")
    if PurePosixPath(value).is_absolute() or PureWindowsPath(value).is_absolute():
        raise ValueError(
            f"must be a path relative to the capture-set folder, got absolute path {value!r}; "
            "move the image into the folder and give its relative path"
        )
    parts = PurePosixPath(value.replace("\\", "/")).parts
    depth = 0
    for part in parts:
        depth += -1 if part == ".." else (0 if part == "." else 1)
        if depth < 0:
            raise ValueError(
                f"must stay inside the capture-set folder, got {value!r} (its '..' leaves the "
                "folder); copy the file into the capture set and give its path from there"
            )
    return value


def normalise_orientation(label: str) -> str:
    """An orientation label in its bucket spelling: lower case, ``-`` for ``_`` and spaces.

    >>> normalise_orientation("Landscape_Flipped")
    'landscape-flipped'
    """
    return "-".join(label.strip().lower().replace("_", " ").replace("-", " ").split())
