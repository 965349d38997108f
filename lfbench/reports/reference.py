"""References: a published paper whose numbers lfbench puts beside ours, shipped as data by the plugin of
its method and registered through the entry-point group ``lfbench.references``, e.g. SubFocal's paper
(the bundled ``lfbench_methods``)::

    [project.entry-points."lfbench.references"]
    subfocal-tci2023 = "lfbench_methods.subfocal:paper.toml"   # package : its TOML file

A reference says what the paper's tables are and how ours line up with them; its numbers are not in it
(they are the user's transcription, a folder of CSV files: lfbench.reports.paper). Layout of the file::

    name = "subfocal-tci2023"                # the registered name (the entry point's)
    networks = ["subfocal", "lfattnet"]      # trainable networks whose ablations it stands beside
    methods = ["SubFocal"]                   # its methods shown beside ours in Tables I/II by default
    label = "paper (RTX 3090, full training)"   # the label of its columns in the ablation tables
    benchmark_note = "..."                   # caption line of the tables with its Tables I/II
    ablation_note = "..."                    # caption line of the tables with its ablation numbers

    [table4]                                 # its Table IV: rows (interval, interpolation)
    file = "table4_interval_interp.csv"      # with columns interval, interpolation, badpix_0.07, mse_x100
    train_hours = "train_hours_rtx3090"      # and its train time (h) and test time (s) columns
    test_seconds = "test_seconds_512x512_rtx3090"
    test_label = "paper (RTX 3090, 512x512)" # what its test time was measured on
    figure_title = "..."; figure_time_label = "..."   # its panel of the accuracy-vs-time figure

    [table5]                                 # its Table V: BadPix 0.07 per fine-tuning loss (columns loss, badpix_0.07)
    file = "table5_losses.csv"
    best_loss = "uafl"                       # the loss it finds best (at [beta] best when the loss has a beta)
    loss_names = { l1 = "baseline_l1" }      # our loss name -> its row, where they differ

    [beta]                                   # its beta sweep
    best = 0.1                               # the beta it uses and finds best
    note = "..."; curve_note = "..."         # what it says about beta: table caption, figure title

Which reference an ablation uses: the spec's ``[report] reference``, else, when the spec asks for a
paper table or paper methods (or ``--paper`` is given), the reference of the spec's network, else the
default reference: that of the default network (lfbench.method.trainable.DEFAULT_TRAINABLE).
"""

from __future__ import annotations

import dataclasses
import importlib.util
import types
import typing
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import Any

from lfbench.method.trainable import DEFAULT_TRAINABLE
from lfbench.utils.errors import SpecError
from lfbench.utils.tomlfile import read_toml

__all__ = ["ENTRY_POINT_GROUP", "BetaSweep", "Reference", "Table4", "Table5", "default_reference",
           "get_reference", "list_references", "read_reference", "reference_for_network"]

ENTRY_POINT_GROUP = "lfbench.references"


@dataclass(frozen=True)
class Table4:
    """A paper's Table IV: BadPix 0.07, MSE x100, train and test time per (interval, interpolation)."""

    file: str
    train_hours: str
    test_seconds: str
    test_label: str
    figure_title: str
    figure_time_label: str


@dataclass(frozen=True)
class Table5:
    """A paper's Table V: BadPix 0.07 per fine-tuning loss; ``best_loss`` the one it finds best."""

    file: str
    best_loss: str
    loss_names: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class BetaSweep:
    """A paper's beta sweep: the ``best`` beta, and what it says about it (``note``: table caption,
    ``curve_note``: figure title)."""

    best: float
    note: str
    curve_note: str


@dataclass(frozen=True)
class Reference:
    """A paper lfbench puts beside ours (see the module docstring for the file layout)."""

    name: str
    networks: tuple[str, ...]
    methods: tuple[str, ...]
    label: str
    benchmark_note: str
    ablation_note: str
    table4: Table4 | None = None
    table5: Table5 | None = None
    beta: BetaSweep | None = None
    source: str = field(default="", compare=False)


def _parse(cls: type, raw: Any, where: str, path: Path) -> Any:
    """An instance of the dataclass ``cls`` from the TOML table ``raw``: every key declared by a field, of
    the field's type (str, float, tuple of str, dict of str, or a nested dataclass table); SpecError
    naming the file and key otherwise."""
    if not isinstance(raw, dict):
        raise SpecError(f"{where or 'the file'} must be a table", path)
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.name != "source"}
    unknown = sorted(set(raw) - set(fields))
    if unknown:
        raise SpecError(f"{where + '.' if where else ''}{unknown[0]}: unknown key (known: {', '.join(fields)})", path)
    values = {}
    for name, f in fields.items():
        key = f"{where}.{name}" if where else name
        if name not in raw:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise SpecError(f"{key}: is required", path)
            continue
        values[name] = _value(hints[name], raw[name], key, path)
    return cls(**values)


def _value(kind: Any, value: Any, key: str, path: Path) -> Any:
    options = [a for a in typing.get_args(kind) if a is not type(None)] if isinstance(kind, types.UnionType) else []
    if options:
        return _value(options[0], value, key, path)
    if dataclasses.is_dataclass(kind):
        return _parse(kind, value, key, path)
    origin = typing.get_origin(kind)
    if origin is tuple and isinstance(value, list) and all(isinstance(v, str) for v in value):
        return tuple(value)
    if origin is dict and isinstance(value, dict) and all(isinstance(v, str) for v in value.values()):
        return dict(value)
    if kind is float and isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if kind is str and isinstance(value, str):
        return value
    expected = {tuple: "a list of strings", dict: "a table of strings"}.get(origin, getattr(kind, "__name__", kind))
    raise SpecError(f"{key}: expected {expected}, got {str(value)[:40]!r}", path)


def read_reference(path: str | Path) -> Reference:
    """The reference in the TOML file ``path`` (SpecError naming the file and key when it is not one)."""
    path = Path(path)
    raw, _ = read_toml(path, "reference")
    return dataclasses.replace(_parse(Reference, raw, "", path), source=str(path))


def list_references() -> dict[str, Reference]:
    """Every registered reference by name (the entry points of ``lfbench.references``)."""
    found = {}
    for ep in sorted(metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
        path = _data_file(ep)
        reference = read_reference(path)
        if reference.name != ep.name:
            raise SpecError(f"reference {ep.name!r}: its file says name = {reference.name!r}", path)
        found[ep.name] = reference
    return found


def _data_file(ep: metadata.EntryPoint) -> Path:
    """The file an entry point ``package:file.toml`` names, found without running the package's
    ``__init__`` (a plugin's package may import torch: a report needs only its data file)."""
    try:
        spec = importlib.util.find_spec(ep.module)
    except (ImportError, ValueError) as exc:
        spec, why = None, str(exc)
    else:
        why = "no such package"
    folders = list(spec.submodule_search_locations or []) if spec is not None else []
    if not folders or not ep.attr:
        raise SpecError(f"reference {ep.name!r} ({ep.value}): expected 'package:file.toml' of an installed "
                        f"package ({why})")
    return Path(folders[0]) / ep.attr


def get_reference(name: str) -> Reference:
    """The registered reference ``name``; SpecError 'Unknown reference ... Available: ...' otherwise."""
    known = list_references()
    if name not in known:
        raise SpecError(f"Unknown reference {name!r}. Available: {', '.join(known) or 'none'}")
    return known[name]


def reference_for_network(network: str) -> Reference | None:
    """The registered reference whose ``networks`` include ``network`` (None when there is none)."""
    return next((r for r in list_references().values() if network in r.networks), None)


def default_reference() -> Reference | None:
    """The reference of the default network: what a paper folder is read as when nothing names another."""
    return reference_for_network(DEFAULT_TRAINABLE)
