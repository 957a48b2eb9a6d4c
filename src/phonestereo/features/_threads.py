"""Two-way split of per-keypoint loops whose work is OpenCV calls (they release the GIL).

The sparse matcher's NCC search is a Python loop of one small ``cv2.matchTemplate`` per
keypoint (~18 µs each, most of it inside OpenCV with the GIL released). With the second of the
machine's two cores taking half of the keypoints, the search runs ~1.7× faster; a Dask or
process pool scale-out that already fills the cores turns it off with ``PHONESTEREO_THREADS=1``.
Hand-written (a dozen lines over ``concurrent.futures``) because the pool must not survive a
``fork``: a child inherits the executor object but not its thread, and would wait forever.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from typing import Any, TypeVar

__all__ = ["ahead", "background", "run_split", "split_enabled"]

T = TypeVar("T")

#: Below this many items one thread does it all (the hand-over costs ~50 µs).
MIN_SPLIT = 48

_PREFIX = "phonestereo-split"
_AHEAD = "phonestereo-ahead"
#: thread-name prefix → (pid that made it, its single-thread pool)
_pools: dict[str, tuple[int, ThreadPoolExecutor]] = {}


def split_enabled() -> bool:
    """Whether a second thread is used: ≥ 2 usable cores and ``PHONESTEREO_THREADS`` ≠ 1."""
    if os.environ.get("PHONESTEREO_THREADS", "").strip() == "1":
        return False
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return cores >= 2


def _on_helper() -> bool:
    """True on the helper thread itself: it must not wait on its own queue (it would hang)."""
    return threading.current_thread().name.startswith(_PREFIX)


def _executor(prefix: str = _PREFIX) -> ThreadPoolExecutor:
    """This process's single-thread pool named ``prefix`` (the helper's by default)."""
    pid = os.getpid()
    made = _pools.get(prefix)
    if made is None or made[0] != pid:  # first use, or a new process (fork): a fresh thread
        made = (pid, ThreadPoolExecutor(max_workers=1, thread_name_prefix=prefix))
        _pools[prefix] = made
    return made[1]


def run_split(
    fn: Callable[[Sequence[T]], None], items: Sequence[T], min_items: int = MIN_SPLIT
) -> None:
    """Run ``fn(items[:half])`` here and ``fn(items[half:])`` on a helper thread, and wait.

    ``fn`` must write disjoint outputs for disjoint items (so the result does not depend on
    the split); an exception in either half is raised here. Fewer than ``min_items`` items
    run here (lower it for items that take ≳ 0.2 ms each).
    """
    if len(items) < min_items or not split_enabled() or _on_helper():
        fn(items)
        return
    half = len(items) // 2
    other = _executor().submit(fn, items[half:])
    try:
        fn(items[:half])
    finally:
        other.result()


def background(fn: Callable[..., T], *args: Any) -> Future[T]:
    """``fn(*args)`` started on the helper thread (or run here, done, when the split is off).

    For independent work on the other image of a pair while this thread does its own; take
    the value with ``.result()`` (which raises what ``fn`` raised).
    """
    if split_enabled() and not _on_helper():
        return _executor().submit(fn, *args)
    done: Future[T] = Future()
    try:
        done.set_result(fn(*args))
    except Exception as exc:  # handed to .result(), as the executor does
        done.set_exception(exc)
    return done


def ahead(fn: Callable[..., T], *args: Any) -> Future[T]:
    """``fn(*args)`` started on a thread of its own (not the helper: its :func:`background`
    and :func:`run_split` work still goes to the helper, so it uses both cores once they are
    free), or run here, done, when the split is off.

    For a long job that does not depend on what this thread does next while that leaves a core
    idle (the learning flow's W-T scale measurement during MediaPipe's landmarks, whose graph
    computes on its own threads). On the helper itself the job would keep the helper from the
    work this thread hands it afterwards and run its own helper work in line (at 4000 × 3000
    the learning's landmark disparity then waited for the whole measurement).
    """
    if not split_enabled() or _on_helper():
        return background(fn, *args)
    return _executor(_AHEAD).submit(fn, *args)
