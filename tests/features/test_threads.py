"""The two-thread split of the NCC search: same result as one thread, and safe after fork."""

from __future__ import annotations

import multiprocessing as mp

import cv2
import numpy as np
import pytest

from phonestereo.features import _threads
from phonestereo.features.search import ncc_search


def _pair(seed: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (160, 400)).astype(np.float32), (0, 0), 1.5)
    xy = np.stack([rng.integers(60, 380, 120), rng.integers(12, 148, 120)], axis=1)
    return img, np.roll(img, -9, axis=1), xy


def _search() -> np.ndarray:
    left, right, xy = _pair()
    s = ncc_search(left, right, xy, radius=7, min_d=0, max_d=40, row_tolerance=2, lr_min_score=0)
    return np.column_stack([s.d0, s.e0, s.score, s.second, s.lr_ok])


def test_split_search_equals_one_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    assert len(_pair()[2]) >= _threads.MIN_SPLIT  # the split path is taken
    split = _search()
    monkeypatch.setenv("PHONESTEREO_THREADS", "1")
    assert not _threads.split_enabled()
    single = _search()
    np.testing.assert_array_equal(split, single)  # bit for bit: disjoint writes
    assert np.nanmedian(split[:, 0]) == pytest.approx(9.0, abs=0.05)


def _child(q: mp.Queue) -> None:  # type: ignore[type-arg]
    q.put(float(np.nanmedian(_search()[:, 0])))


@pytest.mark.skipif("fork" not in mp.get_all_start_methods(), reason="no fork on this OS")
def test_split_search_works_in_a_forked_child() -> None:
    _search()  # the parent's pool thread exists now; the child inherits the object, not it
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_child, args=(q,))
    p.start()
    p.join(timeout=30)
    alive = p.is_alive()
    if alive:
        p.kill()
    assert not alive, "the forked child hung in the split search"
    assert q.get(timeout=5) == pytest.approx(9.0, abs=0.05)


@pytest.mark.parametrize("threads", ["", "1"])
def test_background_returns_the_value_or_raises(
    monkeypatch: pytest.MonkeyPatch, threads: str
) -> None:
    monkeypatch.setenv("PHONESTEREO_THREADS", threads)
    assert _threads.background(np.add, 2, 3).result() == 5
    fut = _threads.background(np.linalg.inv, np.zeros((2, 2)))
    with pytest.raises(np.linalg.LinAlgError):
        fut.result()


def test_matcher_result_does_not_depend_on_the_threads(monkeypatch: pytest.MonkeyPatch) -> None:
    from phonestereo.features.matching import match_rectified

    left, right, _ = _pair(1)
    two = match_rectified(left, right, max_disparity=24)
    monkeypatch.setenv("PHONESTEREO_THREADS", "1")
    one = match_rectified(left, right, max_disparity=24)
    assert len(two) == len(one) > 100
    for name in ("xy", "d", "e", "sigma_d"):
        np.testing.assert_array_equal(getattr(two, name), getattr(one, name))
