"""The fingerprint of a capture set: which bytes a fix store's observations were learned from.

Capture ids are the phone's file names (``IMG_0001``) and repeat across sets, so a fix store
keys its captures by (fingerprint, capture id). The fingerprint is the SHA-256 of the
manifest's bytes followed by every image the manifest names, in manifest order (each image's
path and its bytes): re-learning the same folder is idempotent, another folder with the same
names is another set, and an edited image or manifest is a different set.
"""

from __future__ import annotations

import hashlib

from phonestereo.errors import InputError
from phonestereo.io.manifest import MANIFEST_NAME, CaptureSet

#: Length of the hex fingerprint kept (128 bits: collisions are not a concern).
FINGERPRINT_CHARS = 32


def capture_set_fingerprint(cs: CaptureSet) -> str:
    """SHA-256 (first 128 bits, hex) of the manifest and the image bytes of ``cs``.

    Parameters
    ----------
    cs : CaptureSet
        A loaded capture set; its manifest and images are read from ``cs.root``.

    Returns
    -------
    str
        32 hex characters.

    Raises
    ------
    InputError
        The manifest or an image cannot be read (the message names the file).
    """
    h = hashlib.sha256()
    names = dict.fromkeys([MANIFEST_NAME, *(n for e in cs.captures() for n in (e.wide, e.tele))])
    for name in names:  # manifest order, each file once
        p = cs.root / name
        h.update(name.encode() + b"\0")
        try:
            with p.open("rb") as fh:
                h.update(hashlib.file_digest(fh, "sha256").digest())
        except OSError as exc:
            raise InputError(
                f"cannot read '{p}' to fingerprint the capture set ({exc.strerror or exc}); "
                "check that the set is complete and readable"
            ) from exc
    return h.hexdigest()[:FINGERPRINT_CHARS]


__all__ = ["FINGERPRINT_CHARS", "capture_set_fingerprint"]
