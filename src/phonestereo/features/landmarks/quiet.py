"""Silence the native (C++) log lines of MediaPipe / TensorFlow Lite / absl unless asked for.

MediaPipe writes lines such as ``INFO: Created TensorFlow Lite XNNPACK delegate for CPU`` and
``W0000 ... inference_feedback_manager.cc:114] Feedback manager requires ...`` straight to file
descriptor 2 from its C++ threads while a graph is built and first run. Neither
``GLOG_minloglevel`` nor ``TF_CPP_MIN_LOG_LEVEL`` reaches them in MediaPipe 0.10.21 (both are
still set here, for the builds they do reach), so :func:`native_stderr_silenced` points fd 2 at
``/dev/null`` for the duration of a block while Python's own ``sys.stderr`` (warnings, Rich
progress bars, error messages) keeps writing to the real stderr through a duplicate descriptor.

Set ``PHONESTEREO_VERBOSE=1`` (the CLI's ``phonestereo --verbose``) to see the native lines.
"""

from __future__ import annotations

import contextlib
import io
import os
import sys
import threading
from collections.abc import Iterator

VERBOSE_ENV = "PHONESTEREO_VERBOSE"
_QUIET_ENV = {"GLOG_minloglevel": "2", "TF_CPP_MIN_LOG_LEVEL": "2"}

_lock = threading.Lock()
_depth = 0
_saved_fd: int | None = None
_saved_stderr: object = None


def verbose() -> bool:
    """True when the user asked for the native log lines (``PHONESTEREO_VERBOSE`` set, not 0)."""
    return os.environ.get(VERBOSE_ENV, "") not in ("", "0")


def quiet_env() -> None:
    """Set the log-level variables the native libraries read at import (unless verbose)."""
    if not verbose():
        for key, value in _QUIET_ENV.items():
            os.environ.setdefault(key, value)


def _redirect() -> None:
    global _saved_fd, _saved_stderr
    with contextlib.suppress(AttributeError, ValueError, OSError):
        sys.stderr.flush()
    _saved_fd = os.dup(2)
    null = os.open(os.devnull, os.O_WRONLY)
    os.dup2(null, 2)
    os.close(null)
    _saved_stderr = sys.stderr
    if _writes_to_fd2(sys.stderr):
        # Python-level writes keep reaching the terminal through the saved descriptor.
        sys.stderr = io.TextIOWrapper(
            os.fdopen(os.dup(_saved_fd), "wb", buffering=0),
            encoding=getattr(sys.stderr, "encoding", None) or "utf-8",
            errors="backslashreplace",
            line_buffering=True,
        )


def _restore() -> None:
    global _saved_fd, _saved_stderr
    if sys.stderr is not _saved_stderr:
        with contextlib.suppress(OSError, ValueError):
            sys.stderr.flush()
            sys.stderr.close()
        sys.stderr = _saved_stderr  # type: ignore[assignment]
    assert _saved_fd is not None
    os.dup2(_saved_fd, 2)
    os.close(_saved_fd)
    _saved_fd, _saved_stderr = None, None


def _writes_to_fd2(stream: object) -> bool:
    try:
        return stream.fileno() == 2  # type: ignore[attr-defined, no-any-return]
    except (AttributeError, ValueError, OSError, io.UnsupportedOperation):
        return False


@contextlib.contextmanager
def native_stderr_silenced() -> Iterator[None]:
    """Within the block, native writes to fd 2 are dropped (nothing happens when verbose).

    Re-entrant and thread-safe: the first block entered redirects, the last one left restores.

    >>> with native_stderr_silenced():
    ...     _ = os.write(2, b"dropped\\n")   # a native library's line: not shown
    """
    global _depth
    if verbose():
        yield
        return
    with _lock:
        if _depth == 0:
            _redirect()
        _depth += 1
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                _restore()
