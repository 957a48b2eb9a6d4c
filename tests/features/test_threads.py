"""The two-thread split of the NCC search: same result as one thread, and safe after fork."""

from __future__ import annotations

import multiprocessing as mp
import threading

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


def test_refine_lk_halves_equal_fitting_each_half_alone(monkeypatch: pytest.MonkeyPatch) -> None:
    from phonestereo.features.subpixel import SPLIT_AT, bspline_coefficients, refine_lk

    left, right, _ = _pair(2)
    rng = np.random.default_rng(3)
    xy = np.stack([rng.integers(40, 360, 2 * SPLIT_AT), rng.integers(20, 140, 2 * SPLIT_AT)], 1)
    coef = bspline_coefficients(right)
    d0, e0 = np.full(len(xy), 9.0), np.zeros(len(xy))
    whole = refine_lk(left, None, coef, xy, d0, e0)
    k = len(xy) // 2  # the split refine_lk makes: the same numbers as two separate calls
    halves = [refine_lk(left, None, coef, xy[s], d0[s], e0[s]) for s in (slice(0, k),
                                                                          slice(k, None))]
    monkeypatch.setenv("PHONESTEREO_THREADS", "1")
    one = refine_lk(left, None, coef, xy, d0, e0)
    assert whole.converged.sum() > 0.9 * len(xy)
    assert np.median(whole.d[whole.converged]) == pytest.approx(9.0, abs=0.01)
    for name in ("d", "e", "zncc", "cov_unit", "iterations"):  # bit for bit
        np.testing.assert_array_equal(getattr(whole, name), getattr(one, name))
        np.testing.assert_array_equal(
            getattr(whole, name), np.concatenate([getattr(h, name) for h in halves])
        )


def test_background_on_the_helper_thread_runs_inline() -> None:
    # refine_lk may be reached from work already on the helper thread: waiting on its own
    # queue would hang, so it runs there directly.
    inner = _threads.background(lambda: _threads.background(np.add, 1, 2).result())
    assert inner.result(timeout=10) == 3


@pytest.mark.parametrize("threads", ["", "1"])
def test_ahead_runs_apart_and_hands_its_own_work_to_the_helper(
    monkeypatch: pytest.MonkeyPatch, threads: str
) -> None:
    monkeypatch.setenv("PHONESTEREO_THREADS", threads)

    def job() -> tuple[str, str]:
        inner = _threads.background(lambda: threading.current_thread().name)
        return threading.current_thread().name, inner.result(timeout=10)

    mine, helper = _threads.ahead(job).result(timeout=10)
    if not _threads.split_enabled():  # no second core (or turned off): all here
        assert mine == helper == threading.current_thread().name
    else:
        assert mine.startswith("phonestereo-ahead") and helper.startswith("phonestereo-split")
    with pytest.raises(np.linalg.LinAlgError):
        _threads.ahead(np.linalg.inv, np.zeros((2, 2))).result(timeout=10)
