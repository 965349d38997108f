"""Read a TOML file for a config or spec, with one-line errors naming the file; write one (tomli-w).

The one TOML reader of lfbench: the file is read with a byte cap (lfbench.utils.readfile: no device,
FIFO or endless file), and what it holds is bounded before anyone uses it: nesting at most
MAX_TOML_DEPTH levels (tomllib recurses per level; deeper tables break json.dumps and deepcopy later)
and integers within TOML's own 64-bit range (tomllib accepts any length: a 400-digit integer breaks
float() and torch later, a 5000-digit one Python's int() itself).
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

import tomli_w

from lfbench.utils.errors import SpecError
from lfbench.utils.readfile import read_text

__all__ = ["MAX_TOML_BYTES", "MAX_TOML_DEPTH", "TOML_INT_RANGE", "read_toml", "check_toml_values", "toml_text"]

MAX_TOML_BYTES = 16 * 1024**2
MAX_TOML_DEPTH = 32
#: TOML's integers: "arbitrary 64-bit signed integers", and an error for any it cannot hold.
TOML_INT_RANGE = (-(2**63), 2**63 - 1)


def read_toml(path: str | Path, what: str) -> tuple[dict[str, Any], str]:
    """(parsed table, text) of the TOML file ``path``; ``what`` names it in errors (e.g. "config").
    Raises SpecError when it is missing, not a regular file, larger than MAX_TOML_BYTES, not UTF-8,
    not valid TOML, nested deeper than MAX_TOML_DEPTH or holds an integer outside 64 bits."""
    path = Path(path)
    text = read_text(path, what, MAX_TOML_BYTES, error=SpecError)
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError(f"invalid TOML: {exc}", path) from None
    except RecursionError:
        raise SpecError(f"invalid TOML: nested more than {MAX_TOML_DEPTH} levels deep", path) from None
    except ValueError:  # Python's int() refused thousands of digits
        raise SpecError("invalid TOML: an integer with thousands of digits (TOML integers are 64-bit)",
                        path) from None
    check_toml_values(table, path)
    return table, text


def check_toml_values(table: dict[str, Any], path: str | Path | None = None) -> None:
    """SpecError naming ``path`` and the key when ``table`` nests deeper than MAX_TOML_DEPTH or holds an
    integer outside TOML_INT_RANGE (an iterative walk: no recursion)."""
    stack: list[tuple[Any, str, int]] = [(table, "", 0)]
    while stack:
        value, key, depth = stack.pop()
        if isinstance(value, dict | list):
            if depth > MAX_TOML_DEPTH:
                raise SpecError(f"invalid TOML: {key or 'a value'} is nested more than {MAX_TOML_DEPTH} levels deep",
                                path)
            items = value.items() if isinstance(value, dict) else enumerate(value, 1)
            stack += [(v, f"{key}.{k}" if key else str(k), depth + 1) for k, v in items]
        elif isinstance(value, int) and not isinstance(value, bool):
            if not TOML_INT_RANGE[0] <= value <= TOML_INT_RANGE[1]:
                digits = len(str(abs(value)))
                raise SpecError(f"{key[:80]}: integer of {digits} digits is outside TOML's 64-bit range "
                                f"({TOML_INT_RANGE[0]} to {TOML_INT_RANGE[1]})", path)


def toml_text(data: dict[str, Any], header: str = "") -> str:
    """``data`` (plain values: str, bool, int, float, lists, dicts) as TOML text, written by tomli-w, with the
    ``header`` lines first as comments. None values are left out (TOML has no null; a config reader takes an
    absent key as its default): ``tomllib.loads(toml_text(d))`` is ``d`` without them."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    body = tomli_w.dumps(_without_none(data))
    return "\n".join(lines) + ("\n" if lines else "") + body


def _without_none(x: Any) -> Any:
    if isinstance(x, dict):
        return {k: _without_none(v) for k, v in x.items() if v is not None}
    if isinstance(x, (list, tuple)):
        return [_without_none(v) for v in x if v is not None]
    return x
