"""Metric regression checks: compare new results with golden records, each with its own tolerance.

Golden file: a JSON list of records {method, scene, metric, value, tolerance, resolution}. A check
fails when a metric worsens by more than its tolerance (in the metric's own units; lower is better
for every benchmark metric unless the metric says otherwise), when a golden (method, scene, metric)
is missing from the new results, when its resolution changed or when the new value is not finite or
outside the metric's range. Improvements beyond the tolerance and new records absent from the golden
file are reported (so the golden file can be refreshed) but do not fail (new records fail on request).
Golden files are validated before any comparison: a NaN golden value would otherwise pass every
check, and so would a tolerance as wide as the metric's range (``Metric.value_range``: a 0-100 %
metric cannot take a tolerance of 100 or more).

A gate that compared nothing does not pass (:class:`GateResult`): an empty golden file, or one whose
every scene is absent from the new results under ``skip_absent_scenes``, fails unless
``allow_empty`` says comparing nothing is intended; the summary says how many golden records were
compared and how many were skipped, and why.
"""

from __future__ import annotations

import fnmatch
import json
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

from lfbench.data.scene import HIGHRES, LOWRES
from lfbench.results import Results, check_unique
from lfbench.scoring.metrics import METRICS, Metric
from lfbench.utils.atomic import write_text
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.jsonfile import read_json

RESOLUTIONS = (LOWRES, HIGHRES)
TOLERANCE_RULE = "tolerance must be a finite number >= 0"


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

    kind: str  # "worse", "missing", "resolution", "nan", "new", "better"
    key: tuple[str, str, str]
    message: str
    failed: bool = True


@dataclass(frozen=True)
class GateResult:
    """The outcome of :func:`check`: the findings, how many golden records were compared (a missing
    record counts: it was looked for), which were skipped and why, and whether the gate passes."""

    findings: list[Finding]
    golden: int
    compared: int
    skipped_scenes: tuple[str, ...] = ()  # scenes absent from the new results (skip_absent_scenes)
    allow_empty: bool = False

    @property
    def failures(self) -> list[Finding]:
        return [f for f in self.findings if f.failed]

    @property
    def skipped(self) -> int:
        return self.golden - self.compared

    @property
    def compared_nothing(self) -> bool:
        return self.compared == 0

    @property
    def passed(self) -> bool:
        """No failure, and something was compared (or ``allow_empty``)."""
        return not self.failures and (self.compared > 0 or self.allow_empty)

    def summary(self) -> str:
        """One line: OK/FAIL, records compared, regressions, improvements, new records, what was skipped
        and why, and why a gate that compared nothing failed."""
        better = sum(f.kind == "better" for f in self.findings)
        new = sum(f.kind == "new" for f in self.findings)
        text = (f"{'OK' if self.passed else 'FAIL'}: {self.compared} compared, {len(self.failures)} regressions, "
                f"{better} improved beyond tolerance"
                + (f", {new} new records not in the golden file" if new else ""))
        if self.skipped:
            text += f"; {self.skipped} skipped: scene absent from the new results ({', '.join(self.skipped_scenes)})"
        if self.compared_nothing:
            why = "the golden file holds no records" if not self.golden else "every golden record was skipped"
            text += (f" -- nothing was compared ({why}): intended with --allow-empty" if self.allow_empty
                     else f" -- nothing was compared ({why}), so the gate cannot pass (--allow-empty if intended)")
        return text


    def stale_hint(self, golden: str | Path = "GOLDEN", new: str | Path = "NEW", *, shown: int = 5) -> str | None:
        """One line when the gate passed and some new values are better than golden by more than their
        tolerance: the golden file is stale (it would let those records fall back unnoticed). Names the
        first ``shown`` records and the command that refreshes it; None otherwise."""
        better = ["/".join(f.key) for f in self.findings if f.kind == "better"]
        if not better or not self.passed:
            return None
        names = ", ".join(better[:shown]) + (f" and {len(better) - shown} more" if len(better) > shown else "")
        return (f"hint: the golden file is stale: {len(better)} record{'s' if len(better) != 1 else ''} better than "
                f"golden by more than the tolerance ({names}); if the improvement is meant, refresh it with "
                f"`lfbench regress {golden} {new} --update`")


def read_golden(path: str | Path) -> list[GoldenRecord]:
    """Golden records of ``path``, validated: every value and tolerance a finite JSON number (no NaN,
    Infinity or "NaN" strings), tolerance >= 0, a known metric id, resolution lowres/highres, no
    duplicate keys or records. DataError naming the file and the record otherwise."""
    path = Path(path)
    data = read_json(path, "golden file")
    items = data.get("records") if isinstance(data, dict) else data
    if not isinstance(items, list):
        raise DataError("expected a JSON list of golden records", path)
    out: list[GoldenRecord] = []
    seen: set[tuple[str, str, str]] = set()
    for i, item in enumerate(items):
        try:
            if not isinstance(item, dict):
                raise TypeError("not an object")
            names = [item[k] for k in ("method", "scene", "metric", "resolution")]
            if not all(isinstance(v, str) and v for v in names):
                raise TypeError("method, scene, metric and resolution must be non-empty strings")
            value, tolerance = _number(item["value"], "value"), _number(item["tolerance"], "tolerance")
        except (KeyError, TypeError, ValueError) as exc:
            raise DataError(f"golden record {i} is malformed (needs method, scene, metric, value, tolerance, "
                            f"resolution): {exc}", path) from None
        rec = GoldenRecord(names[0], names[1], names[2], value, tolerance, names[3])
        where = f"golden record {i} ({'/'.join(rec.key)})"
        if not math.isfinite(rec.value):
            raise DataError(f"{where}: value must be a finite number, got {rec.value}", path)
        if not _is_tolerance(rec.tolerance):
            raise DataError(f"{where}: {TOLERANCE_RULE}", path)
        metric = METRICS.find(rec.metric)
        if metric is None:
            raise DataError(f"{where}: unknown metric {rec.metric!r}", path)
        problem = _out_of_range(metric, rec.value) or _tolerance_too_wide(metric, rec.tolerance)
        if problem:
            raise DataError(f"{where}: {problem}", path)
        if rec.resolution not in RESOLUTIONS:
            raise DataError(f"{where}: resolution must be one of {', '.join(RESOLUTIONS)}", path)
        if rec.key in seen:
            raise DataError(f"{where}: duplicate record", path)
        seen.add(rec.key)
        out.append(rec)
    return out


def _is_tolerance(v: object) -> bool:
    """A tolerance is a finite number >= 0 (a negative one fails every check, an infinite one passes
    every check); booleans and strings are not numbers."""
    return not isinstance(v, bool) and isinstance(v, int | float) and math.isfinite(v) and v >= 0


def _number(v: object, name: str) -> float:
    """A JSON number (not a bool or a string such as "NaN") as float."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise TypeError(f"{name} must be a JSON number, got {type(v).__name__} {v!r}"[:120])
    return float(v)


def _range_text(metric: Metric) -> str:
    low, high = metric.value_range
    return f"{low:g} to {high:g} {metric.unit}"


def _invalid(metric: Metric | None, value: float) -> str | None:
    """Why a new ``value`` of ``metric`` (None: an id lfbench does not know) cannot be a value: not finite, or
    outside the metric's range; None when it can."""
    if not math.isfinite(value):
        return f"value is {value}"
    return _out_of_range(metric, value) if metric is not None else None


def _out_of_range(metric: Metric, value: float) -> str | None:
    """Why ``value`` cannot be a value of ``metric`` (outside its declared range), or None."""
    low, high = metric.value_range
    if low <= value <= high:
        return None
    return f"value {value:.6g} is outside the range of {metric.id} ({_range_text(metric)})"


def _tolerance_too_wide(metric: Metric, tolerance: float) -> str | None:
    """Why ``tolerance`` cannot guard ``metric`` (as wide as its range: every value would pass), or None."""
    if tolerance < metric.span:
        return None
    return (f"tolerance {tolerance:g} is as wide as the range of {metric.id} ({_range_text(metric)}): every value "
            "would pass")


def compare(golden: list[GoldenRecord], new: Results, skip_absent_scenes: bool = False,
            fail_on_new: bool = False) -> list[Finding]:
    """All findings of ``new`` against ``golden``, failures first in golden order (:func:`check`'s findings)."""
    return check(golden, new, skip_absent_scenes=skip_absent_scenes, fail_on_new=fail_on_new).findings


def check(golden: list[GoldenRecord], new: Results, *, skip_absent_scenes: bool = False, fail_on_new: bool = False,
          allow_empty: bool = False) -> GateResult:
    """``new`` against ``golden``: the findings (failures first, in golden order) and what was compared.

    ``skip_absent_scenes``: golden records of scenes that no new record mentions are left out (e.g.
    real-data scenes on a machine without the data) and counted as skipped; a method or metric missing
    on a scene that was evaluated still fails. New records absent from the golden file are reported
    ("NEW"), and fail only with ``fail_on_new``. A non-finite new value, or one outside the metric's
    range, always fails. The gate does not pass when it compared nothing, unless ``allow_empty``.
    """
    current = {(r.method, r.scene, r.metric): r for r in new.records}
    scenes = {r.scene for r in new.records}
    findings: list[Finding] = []
    skipped: dict[str, None] = {}
    for g in golden:
        name = "/".join(g.key)
        if skip_absent_scenes and g.scene not in scenes:
            skipped[g.scene] = None
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
        metric = METRICS.find(g.metric)  # known: read_golden refuses unknown ids
        why = _invalid(metric, r.value)
        if why:
            findings.append(Finding("nan", g.key, f"INVALID  {name}: new {why}"))
            continue
        badness = (metric or Metric.undefined(g.metric)).badness  # a signed metric: its magnitude
        change = badness(r.value) - badness(g.value)  # > 0 means worse
        detail = f"{name}: {g.value:.6g} -> {r.value:.6g} ({r.value - g.value:+.3g}, tolerance {g.tolerance:g})"
        if change > g.tolerance:
            findings.append(Finding("worse", g.key, f"WORSE    {detail}"))
        elif change < -g.tolerance:
            findings.append(Finding("better", g.key, f"better   {detail}", failed=False))
    known = {g.key for g in golden}
    for key, r in current.items():
        if key not in known:
            why = _invalid(METRICS.find(key[2]), r.value)  # a value that cannot be one fails, golden or not
            findings.append(Finding("new", key, f"NEW      {'/'.join(key)}: {r.value:.6g} is not in the golden file"
                                    + (f" (INVALID: {why})" if why else ""), failed=fail_on_new or why is not None))
    findings.sort(key=lambda f: not f.failed)
    compared = sum(1 for g in golden if g.scene not in skipped)
    return GateResult(findings, golden=len(golden), compared=compared, skipped_scenes=tuple(skipped),
                      allow_empty=allow_empty)


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


def check_tolerance(tolerance: float | Mapping[str, float]) -> None:
    """SpecError unless every tolerance is a finite number >= 0 (:func:`_is_tolerance`)."""
    values = tolerance.values() if isinstance(tolerance, Mapping) else [tolerance]
    for v in values:
        if not _is_tolerance(v):
            raise SpecError(f"{TOLERANCE_RULE}, got {v!r}")


def make_golden(results: Results, tolerance: float | Mapping[str, float], path: str | Path, *,
                source: str | Path | None = None, allow_empty: bool = False) -> int:
    """Write the finite records of ``results`` as golden records; ``tolerance`` as in :func:`tolerance_for`.
    Checked first: no (method, scene, metric) twice (DataError naming ``source``, where the results
    came from, else ``path``), every tolerance (and narrower than the range of each record's metric),
    every record's metric known and value within its range (the file must read back), and at least one
    record to write (an empty golden file is a gate that cannot pass, unless ``allow_empty``)."""
    check_unique(results, source if source is not None else path)
    check_tolerance(tolerance)
    path = Path(path)
    if path.is_dir():
        raise DataError("golden file is a folder, expected a file", path)
    for r in results.records:
        metric = METRICS.find(r.metric)
        where = f"record {r.method}/{r.scene}/{r.metric}"
        if metric is None:
            raise DataError(f"{where}: unknown metric {r.metric!r}, cannot make it golden", path)
        problem = _out_of_range(metric, r.value) if math.isfinite(r.value) else None
        if problem:
            raise DataError(f"{where}: {problem}", source if source is not None else path)
        problem = _tolerance_too_wide(metric, tolerance_for(r.method, r.metric, tolerance))
        if problem:
            raise SpecError(f"--tolerance for {where}: {problem}")
    records = [{"method": r.method, "scene": r.scene, "metric": r.metric, "value": r.value,
                "tolerance": tolerance_for(r.method, r.metric, tolerance), "resolution": r.resolution}
               for r in results.records if math.isfinite(r.value)]
    if not records and not allow_empty:
        raise DataError("no finite records to make golden: an empty golden file is a gate that compares nothing "
                        "(--allow-empty writes one anyway)", source if source is not None else path)
    write_text(path, json.dumps(records, indent=1, allow_nan=False) + "\n")
    return len(records)
