"""User-facing errors: one clear line naming the file and the problem, exit code 2."""

from __future__ import annotations

import unicodedata
from pathlib import Path


class LFBenchError(Exception):
    """An error caused by the user's input (file, argument, spec); the CLI prints it on one line.

    ``path`` names the offending file or folder, when there is one.
    """

    exit_code = 2

    def __init__(self, message: str, path: str | Path | None = None) -> None:
        self.path = None if path is None else Path(path)
        super().__init__(message)

    def __reduce__(self):  # message and path survive a trip to a worker process and back
        return type(self), (self.args[0] if self.args else "", self.path)

    def __str__(self) -> str:
        msg = _visible(" ".join(super().__str__().split()))  # always a single line
        return f"{_visible(str(self.path))}: {msg}" if self.path is not None else msg


def _visible(text: str) -> str:
    """``text`` with control characters and line separators written as escapes (a file named
    'a\\nb' stays on the error's one line, and no terminal escape sequence is sent)."""
    return "".join(ch.encode("unicode_escape").decode("ascii") if unicodedata.category(ch) in ("Cc", "Zl", "Zp")
                   else ch for ch in text)


def exception_line(exc: BaseException, width: int = 160) -> str:
    """``TypeName: first line of the message`` of an exception a plugin's code raised, for one error line."""
    first = (str(exc).strip().splitlines() or [""])[0][:width]
    return f"{type(exc).__name__}: {first}" if first else type(exc).__name__


class Interrupted(LFBenchError):
    """Work stopped on request (SIGINT/SIGTERM) after saving what it had done: a stop, not an error; the
    same command resumes it. The CLI prints its message (``stopped at ...``) without ``error:``, exit code 130."""

    exit_code = 130


class RunFailed(LFBenchError):
    """The run stopped for a reason that is not its input (e.g. a worker process died: killed, or out of memory):
    nothing of it was written, the previous outputs are kept, and the same command can be run again. Exit code 1."""

    exit_code = 1


class DataError(LFBenchError):
    """A data file or folder is missing, malformed or inconsistent."""


class SpecError(LFBenchError):
    """A method spec, parameter or option is not valid."""


class PluginError(LFBenchError):
    """A plugin broke its contract with lfbench (e.g. a hook returned a value of the wrong kind): the line
    names the hook and the plugin. Exit code 1: the input was fine, the plugin's code is what to fix."""

    exit_code = 1
