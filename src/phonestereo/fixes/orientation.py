"""Orientation (thesis §3.4, Figure 3-11): buckets from gravity and a per-bucket disparity offset.

Gravity bends the assembled module differently in each device orientation, so the same object
gives a different disparity when the phone is flipped (Figure 3-11: an offset). The thesis's
fix: record the gyro/gravity reading when a fix is learned and when it is applied, and use a
fix only within the orientation it was learned in (docs/architecture.md;
the "orientation bucket known" gate of §4.1.1).

Bucket rule (:func:`orientation_bucket`). Gravity ``g`` is a device-frame unit vector; the
device frame is the wide camera's frame in landscape (x right, y down, z forward, out of the
rear cameras). The bucket is named after the axis with the largest ``|g_i|`` (ties broken in
the order y, x, z) and its sign:

=================== =========================== =================================
dominant component  bucket                      the phone is ...
=================== =========================== =================================
``+g_y``            ``landscape``               upright landscape (calibration)
``−g_y``            ``landscape-flipped``       landscape rolled by 180°
``+g_x``            ``portrait``                rolled so the image x axis points down
``−g_x``            ``portrait-flipped``        rolled the other way
``+g_z``            ``face-up``                 lying flat, cameras looking down
``−g_z``            ``face-down``               lying flat, cameras looking up
=================== =========================== =================================

:class:`OrientationOffsets` fits one disparity offset per bucket from (bucket, measured d,
expected d) samples — e.g. chart corners of known depth, or face observations — and corrects a
disparity only inside a bucket it knows; an unknown bucket is a result with a reason
(:meth:`OrientationOffsets.lookup`) or an :class:`~phonestereo.errors.InputError`
(:meth:`OrientationOffsets.offset`), never a silent zero.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from phonestereo.errors import InputError, ShapeError
from phonestereo.io.manifest_fields import ORIENTATION_BUCKETS

#: Every bucket :func:`orientation_bucket` can return, in the order of the table above (the
#: labels a manifest accepts, defined once in io beside the manifest's checks).
BUCKETS: tuple[str, ...] = ORIENTATION_BUCKETS
_AXIS_ORDER = (1, 0, 2)  # ties broken in the order y, x, z
_NAMES = {(1, 1): "landscape", (1, -1): "landscape-flipped", (0, 1): "portrait",
          (0, -1): "portrait-flipped", (2, 1): "face-up", (2, -1): "face-down"}


def orientation_bucket(gravity: Any) -> str:
    """The orientation bucket of a device-frame gravity vector (thesis §3.4; rule above).

    Parameters
    ----------
    gravity : array_like, shape (3,)
        Gravity in the device frame (any non-zero length; an accelerometer reading in m/s²
        works too).

    Returns
    -------
    str
        One of :data:`BUCKETS`.

    Raises
    ------
    ShapeError
        ``gravity`` is not three numbers.
    InputError
        ``gravity`` is zero or not finite.

    Examples
    --------
    >>> orientation_bucket([0.0, 1.0, 0.0]), orientation_bucket([0.05, -0.99, 0.1])
    ('landscape', 'landscape-flipped')
    >>> orientation_bucket([9.81, 0.3, 0.0])            # accelerometer units are fine
    'portrait'
    """
    g = np.asarray(gravity, dtype=np.float64)
    if g.shape != (3,):
        raise ShapeError(f"gravity must be a (3,) device-frame vector, got shape {g.shape}")
    if not np.isfinite(g).all() or not np.any(g):
        raise InputError(
            f"gravity must be a finite non-zero vector, got {g.tolist()}; pass the "
            "accelerometer's gravity estimate in the device frame"
        )
    mags = np.abs(g)[list(_AXIS_ORDER)]
    axis = _AXIS_ORDER[int(np.argmax(mags))]  # argmax takes the first maximum: y, x, z
    return _NAMES[(axis, 1 if g[axis] > 0 else -1)]


def capture_bucket(gravity: Any = None, orientation: str | None = None) -> str:
    """The bucket of a capture from its manifest ``gravity`` or, without it, its label.

    Gravity wins when both are given (labels are coarser). A label must be one of
    :data:`BUCKETS`.

    Examples
    --------
    >>> capture_bucket(None, "landscape-flipped"), capture_bucket((0.0, 1.0, 0.0), "portrait")
    ('landscape-flipped', 'landscape')
    """
    if gravity is not None:
        return orientation_bucket(gravity)
    if orientation is None:
        raise InputError("a capture needs 'gravity' or an 'orientation' label to get a bucket")
    if orientation not in BUCKETS:
        raise InputError(
            f"orientation label {orientation!r} is not a bucket; use one of {list(BUCKETS)} or "
            "give the gravity vector"
        )
    return orientation


@dataclass(frozen=True)
class BucketOffset:
    """The disparity offset learned in one orientation bucket (a lookup result)."""

    bucket: str
    #: False when nothing was learned in this bucket (``reason`` says so).
    found: bool
    reason: str
    #: Mean of d_measured − d_expected over the bucket's samples, pixels (NaN if not found).
    offset_px: float
    #: 1σ of that mean (standard error; ∞ with a single sample).
    sigma_px: float
    #: Standard deviation of the single samples, pixels.
    spread_px: float
    #: Samples used.
    n: int

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (NaN/∞ → None)."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        return {"bucket": self.bucket, "found": self.found, "reason": self.reason,
                "offset_px": num(self.offset_px), "sigma_px": num(self.sigma_px),
                "spread_px": num(self.spread_px), "n": self.n}


def _bucket_fit(bucket: str, r: np.ndarray) -> BucketOffset:
    n = int(r.size)
    spread = float(np.std(r, ddof=1)) if n > 1 else float("nan")
    sigma = spread / math.sqrt(n) if n > 1 else float("inf")
    return BucketOffset(bucket, True, "", float(np.mean(r)), sigma, spread, n)


@dataclass(frozen=True)
class OrientationOffsets:
    """Per-bucket disparity offsets (thesis §3.4 fix): fitted, looked up, applied per bucket.

    Build with :meth:`fit`. ``offsets`` maps bucket → :class:`BucketOffset`.

    Examples
    --------
    A folded module whose tele sags 1 px (tele pixels, ×3 zoom) when flipped: the flipped
    bucket reads 1/3 px less disparity than the landscape one.

    >>> d_true = np.full(6, 9.0)
    >>> fix = OrientationOffsets.fit(["landscape"] * 3 + ["landscape-flipped"] * 3,
    ...                              d_true + [0.0, 0.0, 0.0, -1/3, -1/3, -1/3], d_true)
    >>> round(fix.offset("landscape-flipped")[0], 4)
    -0.3333
    >>> fix.correct([8.6667], "landscape-flipped").round(4).tolist()
    [9.0]
    >>> fix.lookup("portrait").found
    False
    """

    offsets: dict[str, BucketOffset]

    @classmethod
    def fit(
        cls,
        buckets: Sequence[str] | np.ndarray,
        d_measured: Any,
        d_expected: Any,
        *,
        max_abs_residual_px: float | None = None,
    ) -> OrientationOffsets:
        """Fit one offset per bucket: mean(d_measured − d_expected) within each bucket.

        Parameters
        ----------
        buckets : sequence of str, length N
            Bucket of each sample (:func:`orientation_bucket` of its capture's gravity).
        d_measured, d_expected : array_like, shape (N,)
            Measured disparity and the disparity the sample should have (f·B/Z from a known
            depth, or the same point's disparity in a reference bucket), pixels. NaN samples
            are skipped.
        max_abs_residual_px : float, optional
            Samples whose residual is farther than this from the bucket's median are dropped
            (gross mismatches); default keeps all.

        Raises
        ------
        ShapeError
            Lengths differ.
        InputError
            A bucket name is not one of :data:`BUCKETS`.
        """
        b = np.asarray(buckets, dtype=object).reshape(-1)
        dm = np.asarray(d_measured, dtype=np.float64).reshape(-1)
        de = np.asarray(d_expected, dtype=np.float64).reshape(-1)
        if not (b.size == dm.size == de.size):
            raise ShapeError(
                f"buckets, d_measured and d_expected need one value per sample, got lengths "
                f"{b.size}, {dm.size}, {de.size}"
            )
        unknown = sorted({str(x) for x in b} - set(BUCKETS))
        if unknown:
            raise InputError(
                f"unknown bucket name(s) {unknown}; use orientation_bucket(gravity) "
                f"(one of {list(BUCKETS)})"
            )
        r = dm - de
        ok = np.isfinite(r)
        out: dict[str, BucketOffset] = {}
        for name in BUCKETS:  # six buckets, not samples
            rb = r[ok & (b == name)]
            if rb.size == 0:
                continue
            if max_abs_residual_px is not None:
                rb = rb[np.abs(rb - np.median(rb)) <= max_abs_residual_px]
            out[name] = _bucket_fit(name, rb)
        return cls(out)

    @property
    def buckets(self) -> tuple[str, ...]:
        """The buckets with a learned offset."""
        return tuple(self.offsets)

    def lookup(self, bucket: str) -> BucketOffset:
        """The bucket's offset, or a not-found result that says which buckets are known."""
        if bucket in self.offsets:
            return self.offsets[bucket]
        nan = float("nan")
        known = list(self.offsets) or "none"
        return BucketOffset(
            bucket, False, f"no offset learned in orientation {bucket!r} (known: {known})",
            nan, float("inf"), nan, 0,
        )

    def offset(self, bucket: str) -> tuple[float, float]:
        """(offset_px, sigma_px) of a bucket.

        Raises
        ------
        InputError
            Nothing was learned in this bucket (the message lists the known ones): the fix
            must not be applied across orientations (thesis §3.4).
        """
        got = self.lookup(bucket)
        if not got.found:
            raise InputError(
                f"{got.reason}; learn the fix in this orientation first (a fix is applied "
                "only within its orientation bucket, thesis §3.4)"
            )
        return got.offset_px, got.sigma_px

    def relative(self, reference: str) -> dict[str, tuple[float, float]]:
        """Offsets relative to a reference bucket: bucket → (Δoffset_px, sigma_px)."""
        o_ref, s_ref = self.offset(reference)
        return {
            k: (v.offset_px - o_ref, math.hypot(v.sigma_px, s_ref) if k != reference else 0.0)
            for k, v in self.offsets.items()
        }

    def correct(self, d: Any, bucket: str) -> np.ndarray:
        """d − offset(bucket): disparities (any shape) mapped to the expected ones, pixels."""
        o, _ = self.offset(bucket)
        return np.asarray(np.asarray(d, dtype=np.float64) - o)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: bucket → offset dict."""
        return {k: v.to_dict() for k, v in self.offsets.items()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> OrientationOffsets:
        """Rebuild from :meth:`to_dict`."""

        def num(v: Any, none: float) -> float:
            return none if v is None else float(v)

        return cls({
            k: BucketOffset(k, bool(v["found"]), str(v["reason"]),
                            num(v["offset_px"], float("nan")), num(v["sigma_px"], float("inf")),
                            num(v["spread_px"], float("nan")), int(v["n"]))
            for k, v in data.items()
        })


__all__ = [
    "BUCKETS",
    "BucketOffset",
    "OrientationOffsets",
    "capture_bucket",
    "orientation_bucket",
]
