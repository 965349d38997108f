"""``~`` and ``$VAR`` / ``${VAR}`` in paths of config files and specs, expanded strictly."""

from __future__ import annotations

import os
import re
from pathlib import Path

from lfbench.utils.errors import SpecError

__all__ = ["expand_vars"]

_VAR_RE = re.compile(r"\$\{(\w+)\}|\$(\w+)")


def expand_vars(value: str, source: str | Path | None = None, key: str | None = None) -> str:
    """``value`` with ``~`` and every ``$VAR`` / ``${VAR}`` expanded. An unset variable is a SpecError
    naming ``source`` (the file) and ``key`` (the setting), never silently left in the path."""
    def sub(m: re.Match) -> str:
        name = m.group(1) or m.group(2)
        if name not in os.environ:
            what = f"{key}: {value!r}" if key else f"path {value!r}"
            raise SpecError(f"{what} uses environment variable {name}, which is not set", source)
        return os.environ[name]

    return os.path.expanduser(_VAR_RE.sub(sub, value))
