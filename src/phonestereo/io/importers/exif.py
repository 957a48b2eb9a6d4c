"""``phonestereo import exif``: plain JPEGs of the two cameras to a capture set
(docs/import-exif.md).

EXIF carries part of what a capture needs (EXIF 2.32 / CIPA DC-008 tag names):

* ``DateTimeOriginal`` (0x9003) + ``SubSecTimeOriginal`` (0x9291): the capture time. Wide and
  tele images are paired by it (nearest tele within ``max_gap_s``, one to one); ``time_s`` is
  the time since the first pair plus ``time_offset_s``, the seconds the camera app had run
  before the first pair, which EXIF does not know and the user must give.
* ``FocalLength`` (0x920A, mm): checks that WIDE_GLOB holds the shorter focal length.
* ``Orientation`` (0x0112): how the stored (sensor-oriented) image must be turned for display,
  which for a back camera with the usual landscape sensor maps to our buckets
  1 → landscape, 3 → landscape-flipped, 6 → portrait, 8 → portrait-flipped. Images are read
  as stored; the rotation is *not* applied.
* ``SubjectDistance`` (0x9206, m), when present: ``focus_position`` = 1/distance (dioptres).

EXIF has no focus mode, capture kind, app start time or factory calibration: each is a
required argument, never a default.
"""

from __future__ import annotations

import datetime as dt
import glob
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from phonestereo.errors import InputError
from phonestereo.io.calibration import load_calibration
from phonestereo.io.importers.common import ImportResult, write_set_atomically
from phonestereo.io.manifest import CaptureEntry, Manifest

EXIF_ORIENTATION = {1: "landscape", 3: "landscape-flipped", 6: "portrait", 8: "portrait-flipped"}
#: The orientation buckets (fixes/orientation.py), the labels --orientation accepts.
BUCKETS = (*EXIF_ORIENTATION.values(), "face-up", "face-down")
_EXIF_IFD = 0x8769


@dataclass(frozen=True)
class ExifShot:
    """What EXIF says about one JPEG."""

    path: Path
    size: tuple[int, int]
    time: dt.datetime
    focal_length_mm: float | None
    orientation: int | None
    subject_distance_m: float | None


def read_exif(path: Path) -> ExifShot:
    """The EXIF fields of one image; :class:`InputError` naming the file and tag when the
    capture time is missing."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            size = (int(im.size[0]), int(im.size[1]))
            exif = im.getexif()
    except (OSError, UnidentifiedImageError) as exc:
        raise InputError(f"cannot read image '{path}': {exc}") from exc
    sub = exif.get_ifd(_EXIF_IFD)
    stamp = sub.get(0x9003) or exif.get(0x0132)
    if not stamp:
        raise InputError(
            f"{path.name}: EXIF tag 'DateTimeOriginal' is missing; images cannot be paired "
            "without capture times (re-export the photos with their metadata)"
        )
    try:
        when = dt.datetime.strptime(str(stamp).strip("\x00 "), "%Y:%m:%d %H:%M:%S")
    except ValueError as exc:
        raise InputError(f"{path.name}: EXIF 'DateTimeOriginal' {stamp!r} is malformed") from exc
    frac = str(sub.get(0x9291, "") or "").strip("\x00 ")
    if frac.isdigit():
        when += dt.timedelta(seconds=float("0." + frac))
    focal = sub.get(0x920A)
    dist = sub.get(0x9206)
    orient = exif.get(0x0112)
    return ExifShot(
        path,
        size,
        when,
        float(focal) if focal else None,
        int(orient) if orient else None,
        float(dist) if dist and float(dist) > 0 else None,
    )


def _glob(pattern: str, what: str) -> list[ExifShot]:
    paths = sorted(Path(p) for p in glob.glob(os.path.expanduser(pattern)))
    if not paths:
        raise InputError(f"{what} '{pattern}' matches no file; quote the glob so the shell "
                         "passes it unexpanded, e.g. 'photos/wide_*.jpg'")
    return [read_exif(p) for p in paths]


def import_exif(
    wide_glob: str,
    tele_glob: str,
    calibration: str | os.PathLike[str],
    out: str | os.PathLike[str],
    *,
    kind: str,
    focus_mode: str,
    time_offset_s: float,
    orientation: str | None = None,
    max_gap_s: float = 1.0,
) -> ImportResult:
    """Pair wide and tele JPEGs by capture time and write a capture set.

    Parameters
    ----------
    wide_glob, tele_glob : str
        Glob patterns of the two cameras' images.
    calibration : path
        The rig's calibration.json (factory or your own); copied into the set.
    kind : {"face", "verification", "scene", "calibration"}
    focus_mode : {"manual", "auto"}
    time_offset_s : float
        Seconds the camera app had run before the first pair (≥ 0).
    orientation : str, optional
        Orientation bucket for images without an EXIF Orientation tag; overrides none.
    max_gap_s : float
        Largest capture-time difference of a wide/tele pair, seconds.
    """
    if orientation is not None and orientation not in BUCKETS:
        raise InputError(
            f"--orientation {orientation!r} is not a bucket; use one of {list(BUCKETS)}"
        )
    if not (math.isfinite(time_offset_s) and time_offset_s >= 0):
        raise InputError(f"--time-offset-s must be a number of seconds >= 0 (camera app start to "
                         f"first pair), got {time_offset_s}")
    if not (math.isfinite(max_gap_s) and max_gap_s > 0):
        raise InputError(f"--max-gap-s must be a positive number of seconds, got {max_gap_s}")
    cal = load_calibration(calibration)
    wides, teles = _glob(wide_glob, "WIDE_GLOB"), _glob(tele_glob, "TELE_GLOB")
    fw = [s.focal_length_mm for s in wides if s.focal_length_mm]
    ft = [s.focal_length_mm for s in teles if s.focal_length_mm]
    if fw and ft and min(ft) <= max(fw):
        raise InputError(
            f"EXIF FocalLength: WIDE_GLOB images reach {max(fw):g} mm and TELE_GLOB images "
            f"only {min(ft):g} mm; the tele has the longer focal length — swap the two globs"
        )
    for shots, cam, what in ((wides, cal.rig.wide, "wide"), (teles, cal.rig.tele, "tele")):
        for s in shots:
            if s.size != cam.size:
                raise InputError(
                    f"{s.path.name}: stored size {s.size[0]}×{s.size[1]} differs from the "
                    f"calibration's {what} size {cam.size[0]}×{cam.size[1]}; give the "
                    "calibration of these images (EXIF rotation is not applied on reading)"
                )
    pairs, notes, used = [], [], set()
    for w in sorted(wides, key=lambda s: s.time):
        best = min(
            (t for t in teles if t.path not in used),
            key=lambda t: abs((t.time - w.time).total_seconds()),
            default=None,
        )
        if best is None or abs((best.time - w.time).total_seconds()) > max_gap_s:
            notes.append(f"{w.path.name}: no tele image within {max_gap_s:g} s; left out")
            continue
        used.add(best.path)
        pairs.append((w, best))
    notes += [f"{t.path.name}: no wide image within {max_gap_s:g} s; left out"
              for t in teles if t.path not in used]
    if not pairs:
        raise InputError(
            f"no wide/tele pair within {max_gap_s:g} s; check the globs or --max-gap-s"
        )
    t0 = pairs[0][0].time
    entries, images = [], []
    for n, (w, t) in enumerate(pairs):
        label = _orientation(w, t, orientation)
        cid = f"e{n:03d}"
        entries.append(
            _capture_entry(
                id=cid,
                wide=f"images/{cid}_wide{w.path.suffix.lower()}",
                tele=f"images/{cid}_tele{t.path.suffix.lower()}",
                time_s=round(time_offset_s + (w.time - t0).total_seconds(), 6),
                orientation=label,
                kind=kind,
                focus_mode=focus_mode,
                focus_position=(
                    round(1.0 / w.subject_distance_m, 6) if w.subject_distance_m else None
                ),
            )
        )
        images += [(w.path, entries[-1].wide), (t.path, entries[-1].tele)]
    manifest = Manifest(description="imported from EXIF JPEGs", captures=entries)
    dest = write_set_atomically(out, cal, manifest, images)
    return ImportResult(
        dest, len(entries), {"wide": wide_glob, "tele": tele_glob}, {}, tuple(notes)
    )


def _capture_entry(**fields: Any) -> CaptureEntry:
    try:
        return CaptureEntry(**fields)
    except ValueError as exc:  # pydantic's ValidationError
        raise InputError(f"capture '{fields.get('id')}': {exc}") from exc


def _orientation(w: ExifShot, t: ExifShot, fallback: str | None) -> str:
    tags = {s.orientation for s in (w, t) if s.orientation is not None}
    if len(tags) > 1:
        raise InputError(
            f"{w.path.name} / {t.path.name}: EXIF Orientation differs ({sorted(tags)}); a pair "
            "is taken in one orientation — check the pairing (--max-gap-s)"
        )
    if tags:
        tag = tags.pop()
        if tag not in EXIF_ORIENTATION:
            raise InputError(
                f"{w.path.name}: EXIF Orientation {tag} (mirrored) is not a back-camera "
                "orientation; give --orientation"
            )
        return EXIF_ORIENTATION[tag]
    if fallback is None:
        raise InputError(
            f"{w.path.name}: EXIF tag 'Orientation' is missing; give --orientation (one of "
            f"{list(EXIF_ORIENTATION.values())} or face-up / face-down)"
        )
    return fallback
