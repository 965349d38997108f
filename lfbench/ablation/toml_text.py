"""Writing a training config (nested dicts of plain values) as TOML text, so every ablation cell has a
config file that ``lfbench train CELL/train.toml --out CELL`` runs as is.

Only what TrainConfig.to_dict() holds is supported: strings, booleans, ints, floats, lists, dicts
(as tables, inline when inside a list) and lists of dicts (as arrays of tables). None values are left
out (TOML has no null; the config parser treats a missing key as its default).
``tomllib.loads(dumps(d)) == d`` without the None entries.
"""

from __future__ import annotations

import json
import math
import re
from typing import Any

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")


def _key(k: str) -> str:
    return k if _BARE_KEY.match(k) else json.dumps(k)


def _value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v, ensure_ascii=False)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v if x is not None) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(str(k))} = {_value(x)}" for k, x in v.items() if x is not None) + "}"
    raise TypeError(f"cannot write {type(v).__name__} {v!r} as TOML")


def _is_table(v: Any) -> bool:
    return isinstance(v, dict) and bool(v)


def _is_table_array(v: Any) -> bool:
    return isinstance(v, (list, tuple)) and bool(v) and all(isinstance(x, dict) for x in v)


def _emit(lines: list[str], path: list[str], table: dict[str, Any]) -> None:
    for k, v in table.items():
        if v is None or _is_table(v) or _is_table_array(v):
            continue
        lines.append(f"{_key(str(k))} = {_value(v)}")
    for k, v in table.items():
        if _is_table(v):
            sub = [*path, _key(str(k))]
            lines.append("")
            lines.append(f"[{'.'.join(sub)}]")
            _emit(lines, sub, v)
        elif _is_table_array(v):
            sub = [*path, _key(str(k))]
            for item in v:
                lines.append("")
                lines.append(f"[[{'.'.join(sub)}]]")
                _emit(lines, sub, item)


def dumps(data: dict[str, Any], header: str = "") -> str:
    """``data`` as TOML text; ``header`` lines are written first as comments."""
    lines = [f"# {line}" if line else "#" for line in header.splitlines()]
    _emit(lines, [], data)
    return "\n".join(lines).lstrip("\n") + "\n"
