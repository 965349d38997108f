"""Read a JSON file written by lfbench (results, golden records, markers) strictly, with one-line errors;
write JSON text strictly (:func:`json_text`: a non-finite number becomes ``null``).

Strict means: UTF-8, no duplicate object keys (Python's json keeps the last one silently), no
``NaN``/``Infinity`` literals (not JSON; lfbench writes ``null`` for a missing number) unless
asked for, integers within 64 bits (a 5000-digit one raises ValueError in Python's int, a 400-digit
one OverflowError wherever it meets a float), bounded size (read with a byte cap: a device such as
/dev/zero reports size 0 and never ends) and nesting depth (a deeply nested file raises
RecursionError in json).
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

from lfbench.utils.errors import DataError
from lfbench.utils.readfile import read_bytes

__all__ = ["MAX_JSON_BYTES", "MAX_JSON_DEPTH", "INT_RANGE", "json_text", "read_json", "parse_json"]

MAX_JSON_BYTES = 256 * 1024**2
MAX_JSON_DEPTH = 64
#: The integers a JSON file may hold: 64-bit, signed or unsigned.
INT_RANGE = (-(2**63), 2**64 - 1)


def read_json(path: str | Path, what: str = "JSON file", *, allow_nonfinite: bool = False) -> Any:
    """The parsed content of ``path``; DataError naming the file when it is missing, unreadable,
    larger than MAX_JSON_BYTES, not UTF-8, not valid JSON, nested deeper than MAX_JSON_DEPTH, has a
    duplicate key or (unless ``allow_nonfinite``) a NaN/Infinity literal. ``what`` names it in errors."""
    path = Path(path)
    raw = read_bytes(path, what, MAX_JSON_BYTES)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise DataError(f"{what} is not UTF-8 text", path) from None
    return parse_json(text, path, what, allow_nonfinite=allow_nonfinite)


def parse_json(text: str, path: str | Path | None = None, what: str = "JSON", *, allow_nonfinite: bool = False) -> Any:
    """Parse ``text`` with the rules of :func:`read_json`; ``path`` names the source in errors."""
    depth = _max_depth(text)
    if depth > MAX_JSON_DEPTH:
        raise DataError(f"{what} is nested {depth} levels deep (at most {MAX_JSON_DEPTH})", path)

    def constant(name: str) -> float:
        if not allow_nonfinite:
            raise _Refused(f"{name} is not a JSON number (write null for a missing value)")
        return float(name)

    def integer(text: str) -> int:
        digits = len(text.lstrip("-"))
        if digits > 20:  # never hand Python's int() thousands of digits
            raise _Refused(f"integer with {digits} digits (at most 64-bit integers)")
        value = int(text)
        if not INT_RANGE[0] <= value <= INT_RANGE[1]:
            raise _Refused(f"integer {value} is outside the 64-bit range")
        return value

    def pairs(items: list[tuple[str, Any]]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in items:
            if key in out:
                raise _Refused(f"duplicate key {key!r}")
            out[key] = value
        return out

    try:
        return json.loads(text, object_pairs_hook=pairs, parse_constant=constant, parse_int=integer)
    except _Refused as exc:
        raise DataError(f"{what}: {exc}", path) from None
    except json.JSONDecodeError as exc:
        raise DataError(f"{what} is not valid JSON: {exc}", path) from None
    except RecursionError:  # pragma: no cover - the depth check comes first
        raise DataError(f"{what} is nested too deeply", path) from None
    except ValueError as exc:  # pragma: no cover - json's own limits (the hooks refuse first)
        raise DataError(f"{what} is not valid JSON: {' '.join(str(exc).split())[:120]}", path) from None


def json_text(obj: Any, *, indent: int | None = None, sort_keys: bool = False) -> str:
    """``obj`` as strict JSON text (what every JSON file lfbench writes holds): NaN and +-inf, which JSON
    has no literal for (Python would write ``NaN``), are written as ``null``, in dicts, lists and tuples at
    any depth; anything else as :func:`json.dumps` writes it."""
    return json.dumps(_finite_or_null(obj), indent=indent, sort_keys=sort_keys, allow_nan=False)


def _finite_or_null(obj: Any) -> Any:
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite_or_null(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_finite_or_null(v) for v in obj]
    return obj


class _Refused(ValueError):
    """Raised inside the json hooks; becomes a DataError naming the file."""


_STRING = re.compile(r'"(?:[^"\\]|\\.)*"', re.DOTALL)
_BRACKET = re.compile(r"[\[\]{}]")


def _max_depth(text: str) -> int:
    """Deepest nesting of [ and { outside strings (a scan, no recursion)."""
    depth = deepest = 0
    for m in _BRACKET.finditer(_STRING.sub("", text)):
        if m.group() in "[{":
            depth += 1
            deepest = max(deepest, depth)
        else:
            depth -= 1
    return deepest
