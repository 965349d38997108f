"""Stopping a training run cleanly: SIGINT/SIGTERM set a flag (:class:`StopFlag`) read at the next step
boundary, where the trainer writes a checkpoint and raises :class:`TrainingInterrupted` (a stop, exit 130)."""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from typing import Any

from lfbench.utils.errors import Interrupted


class TrainingInterrupted(Interrupted):
    """Training stopped on SIGINT/SIGTERM after writing a checkpoint (resumable: a stop, exit 130)."""


class StopFlag:
    """Set by SIGINT/SIGTERM; training stops at the next step boundary (a second signal aborts)."""

    def __init__(self) -> None:
        self.set = False
        self._old: dict[int, Any] = {}

    def _handler(self, signum, frame):
        if self.set:
            raise KeyboardInterrupt
        self.set = True

    @contextlib.contextmanager
    def installed(self) -> Iterator[StopFlag]:
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self._old[sig] = signal.signal(sig, self._handler)
        try:
            yield self
        finally:
            for sig, old in self._old.items():
                signal.signal(sig, old)
            self._old.clear()


__all__ = ["StopFlag", "TrainingInterrupted"]
