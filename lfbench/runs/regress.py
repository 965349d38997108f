"""Metric regression checks: compare new results with golden records, each with its own tolerance.

Golden file: a JSON list of records {method, scene, metric, value, tolerance, resolution}. A check
fails when a metric worsens by more than its tolerance (in the metric's own units; lower is better
for every benchmark metric unless the metric says otherwise), when a golden (method, scene, metric)
is missing from the new results, or when its resolution changed. Improvements beyond the tolerance
are reported (so the golden file can be refreshed) but do not fail.
"""

from __future__ import annotations

import fnmatch
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from lfbench.runs.results import Results
from lfbench.utils.atomic import write_text
from lfbench.utils.errors import DataError

HIGHER_IS_BETTER: frozenset[str] = frozenset()


@dataclass(frozen=True)
class GoldenRecord:
    method: str
    scene: str
    metric: str
    value: float
    tolerance: float
    resolution: str

    @property
    def key(self) -> tuple[str, str, str]:
        return self.method, self.scene, self.metric


@dataclass(frozen=True)
class Finding:
    """One line of the regression report; ``failed`` decides the exit code."""

    kind: str  # "worse", "missing", "resolution", "nan", "better"
    key: tuple[str, str, str]
    message: str

    @property
    def failed(self) -> bool:
        return self.kind != "better"


def read_golden(path: str | Path) -> list[GoldenRecord]:
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DataError("golden file not found", path) from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise DataError(f"not valid JSON: {exc}", path) from None
    items = data.get("records") if isinstance(data, dict) else data
    if not isinstance(items, list):
        raise DataError("expected a JSON list of golden records", path)
    out = []
    for i, item in enumerate(items):
        try:
            rec = GoldenRecord(str(item["method"]), str(item["scene"]), str(item["metric"]), float(item["value"]),
                               float(item["tolerance"]), str(item["resolution"]))
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(f"golden record {i} is malformed (needs method, scene, metric, value, tolerance, "
                            f"resolution): {exc}", path) from None
        if rec.tolerance < 0 or not math.isfinite(rec.tolerance):
            raise DataError(f"golden record {i}: tolerance must be a finite number >= 0", path)
        out.append(rec)
    return out


def compare(golden: list[GoldenRecord], new: Results, skip_absent_scenes: bool = False) -> list[Finding]:
    """All findings of ``new`` against ``golden``, failures first in golden order.

    ``skip_absent_scenes``: golden records of scenes that no new record mentions are left out (e.g.
    real-data scenes on a machine without the data); a method or metric missing on a scene that
    was evaluated still fails.
    """
    current = {(r.method, r.scene, r.metric): r for r in new.records}
    scenes = {r.scene for r in new.records}
    findings: list[Finding] = []
    for g in golden:
        name = "/".join(g.key)
        if skip_absent_scenes and g.scene not in scenes:
            continue
        r = current.get(g.key)
        if r is None:
            findings.append(Finding("missing", g.key,
                                    f"MISSING  {name}: in golden ({g.value:.6g}) but not in the new results"))
            continue
        if r.resolution != g.resolution:
            findings.append(Finding("resolution", g.key,
                                    f"CHANGED  {name}: scored at {r.resolution}, golden at {g.resolution}"))
            continue
        if not math.isfinite(r.value):
            findings.append(Finding("nan", g.key, f"INVALID  {name}: new value is {r.value}"))
            continue
        sign = -1.0 if g.metric in HIGHER_IS_BETTER else 1.0
        change = sign * (r.value - g.value)  # > 0 means worse
        detail = f"{name}: {g.value:.6g} -> {r.value:.6g} ({r.value - g.value:+.3g}, tolerance {g.tolerance:g})"
        if change > g.tolerance:
            findings.append(Finding("worse", g.key, f"WORSE    {detail}"))
        elif change < -g.tolerance:
            findings.append(Finding("better", g.key, f"better   {detail}"))
    findings.sort(key=lambda f: not f.failed)
    return findings


def tolerance_for(method: str, metric: str, tolerance: float | Mapping[str, float]) -> float:
    """The tolerance of one record: ``tolerance`` is one number, or a dict whose keys are glob patterns
    of ``METHOD/METRIC`` (e.g. ``'published*/*'``, tried first, in order) or of the metric id alone
    (``'mse_x100'``, ``'*'``); no match gives 0."""
    if not isinstance(tolerance, Mapping):
        return float(tolerance)
    for key, value in tolerance.items():
        if "/" in key and fnmatch.fnmatchcase(f"{method}/{metric}", key):
            return float(value)
    if metric in tolerance:
        return float(tolerance[metric])
    for key, value in tolerance.items():
        if "/" not in key and fnmatch.fnmatchcase(metric, key):
            return float(value)
    return 0.0


def make_golden(results: Results, tolerance: float | Mapping[str, float], path: str | Path) -> int:
    """Write results as golden records; ``tolerance`` as in :func:`tolerance_for`."""
    records = [{"method": r.method, "scene": r.scene, "metric": r.metric, "value": r.value,
                "tolerance": tolerance_for(r.method, r.metric, tolerance), "resolution": r.resolution}
               for r in results.records if math.isfinite(r.value)]
    write_text(path, json.dumps(records, indent=1) + "\n")
    return len(records)
