"""Logging for the command line. Library modules log through ``logging.getLogger(__name__)`` and never
print; the CLI installs one handler (:func:`configure_cli_logging`) that writes the messages as they
are to stderr, through tqdm so that progress bars stay intact."""

from __future__ import annotations

import contextlib
import logging
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import IO

__all__ = ["LOGGERS", "configure_cli_logging", "log_to_file"]

#: The loggers the CLI shows: the library and the bundled methods.
LOGGERS = ("lfbench", "lfbench_methods")


class _TqdmHandler(logging.Handler):
    """Writes each message through ``tqdm.write`` (progress bars are redrawn below) to ``stream``, or
    to whatever sys.stderr is when the message comes (None)."""

    def __init__(self, stream: IO[str] | None = None) -> None:
        super().__init__()
        self.stream = stream

    def emit(self, record: logging.LogRecord) -> None:
        try:
            from tqdm import tqdm

            stream = self.stream if self.stream is not None else sys.stderr
            tqdm.write(self.format(record), file=stream)
            stream.flush()
        except Exception:  # logging must never raise
            self.handleError(record)


def configure_cli_logging(verbosity: int = 0, stream: IO[str] | None = None) -> logging.Handler:
    """Show INFO and above on ``stream`` (default: sys.stderr as it is at each message); ``verbosity`` > 0 adds
    DEBUG, < 0 shows only warnings and errors. Replaces the handler of an earlier call (a process may
    run main() more than once, e.g. in tests)."""
    level = logging.DEBUG if verbosity > 0 else logging.WARNING if verbosity < 0 else logging.INFO
    handler = _TqdmHandler(stream)
    handler.setFormatter(logging.Formatter("%(message)s"))
    for name in LOGGERS:
        logger = logging.getLogger(name)
        for old in [h for h in logger.handlers if isinstance(h, _TqdmHandler)]:
            logger.removeHandler(old)
        logger.addHandler(handler)
        logger.setLevel(level)
    return handler


@contextlib.contextmanager
def log_to_file(path: str | Path, header: str | None = None, logger: str = "lfbench.training") -> Iterator[None]:
    """For the block, append the messages of ``logger`` and its children (INFO and above) to ``path``,
    one line each, and only there: they do not reach the console meanwhile (e.g. an ablation cell's
    training log). ``header``: a first line written before the block."""
    log = logging.getLogger(logger)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "a", encoding="utf-8") as stream:
        if header is not None:
            stream.write(header + "\n")
            stream.flush()
        handler = logging.StreamHandler(stream)
        handler.setFormatter(logging.Formatter("%(message)s"))
        level, propagate = log.level, log.propagate
        log.addHandler(handler)
        log.setLevel(logging.INFO)
        log.propagate = False
        try:
            yield
        finally:
            log.removeHandler(handler)
            log.setLevel(level)
            log.propagate = propagate
