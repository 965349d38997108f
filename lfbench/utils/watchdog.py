"""A time bound on a call into a plugin's code (a network's constructor, its forward): :func:`time_limit`.

The bound is a real-time timer (``SIGALRM``) in the main thread: when it fires, :class:`TimeLimitExceeded` is
raised where the plugin's Python code is running (a ``while True`` loop, a ``time.sleep``). It derives from
BaseException, so a plugin's ``except Exception`` cannot swallow it. One long call into C (one huge tensor
operation) is interrupted when it returns. Where there is no SIGALRM (Windows) or the caller is not the main
thread, the call runs unbounded.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator

__all__ = ["TimeLimitExceeded", "time_limit"]


class TimeLimitExceeded(BaseException):  # noqa: N818 - named for what happened, as TimeoutError is
    """The bounded call ran past its time."""


def _can_bound() -> bool:
    return hasattr(signal, "SIGALRM") and threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def time_limit(seconds: float | None) -> Iterator[None]:
    """Raise :class:`TimeLimitExceeded` inside the block once it has run ``seconds`` (None: no bound). The
    previous SIGALRM handler and timer are restored on the way out."""
    if seconds is None or not _can_bound():
        yield
        return

    def expire(signum, frame):  # noqa: ARG001 - the signal handler's signature
        raise TimeLimitExceeded(f"ran past {seconds:g} s")

    previous = signal.signal(signal.SIGALRM, expire)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)
