"""The learning flow's landmark plumbing: the guided pair, its cache (no MediaPipe here)."""

from __future__ import annotations

from typing import Any

import numpy as np

from phonestereo.features.landmarks import Face, FaceResult, LandmarkBackend
from phonestereo.features.landmarks.base import make_result
from phonestereo.flows.learning import CachedBackend, PairBackend


def _face(x: float) -> Face:
    p = np.array([[x, 100.0], [x + 30.0, 100.0]])
    return Face(p, p, p, 0.0, 1.0, np.array([x - 20, 70, x + 50, 150]))


class Counting(LandmarkBackend):
    """Two faces at x = 100 and 600; counts whole-image searches and box measurements."""

    name = "counting"

    def __init__(self) -> None:
        self.searches = 0
        self.boxes: list[Any] = []

    def detect(self, image: Any) -> FaceResult:
        self.searches += 1
        return make_result([_face(100.0), _face(600.0)], (800, 300), self.name)

    def detect_in_boxes(self, image: Any, boxes: Any) -> FaceResult:
        self.boxes.append(list(boxes))
        return make_result([_face(b[0] + 20.0) for b in boxes], (800, 300), self.name)


class OnlyLeftInTele:
    """Maps a wide face to the tele when it lies left of x = 300 (a stand-in for the view)."""

    key = "left-only"

    def __call__(self, wide_face: Face) -> tuple[float, float, float, float] | None:
        x0, y0, x1, y1 = wide_face.box_px
        return None if x0 > 300 else (x0, y0, x1, y1)


def test_guided_pair_searches_the_wide_and_measures_the_tele_in_its_boxes() -> None:
    wide, tele = Counting(), Counting()
    img = np.zeros((300, 800), np.uint8)
    fw, ft = PairBackend(wide, tele).detect_pair(img, img, OnlyLeftInTele())
    assert (wide.searches, tele.searches) == (1, 0)
    assert len(fw.faces) == 2 and len(ft.faces) == 1  # the right face is outside the tele
    assert tele.boxes == [[(80.0, 70.0, 150.0, 150.0)]]
    # without a guide both are searched
    PairBackend(wide, tele).detect_pair(img, img)
    assert (wide.searches, tele.searches) == (2, 1)


def test_no_wide_face_in_the_tele_is_a_result_with_a_reason() -> None:
    class NoneMaps(OnlyLeftInTele):
        def __call__(self, wide_face: Face) -> None:
            return None

    img = np.zeros((300, 800), np.uint8)
    fw, ft = PairBackend(Counting(), Counting()).detect_pair(img, img, NoneMaps())
    assert fw.found and not ft.found and "no wide face" in ft.reason


def test_cache_keys_pairs_by_images_and_guide() -> None:
    wide, tele = Counting(), Counting()
    cache = CachedBackend(PairBackend(wide, tele))
    a = np.zeros((300, 800), np.uint8)
    b = np.ones((300, 800), np.uint8)
    first = cache.detect_pair(a, a, OnlyLeftInTele())
    assert cache.detect_pair(a, a, OnlyLeftInTele()) is first  # served from the cache
    assert wide.searches == 1
    cache.detect_pair(b, a, OnlyLeftInTele())  # other wide image
    cache.detect_pair(a, a)  # no guide: another entry
    assert wide.searches == 3
