"""Results of a run, the data model every layer above shares: one record per (method, scene, metric),
written as results.json and results.csv (runs write them, reports and regress read them).

results.csv columns: method, scene, metric, value, resolution. results.json holds the same records
plus per (method, scene) run information: runtime in s, non-finite pixel count, alignment notes.
"""

from __future__ import annotations

import csv
import io
import math
import platform
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from lfbench import __version__
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.atomic import write_text
from lfbench.utils.errors import DataError
from lfbench.utils.jsonfile import json_text, read_json
from lfbench.utils.names import file_names
from lfbench.utils.outputs import check_complete, check_within

__all__ = ["CSV_COLUMNS", "Record", "Results", "RunInfo", "check_names", "check_same_scoring", "check_unique",
           "protocol_meta"]

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
    files: list[Path] = field(default_factory=list, repr=False, compare=False)  # written by this run; not saved

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

    @property
    def protocol_metrics(self) -> list[str]:
        """The metric ids of the protocol the results were scored under (``meta.protocol.metrics``, written by
        ``lfbench evaluate``): what figures and pages take their BadPix thresholds from; the metrics of the
        records for results that do not record it."""
        return list((self.meta.get("protocol") or {}).get("metrics") or self.metrics)

    @property
    def disparity_range(self) -> tuple[float, float] | None:
        """The (min, max) disparity (px per view step) of the results' dataset protocol
        (``meta.protocol.disparity_range``), or None when not recorded."""
        found = (self.meta.get("protocol") or {}).get("disparity_range")
        return (float(found[0]), float(found[1])) if found else None

    @property
    def data_roots(self) -> list[Path]:
        """The data roots the results were scored on (``meta.data_roots`` when several, else
        ``meta.data_root``); empty when the results do not record one."""
        roots = self.meta.get("data_roots") or ([self.meta["data_root"]] if self.meta.get("data_root") else [])
        return [Path(r) for r in roots]

    @property
    def references(self) -> list[str]:
        """Methods that are reference lines, not competitors: the oracles of the run (``meta.references``,
        recorded from :attr:`lfbench.Method.oracle`); for results written before that was recorded, a method
        labelled ``gt`` or made from the spec ``gt``. Reports leave them out of ranks and comparisons."""
        if self.meta.get("references") is not None:
            return [m for m in self.methods if m in self.meta["references"]]
        specs = {label: (p or {}).get("spec") if isinstance(p, dict) else None
                 for label, p in (self.meta.get("methods") or {}).items()}
        return [m for m in self.methods if m == "gt" or specs.get(m) == "gt"]

    @property
    def competitors(self) -> list[str]:
        """The methods that are ranked and compared: :attr:`methods` less :attr:`references`."""
        refs = set(self.references)
        return [m for m in self.methods if m not in refs]

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
        meta = {"lfbench_version": __version__, "created": datetime.now(UTC).isoformat(timespec="seconds"),
                "python": platform.python_version(), **self.meta}
        return {"meta": meta, "records": [asdict(r) for r in self.records], "runs": [asdict(r) for r in self.runs]}

    def write(self, out_dir: str | Path) -> tuple[Path, Path]:
        """Write results.json (strict JSON: a NaN value is null) and results.csv into ``out_dir``
        (atomically)."""
        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        write_text(out / "results.json", json_text(self.to_json_dict(), indent=2) + "\n")
        buf = io.StringIO()
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(CSV_COLUMNS)
        for r in self.records:
            w.writerow([r.method, r.scene, r.metric, repr(float(r.value)), r.resolution])
        write_text(out / "results.csv", buf.getvalue())
        return out / "results.json", out / "results.csv"

    @classmethod
    def read(cls, path: str | Path, *, names_checked: bool = False) -> Results:
        """Read results.json (or a folder holding one), or a golden/records JSON list.

        Every record needs string method/scene/metric and a numeric (or null) value; every run entry
        string method/scene and numeric fields; DataError naming the file otherwise. The names are checked
        (:func:`check_names`) unless ``names_checked`` says the file is the set this run staged itself,
        whose names were checked before its work."""
        path = Path(path)
        if path.is_dir():
            path = path / "results.json"
            if path.is_symlink():
                check_within(path, path.parent, "the results folder")
        check_complete(path.parent)  # a half-committed run may mix two runs' files
        data = read_json(path, "results file", allow_nonfinite=True)
        raw = data if isinstance(data, list) else data.get("records") if isinstance(data, dict) else None
        if not isinstance(raw, list):
            raise DataError("expected a list of records or an object with 'records'", path)
        records = []
        for i, item in enumerate(raw):
            try:
                if not isinstance(item, dict):
                    raise TypeError("not an object")
                names = [_text(item[k], k) for k in ("method", "scene", "metric")]
                records.append(Record(*names, _num(item["value"], "value"),
                                      _text(item.get("resolution", "lowres"), "resolution")))
            except KeyError as exc:
                raise DataError(f"record {i} is malformed (no {exc})", path) from None
            except (TypeError, ValueError) as exc:
                raise DataError(f"record {i} is malformed ({exc})", path) from None
        runs = [_run_info(item, i, path) for i, item in enumerate(_list(data, "runs", path))]
        meta = data.get("meta", {}) if isinstance(data, dict) else {}
        if not isinstance(meta, dict):
            raise DataError("'meta' must be an object", path)
        _check_meta(meta, path)
        results = cls(records=records, runs=runs, meta=meta)
        if not names_checked:
            check_names(results.methods, results.scenes, _keys(records), source=path)
        return results


def check_unique(results: Results, source: str | Path | None = None) -> None:
    """DataError naming ``source`` when ``results`` hold one (method, scene, metric) twice."""
    _once(_keys(results.records), source)


def _keys(records: Iterable[Record]) -> Iterator[tuple[str, str, str]]:
    return ((r.method, r.scene, r.metric) for r in records)


def _once(keys: Iterable[tuple[str, ...]], source: str | Path | None,
          twice: Callable[[tuple[str, ...]], str] | None = None) -> None:
    seen: set[tuple[str, ...]] = set()
    for key in keys:
        if key in seen:
            raise DataError(twice(key) if twice is not None else f"record {'/'.join(key)} appears twice", source)
        seen.add(key)


def check_names(methods: Iterable[str], scenes: Iterable[str], keys: Iterable[tuple[str, ...]] = (), *,
                source: str | Path | None = None, twice: Callable[[tuple[str, ...]], str] | None = None,
                scene_folders: Sequence[Any] = ()) -> None:
    """The one check of the names a run files things under, once at each entry point before any work (a
    run's plan, lfbench.runs.folder.check_plan; a results file, :meth:`Results.read`); the layers below
    trust it. DataError (naming ``source``) when a key appears twice (``twice(key)``: the message), two
    ``methods`` or two ``scenes`` share a file name (lfbench.utils.names), or two ``scene_folders`` (light
    fields, checked first) share a name (lfbench.data.scene.check_scene_names)."""
    if scene_folders:  # first: two scenes of one name would also make each (method, scene) pair twice
        from lfbench.data.scene import check_scene_names

        check_scene_names(scene_folders)
    _once(keys, source, twice)
    file_names(methods, "method label", source=source)
    file_names(scenes, "scene", source=source)


def _list(data: Any, key: str, path: Path) -> list[Any]:
    value = data.get(key, []) if isinstance(data, dict) else []
    if not isinstance(value, list):
        raise DataError(f"{key!r} must be a list", path)
    return value


def _run_info(item: Any, i: int, path: Path) -> RunInfo:
    """One entry of 'runs', type-checked field by field."""
    try:
        if not isinstance(item, dict):
            raise TypeError("not an object")
        aligned = item.get("aligned_from")
        notes = item.get("notes", [])
        if aligned is not None and not (isinstance(aligned, list) and all(_is_int(a) for a in aligned)):
            raise TypeError("aligned_from must be a list of integers or null")
        if not (isinstance(notes, list) and all(isinstance(n, str) for n in notes)):
            raise TypeError("notes must be a list of strings")
        nonfinite = item.get("nonfinite_pixels", 0)
        if not _is_int(nonfinite):
            raise TypeError("nonfinite_pixels must be an integer")
        return RunInfo(_text(item["method"], "method"), _text(item["scene"], "scene"),
                       _num(item.get("runtime_s"), "runtime_s"), nonfinite, aligned, notes)
    except KeyError as exc:
        raise DataError(f"run {i} is malformed (no {exc})", path) from None
    except (TypeError, ValueError) as exc:
        raise DataError(f"run {i} is malformed ({exc})", path) from None


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_finite_number(v: Any) -> bool:
    return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)


#: The meta keys lfbench reads back, each with the JSON type it must have (other keys are kept as they are).
_META_TYPES: dict[str, tuple[type, str]] = {
    "data_root": (str, "a folder name (a string)"), "created": (str, "a string"),
    "lfbench_version": (str, "a string"), "ablation": (dict, "an object"),
    "scenes": (list, "a list of folder names"), "methods": (dict, "an object"),
    "dataset": (str, "a dataset name (a string; see `lfbench datasets`)"),
    "data_roots": (list, "a list of folder names"), "references": (list, "a list of method labels"),
    "protocol": (dict, "an object (metrics, disparity_range)"),
    "synthetic": (bool, "true or false (scored on data written by lfbench synth)"),
}


def protocol_meta(metrics: Sequence[str], disparity_range: tuple[float, float]) -> dict[str, Any]:
    """What results record of their dataset protocol (``meta.protocol``, read back by
    :attr:`Results.protocol_metrics` and :attr:`Results.disparity_range`): its metric ids and disparity range
    (px per view step); the border is ``meta.scoring.border_px``."""
    return {"metrics": list(metrics), "disparity_range": [float(disparity_range[0]), float(disparity_range[1])]}


def _protocol_record(results: Results) -> dict[str, Any]:
    """What ``results`` record of how they were scored: the rules (``meta.scoring``, as every reader takes them)
    and the protocol (``meta.protocol``), each only when recorded."""
    record: dict[str, Any] = {}
    if "scoring" in results.meta:
        rules = ScoringRules.from_meta(results.meta)
        record.update({**rules.to_meta(), "scorer": rules.scorer})  # the scorer too where it is lfbench's
    record.update({f"protocol {k}": v for k, v in (results.meta.get("protocol") or {}).items()})
    return record


def check_same_scoring(ours: Results, theirs: Results, source: str | Path) -> None:
    """DataError (one line, naming ``source``) when ``theirs`` were scored under another protocol than ``ours``
    (a border, non-finite rule, scorer, high-resolution scene, metric list or disparity range that both record
    and that differs): their numbers cannot share one table, map or page. What either does not record (results
    written before it was) is not compared."""
    mine, other = _protocol_record(ours), _protocol_record(theirs)
    differ = [k for k in mine if k in other and mine[k] != other[k]]
    if differ:
        what = "; ".join(f"{k.replace('_', ' ')} {other[k]} here, {mine[k]} in the rest" for k in differ)
        raise DataError(f"scored under another protocol than the results it would join ({what}); results of one "
                        "protocol only share a table: score the others into another folder", source)


def _check_meta(meta: dict[str, Any], path: Path) -> None:
    """DataError naming ``path`` when a meta key that lfbench reads back has the wrong type (a results
    file from elsewhere is untrusted: a number as data_root would end in a traceback, not one line)."""
    for key, (kind, text) in _META_TYPES.items():
        if key in meta and meta[key] is not None and not isinstance(meta[key], kind):
            raise DataError(f"'meta.{key}' must be {text}, got {type(meta[key]).__name__}", path)
    if "\0" in (meta.get("data_root") or "") or any(not isinstance(s, str) for s in meta.get("scenes") or []):
        raise DataError("'meta.data_root' and 'meta.scenes' must be folder names", path)
    if any(not isinstance(r, str) or not r or "\0" in r for r in meta.get("data_roots") or []):
        raise DataError("'meta.data_roots' must be folder names", path)
    if any(not isinstance(r, str) for r in meta.get("references") or []):
        raise DataError("'meta.references' must be method labels (strings)", path)
    protocol = meta.get("protocol") or {}
    if not isinstance(protocol.get("metrics", []), list) or any(not isinstance(m, str)
                                                                for m in protocol.get("metrics", [])):
        raise DataError("'meta.protocol.metrics' must be a list of metric ids", path)
    lo_hi = protocol.get("disparity_range")
    if lo_hi is not None and not (isinstance(lo_hi, list) and len(lo_hi) == 2
                                  and all(_is_finite_number(v) for v in lo_hi) and lo_hi[0] < lo_hi[1]):
        raise DataError("'meta.protocol.disparity_range' must be [min, max], finite numbers with min < max", path)
    try:
        ScoringRules.from_meta(meta)  # the recorded rules, as every reader takes them
    except ValueError as exc:
        raise DataError("'meta." + str(exc).removeprefix("'"), path) from None  # 'meta.scoring...' must be
    ablation = meta.get("ablation") or {}
    if not isinstance(ablation.get("title", ""), str) or not isinstance(ablation.get("cells", []), list):
        raise DataError("'meta.ablation' must have a string title and a list of cells", path)


def _text(v: Any, name: str) -> str:
    if not isinstance(v, str):
        raise TypeError(f"{name} must be a string, got {type(v).__name__}")
    return v


def _num(v: Any, name: str = "value") -> float:
    """A JSON number or null (NaN) as float; strings and booleans are refused."""
    if v is None:
        return float("nan")
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise TypeError(f"{name} must be a number or null, got {type(v).__name__}")
    return float(v)
