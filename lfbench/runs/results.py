"""Results of a run: one record per (method, scene, metric), written as results.json and results.csv.

results.csv columns: method, scene, metric, value, resolution. results.json holds the same records
plus per (method, scene) run information: runtime in s, non-finite pixel count, alignment notes.
"""

from __future__ import annotations

import csv
import io
import json
import math
import platform
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from lfbench.utils.atomic import write_text
from lfbench.utils.errors import DataError

CSV_COLUMNS = ("method", "scene", "metric", "value", "resolution")


@dataclass(frozen=True)
class Record:
    """One number: ``value`` of ``metric`` for ``method`` on ``scene``, scored at ``resolution``."""

    method: str
    scene: str
    metric: str
    value: float
    resolution: str


@dataclass
class RunInfo:
    """How one method ran on one scene."""

    method: str
    scene: str
    runtime_s: float
    nonfinite_pixels: int = 0
    aligned_from: list[int] | None = None
    notes: list[str] = field(default_factory=list)


@dataclass
class Results:
    records: list[Record] = field(default_factory=list)
    runs: list[RunInfo] = field(default_factory=list)
    meta: dict[str, Any] = field(default_factory=dict)

    # ------------------------------------------------------------------ access
    @property
    def methods(self) -> list[str]:
        return list(dict.fromkeys(r.method for r in self.records))

    @property
    def scenes(self) -> list[str]:
        return list(dict.fromkeys(r.scene for r in self.records))

    @property
    def metrics(self) -> list[str]:
        return list(dict.fromkeys(r.metric for r in self.records))

    def value(self, method: str, scene: str, metric: str) -> float:
        for r in self.records:
            if (r.method, r.scene, r.metric) == (method, scene, metric):
                return r.value
        raise KeyError((method, scene, metric))

    def to_frame(self):
        """A pandas DataFrame with the CSV columns."""
        import pandas as pd

        return pd.DataFrame([asdict(r) for r in self.records], columns=list(CSV_COLUMNS))

    def extend(self, other: Results) -> None:
        self.records += other.records
        self.runs += other.runs

    # ------------------------------------------------------------------ files
    def to_json_dict(self) -> dict[str, Any]:
        meta = {"lfbench_version": _version(), "created": datetime.now(UTC).isoformat(timespec="seconds"),
                "python": platform.python_version(), **self.meta}
        return {"meta": meta, "records": [_clean(asdict(r)) for r in self.records],
                "runs": [_clean(asdict(r)) for r in self.runs]}

    def write(self, out_dir: str | Path) -> tuple[Path, Path]:
        """Write results.json and results.csv into ``out_dir`` (atomically)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_text(out / "results.json", json.dumps(self.to_json_dict(), indent=2) + "\n")
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(CSV_COLUMNS)
        for r in self.records:
            w.writerow([r.method, r.scene, r.metric, repr(float(r.value)), r.resolution])
        write_text(out / "results.csv", buf.getvalue())
        return out / "results.json", out / "results.csv"

    @classmethod
    def read(cls, path: str | Path) -> Results:
        """Read results.json (or a folder holding one), or a golden/records JSON list."""
        path = Path(path)
        if path.is_dir():
            path = path / "results.json"
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise DataError("results file not found", path) from None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DataError(f"not valid JSON: {exc}", path) from None
        raw = data if isinstance(data, list) else data.get("records") if isinstance(data, dict) else None
        if not isinstance(raw, list):
            raise DataError("expected a list of records or an object with 'records'", path)
        records = []
        for i, item in enumerate(raw):
            try:
                records.append(Record(str(item["method"]), str(item["scene"]), str(item["metric"]),
                                      _num(item["value"]), str(item.get("resolution", "lowres"))))
            except (KeyError, TypeError, ValueError) as exc:
                raise DataError(f"record {i} is malformed ({exc})", path) from None
        runs = []
        if isinstance(data, dict):
            for item in data.get("runs", []):
                runs.append(RunInfo(**{k: v for k, v in item.items() if k in RunInfo.__dataclass_fields__}))
        meta = data.get("meta", {}) if isinstance(data, dict) else {}
        return cls(records=records, runs=runs, meta=meta)


def _num(v: Any) -> float:
    return float("nan") if v is None else float(v)


def _clean(d: dict[str, Any]) -> dict[str, Any]:
    """JSON has no NaN: write null instead."""
    return {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in d.items()}


def _version() -> str:
    from lfbench import __version__

    return __version__
