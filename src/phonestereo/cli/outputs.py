"""Where commands write: a user's existing files are never overwritten unless ``--force``.

Guards for the commands that write:

* :func:`require_output_file` — one output file (``--out``, ``--overlay``, ``--report``, ...):
  not a folder, of the right suffix, new unless ``--force``, in a folder that can be written;
* :func:`require_writable` — the folder a new file or folder would be made in can be written
  (not a file, not a read-only mount), so a command fails before its work, not after it;
* :func:`require_output_folder` — the folder may be new or hold anything, but not one of the
  files the command writes (unless ``--force``), and it must not be a file;
* :func:`prepare_capture_set_folder` — for ``simulate``: the folder must be new or empty, or
  an earlier capture set that ``--force`` removes cleanly (its manifest, calibration, ground
  truth and the images its manifest lists; nothing else is touched).

Both raise :class:`~phonestereo.errors.InputError` with the flag to change; the commands turn
that into exit 2.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

from phonestereo.errors import InputError
from phonestereo.io import parse_manifest

MANIFEST = "manifest.json"
#: Suffixes of the images a command writes (``--overlay``): lossless PNG or JPEG.
IMAGE_OUT = (".png", ".jpg", ".jpeg")
#: Phone dumps ``simulate --export`` writes beside a capture set.
EXPORTS = ("android", "apple")


def _nearest_existing(path: Path) -> Path:
    """``path`` or its nearest ancestor that exists (where a new path would be created)."""
    p = path.absolute()
    while not p.exists() and p != p.parent:
        p = p.parent
    return p


def require_writable(target: Path, *, flag: str = "--out") -> None:
    """Refuse ``target`` (a file or folder a command is about to write) when the folder it
    would be written in is a file or cannot be written (read-only mount, no permission).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     f = Path(d) / "notes.txt"
    ...     _ = f.write_text("mine")
    ...     try:
    ...         require_writable(f / "out.json", flag="--out")
    ...     except InputError as err:
    ...         print(str(err).split("' is ")[-1])
    a file; choose another --out
    """
    where = target if target.is_dir() else _nearest_existing(target.parent)
    if not where.is_dir():
        raise InputError(
            f"{flag} '{target}': the folder '{where}' is a file; choose another {flag}"
        )
    if not os.access(where, os.W_OK | os.X_OK):
        read_only = bool(os.statvfs(where).f_flag & os.ST_RDONLY)
        why = "is on a read-only file system" if read_only else "is not writable for you"
        raise InputError(
            f"{flag} '{target}': the folder '{where}' {why}; choose another {flag} in a folder "
            "you can write (nothing was written)"
        )


def require_output_file(
    path: Path, *, force: bool, flag: str = "--out", suffixes: Sequence[str] = ()
) -> None:
    """Refuse the output file ``path`` when it is a folder, lacks one of ``suffixes`` (when
    given), already exists (unless ``force``) or cannot be written (:func:`require_writable`).

    Call it before the command's work, so that a bad path costs nothing.

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     mine = Path(d) / "module.json"
    ...     _ = mine.write_text("{}")
    ...     try:
    ...         require_output_file(mine, force=False, suffixes=(".json",))
    ...     except InputError as err:
    ...         print(str(err).split("; ")[1])
    pass --force to overwrite it, or choose another --out
    """
    if path.is_dir():
        example = path / f"out{suffixes[0] if suffixes else ''}"
        raise InputError(
            f"{flag} '{path}' is a folder; {flag} names the file to write: give a file path "
            f"such as '{example}'"
        )
    if suffixes and path.suffix.lower() not in suffixes:
        raise InputError(
            f"{flag} '{path}' must end in {' or '.join(suffixes)}, got {path.suffix or 'no suffix'}"
        )
    if path.exists() and not force:
        raise InputError(
            f"{flag} '{path}' already exists; pass --force to overwrite it, or choose another "
            f"{flag}"
        )
    require_writable(path, flag=flag)


def require_output_folder(
    folder: Path, names: Sequence[str], *, force: bool, flag: str = "--out"
) -> None:
    """Refuse ``folder`` when it is a file, or already holds one of ``names`` (unless ``force``).

    Examples
    --------
    >>> import tempfile
    >>> with tempfile.TemporaryDirectory() as d:
    ...     _ = (Path(d) / "a.png").write_bytes(b"")
    ...     try:
    ...         require_output_folder(Path(d), ["a.png", "b.json"], force=False)
    ...     except InputError as err:
    ...         print(str(err).split(";")[1].strip())
    pass --force to overwrite them, or choose another --out
    """
    if folder.exists() and not folder.is_dir():
        raise InputError(
            f"{flag} '{folder}' is a file, not a folder; {flag} names the folder that "
            f"receives {', '.join(names)}: give a folder path"
        )
    clash = [n for n in names if (folder / n).exists()]
    if clash and not force:
        raise InputError(
            f"{flag} '{folder}' already holds {', '.join(clash)}; "
            f"pass --force to overwrite them, or choose another {flag}"
        )
    require_writable(folder, flag=flag)


def _inside(folder: Path, rel: str) -> Path | None:
    path = (folder / rel).resolve()
    return path if path.is_relative_to(folder.resolve()) else None


def prepare_capture_set_folder(folder: Path, *, force: bool, flag: str = "--out") -> list[Path]:
    """Make ``folder`` ready to receive a new capture set; returns the files removed.

    New or empty: nothing to do. An earlier capture set (``manifest.json`` present): refused
    unless ``force``; with ``force`` its files are removed (manifest, calibration,
    ``ground_truth.json``, the images the manifest lists, then empty image folders), so no old
    image is left beside the new manifest. Anything else: refused, even with ``force``.
    """
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{flag} '{folder}' is a file; give a new or empty folder")
    if not folder.exists() or not any(folder.iterdir()):
        return []
    manifest = folder / MANIFEST
    if not manifest.is_file():
        raise InputError(
            f"{flag} '{folder}' is not empty and holds no capture set (no {MANIFEST}); "
            f"choose a new or empty {flag} (--force replaces only an earlier capture set)"
        )
    if not force:
        raise InputError(
            f"{flag} '{folder}' already holds a capture set ({MANIFEST}); choose another "
            f"{flag}, or pass --force to replace it (its images, manifest, calibration and "
            "ground truth are removed first)"
        )
    dumps = [name for name in EXPORTS if (folder / name).exists()]
    if dumps:
        raise InputError(
            f"{flag} '{folder}' also holds {', '.join(dumps)} (an earlier simulate --export); "
            "--force replaces only the capture set's own files: remove those folders or "
            f"choose another {flag}"
        )
    try:
        old = parse_manifest(manifest.read_text(encoding="utf-8"), str(manifest))
    except (InputError, OSError, UnicodeDecodeError) as err:
        raise InputError(
            f"{flag} '{folder}': its {MANIFEST} cannot be read ({err}), so --force cannot tell "
            f"which files are the set's; remove the folder yourself or choose another {flag}"
        ) from err
    names = [MANIFEST, old.calibration, "ground_truth.json"]
    names += [p for c in old.captures for p in (c.wide, c.tele)]
    removed = []
    for name in names:
        path = _inside(folder, name)
        if path is not None and path.is_file():
            path.unlink()
            removed.append(path)
    for parent in sorted({p.parent for p in removed}, key=lambda p: -len(p.parts)):
        if parent != folder.resolve() and parent.is_dir() and not any(parent.iterdir()):
            parent.rmdir()
    return removed


__all__ = [
    "IMAGE_OUT",
    "prepare_capture_set_folder",
    "require_output_file",
    "require_output_folder",
    "require_writable",
]
