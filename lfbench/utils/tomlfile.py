"""Read a TOML file for a config or spec, with one-line errors naming the file."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from lfbench.utils.errors import SpecError


def read_toml(path: str | Path, what: str) -> tuple[dict[str, Any], str]:
    """(parsed table, text) of the TOML file ``path``; ``what`` names it in errors (e.g. "config").
    Raises SpecError when it is missing, unreadable or not valid TOML."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise SpecError(f"{what} not found", path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise SpecError(f"cannot read {what}: {exc}", path) from None
    try:
        return tomllib.loads(text), text
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"invalid TOML: {exc}", path) from None
