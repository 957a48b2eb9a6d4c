"""The landmark backends of the learning flow: MediaPipe tuned for face charts, one backend
per camera, and a cache for ablations (measured in ``benchmarks/bench_flows.py``)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from typing import Any

import numpy as np

from phonestereo.features.landmarks import LandmarkBackend, MediaPipeBackend
from phonestereo.features.landmarks.base import FaceResult, TeleGuide, guided_pair


class CachedBackend(LandmarkBackend):
    """A landmark backend that remembers its answers per image content (for ablations that
    re-learn the same captures under other switches: landmarks do not depend on them)."""

    name = "cached"

    def __init__(self, backend: LandmarkBackend) -> None:
        self.backend = backend
        self._cache: dict[str, FaceResult] = {}
        self._pairs: dict[str, tuple[FaceResult, FaceResult]] = {}

    @staticmethod
    def _key(image: Any) -> str:
        a = np.ascontiguousarray(np.asarray(image))
        return f"{a.shape}{a.dtype}" + hashlib.blake2b(a.data, digest_size=16).hexdigest()

    def detect(self, image: Any) -> FaceResult:
        key = self._key(image)
        if key not in self._cache:
            self._cache[key] = self.backend.detect(image)
        return self._cache[key]

    def detect_many(self, images: Iterable[Any]) -> list[FaceResult]:
        return [self.detect(im) for im in images]

    def detect_pair(
        self, wide: Any, tele: Any, guide: TeleGuide | None = None
    ) -> tuple[FaceResult, FaceResult]:
        key = self._key(wide) + self._key(tele) + ("" if guide is None else guide.key)
        if key not in self._pairs:
            self._pairs[key] = self.backend.detect_pair(wide, tele, guide)
        return self._pairs[key]


class PairBackend(LandmarkBackend):
    """One backend for the wide image and another for the tele of a ``detect_many([wide,
    tele])`` or :meth:`detect_pair` call.

    With a guide (:class:`~phonestereo.learning.pair_guide.WideToTeleGuide`) the tele is
    not searched: it is measured only where the wide's faces map to.
    """

    name = "pair"

    def __init__(self, wide: LandmarkBackend, tele: LandmarkBackend) -> None:
        self.wide = wide
        self.tele = tele

    def detect(self, image: Any) -> FaceResult:
        return self.wide.detect(image)

    def detect_many(self, images: Iterable[Any]) -> list[FaceResult]:
        ims = list(images)
        if len(ims) != 2:
            return self.wide.detect_many(ims)
        return [self.wide.detect(ims[0]), self.tele.detect(ims[1])]

    def detect_pair(
        self, wide: Any, tele: Any, guide: TeleGuide | None = None
    ) -> tuple[FaceResult, FaceResult]:
        return guided_pair(self.wide, self.tele, wide, tele, guide)


def default_backend() -> LandmarkBackend:
    """MediaPipe for the learning flow (measured in ``benchmarks/bench_flows.py``).

    The wide is searched with two tile levels (13 detector runs instead of 42, the same faces
    found on the bench sets) and without mirror averaging (no loss of depth accuracy on the
    bench: the chart plane averages the faces' IPDs); the tele, guided by the wide's faces,
    is only measured. The tele's faces are three times larger and only pair the faces and
    start the disparity search (the eye windows refine it), so it needs no mirror averaging.
    The wide's detector sees its tiles shrunk to at most 1024 px by a whole factor (a 12 MP
    image's tiles as a 2000 × 1500 image's; the landmarks are measured at full resolution).
    """
    return PairBackend(
        MediaPipeBackend(mirror_average=False, two_level_tiles=(0.35, 0.08),
                         detector_max_px=1024),
        MediaPipeBackend(min_tile_px=1000, mirror_average=False),
    )


__all__ = ["CachedBackend", "PairBackend", "default_backend"]
