"""Reading and writing capture images (8-bit grayscale in, PNG or JPEG out).

Files are read as bytes and decoded with :func:`cv2.imdecode` (so any path the OS accepts
works) in grayscale mode, **without** applying the EXIF Orientation tag: a calibration
describes the sensor's pixel grid, and a portrait JPEG turned upright by its EXIF tag would no
longer be that grid. PNG is written with a fixed compression level, which makes equal images
give byte-identical files. :func:`image_size` reads only the header (fast checks of a whole
capture set); :func:`size_mismatch` explains a size that differs from the calibration's.

Examples
--------
>>> import tempfile, pathlib
>>> img = np.zeros((1500, 2000), np.uint8)
>>> with tempfile.TemporaryDirectory() as d:
...     p = write_image(pathlib.Path(d) / "wide.png", img)
...     read_gray(p).shape                       # (H, W) = (height, width)
(1500, 2000)
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import NDArray

from phonestereo.errors import InputError, ShapeError

PNG_COMPRESSION = 3
_PNG = (".png",)
_JPEG = (".jpg", ".jpeg")


def read_gray(path: str | os.PathLike[str]) -> NDArray[np.uint8]:
    """Read an image file as 8-bit grayscale.

    Parameters
    ----------
    path : path
        Image file (any format OpenCV decodes: PNG, JPEG, TIFF, ...). Colour images are
        converted to gray; 16-bit images are scaled to 8 bits by OpenCV.

    Returns
    -------
    ndarray, shape (H, W), uint8

    Raises
    ------
    InputError
        The file is missing, cannot be decoded or is empty.
    """
    p = _image_file(path)
    try:
        data = np.fromfile(p, dtype=np.uint8)
    except OSError as exc:
        raise InputError(f"cannot read image file '{p}': {exc}") from exc
    if data.size == 0:
        raise InputError(f"image file '{p}' is empty (0 bytes); re-export the image")
    # IGNORE_ORIENTATION: the stored pixel grid, as the sensor wrote it (module docstring).
    img = cv2.imdecode(data, cv2.IMREAD_GRAYSCALE | cv2.IMREAD_IGNORE_ORIENTATION)
    if img is None:
        raise InputError(
            f"cannot decode image file '{p}' ({data.size} bytes); it is not an image OpenCV "
            "reads (use PNG or JPEG) or it is truncated"
        )
    if img.size == 0:
        raise InputError(f"image file '{p}' decodes to an empty image")
    return np.ascontiguousarray(img, dtype=np.uint8)


def image_size(path: str | os.PathLike[str]) -> tuple[int, int]:
    """(width, height) of an image file from its header, without decoding the pixels.

    The size is the stored pixel grid (EXIF Orientation is not applied), as :func:`read_gray`
    returns it.

    Raises
    ------
    InputError
        The file is missing, a folder, or not an image (e.g. a text file named ``.png``).
    """
    from PIL import Image, UnidentifiedImageError  # header reader; imported only when used

    p = _image_file(path)
    try:
        with Image.open(p) as im:
            w, h = im.size
    except (UnidentifiedImageError, OSError, ValueError) as exc:
        raise InputError(
            f"'{p}' is not an image file (its header is not PNG, JPEG, TIFF, ...): "
            "re-export the image, or fix the manifest entry that names it"
        ) from exc
    return int(w), int(h)


def size_mismatch(
    size: tuple[int, int], expected: tuple[int, int], what: str, camera: str
) -> str | None:
    """The message for an image whose size differs from the calibration's, naming the cause.

    Parameters
    ----------
    size, expected : (int, int)
        (width, height) of the image and of the calibration's camera, pixels.
    what : str
        The image, as the user knows it (e.g. "capture 'c001' wide image 'images/w.jpg'").
    camera : str
        "wide" or "tele".

    Returns
    -------
    str or None
        None when the sizes agree.

    >>> msg = size_mismatch((1500, 2000), (2000, 1500), "image 'p.jpg'", "wide")
    >>> msg.split(":")[0], "EXIF orientation" in msg
    ("image 'p.jpg' is 1500x2000, the calibration's wide camera is 2000x1500", True)
    """
    (w, h), (ew, eh) = size, expected
    if (w, h) == (ew, eh):
        return None
    head = f"{what} is {w}x{h}, the calibration's {camera} camera is {ew}x{eh}"
    if (w, h) == (eh, ew):
        return (
            f"{head}: a portrait image whose EXIF orientation a viewer or an export applied? "
            "Use the file as the camera wrote it (phonestereo ignores the EXIF Orientation "
            f"tag), or rotate it back to {ew}x{eh}"
        )
    if w * eh == h * ew:
        return (
            f"{head}: the same aspect ratio, scaled by {w / ew:.4g}; the image was resized, or "
            "the calibration was made at another resolution: capture at the calibrated "
            "resolution, or scale the calibration (Camera.scaled)"
        )
    return (
        f"{head}: a crop or another capture mode; capture in the mode the calibration was "
        "made in, or calibrate this one"
    )


def write_image(
    path: str | os.PathLike[str], image: Any, *, jpeg_quality: int = 95, noisy: bool = False
) -> Path:
    """Write an image as PNG (lossless, deterministic bytes) or JPEG, chosen by the suffix.

    Parameters
    ----------
    path : path
        Destination ending in ``.png``, ``.jpg`` or ``.jpeg``; parent folders are created.
    image : array_like, shape (H, W) or (H, W, 3) (BGR)
        uint8 (or uint16 for PNG).
    jpeg_quality : int
        JPEG quality 1–100 (ignored for PNG).
    noisy : bool
        PNG only: the image is sensor noise down to single pixels (a raw capture). Its PNG is
        then Huffman-coded without LZ77's search for repeats, which noise does not have: a
        rendered 2000 × 1500 capture encodes in 0.104 s instead of 0.174 s, and 12 % smaller
        (session 26). Smooth images compress far better with the default.

    Returns
    -------
    Path
        The written path.

    Raises
    ------
    InputError
        Unknown suffix or a dtype the format cannot hold.
    ShapeError
        An image that is not (H, W) or (H, W, 3) with H, W > 0.
    """
    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in _PNG + _JPEG:
        raise InputError(f"cannot write '{p}': use a .png (lossless) or .jpg/.jpeg suffix")
    img = np.asarray(image)
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] != 3) or 0 in img.shape:
        raise ShapeError(f"image must have shape (H, W) or (H, W, 3), got {img.shape}")
    allowed = (np.uint8, np.uint16) if suffix in _PNG else (np.uint8,)
    if img.dtype.type not in allowed:
        raise InputError(
            f"cannot write a {img.dtype} image as {suffix}; convert to uint8 first "
            "(e.g. np.clip(np.rint(img), 0, 255).astype(np.uint8))"
        )
    if suffix in _PNG:
        params = [cv2.IMWRITE_PNG_COMPRESSION, PNG_COMPRESSION]
        if noisy:
            params += [cv2.IMWRITE_PNG_STRATEGY, cv2.IMWRITE_PNG_STRATEGY_HUFFMAN_ONLY]
    else:
        if not 1 <= int(jpeg_quality) <= 100:
            raise InputError(f"jpeg_quality must be in 1..100, got {jpeg_quality}")
        params = [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]
    ok, buf = cv2.imencode(suffix, np.ascontiguousarray(img), params)
    if not ok:
        raise InputError(f"OpenCV could not encode the image for '{p}'")
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(f".{p.name}.{os.getpid()}.tmp")
    buf.tofile(tmp)
    os.replace(tmp, p)
    return p


def _image_file(path: str | os.PathLike[str]) -> Path:
    """``path`` as a Path if it names an existing file; InputError naming the fix otherwise."""
    p = Path(path)
    if p.is_dir():
        raise InputError(f"'{p}' is a folder, not an image file; give the image's path")
    if not p.is_file():
        raise InputError(f"image file not found: '{p}'; check the path")
    return p
