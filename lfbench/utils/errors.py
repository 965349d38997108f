"""User-facing errors: one clear line naming the file and the problem, exit code 2."""

from __future__ import annotations

from pathlib import Path


class LFBenchError(Exception):
    """An error caused by the user's input (file, argument, spec); the CLI prints it on one line.

    ``path`` names the offending file or folder, when there is one.
    """

    exit_code = 2

    def __init__(self, message: str, path: str | Path | None = None) -> None:
        self.path = None if path is None else Path(path)
        super().__init__(message)

    def __str__(self) -> str:
        msg = " ".join(super().__str__().split())  # always a single line
        return f"{self.path}: {msg}" if self.path is not None else msg


class DataError(LFBenchError):
    """A data file or folder is missing, malformed or inconsistent."""


class SpecError(LFBenchError):
    """A method spec, parameter or option is not valid."""
