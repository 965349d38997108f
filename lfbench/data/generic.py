"""Any dataset without code (``toml``): a small ``lfbench-dataset.toml`` beside the data says how views and
ground truth are named and how scenes are scored. README, "Your own dataset", shows one.

Keys (every one optional except ``views.pattern`` and ``views.angular``)::

    [views]
    pattern = "view_{v}_{u}.png"   # {v} angular row, {u} column (or {k} = v * U + u), from `first`
    angular = [9, 9]               # rows, columns (or one number for a square grid)
    first = 0                      # the first index: 0 or 1
    reverse_rows = false           # the files count rows bottom to top (`lfbench check-dataset` tells)
    reverse_columns = false        # ... columns right to left
    transpose = false              # ... the first index is the column (square grids)
    [ground_truth]
    file = "disparity.pfm"         # the centre view's disparity, px per view step (absent file: not scored)
    format = "pfm"                 # pfm, npy or png16 (16-bit gray PNG); disparity = value * scale + offset
    scale = 1.0
    offset = 0.0
    [protocol]
    border = 15                    # px ignored at every border
    metrics = ["badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100"]
    disparity_range = [-4.0, 4.0]  # what a method with d_min / d_max searches
    disparity_interval = 0.1       # its spacing, px (> 0, at most max - min; absent: each method's own)
    scorer = "lfbench"             # BadPix |e| > t, non-finite rule of lfbench; "paper-author": |e| >= t, NaN
                                   # good in BadPix and NaN in MSE (lfbench.scoring.policy)

Scenes are the folders under the data root (or ROOT/<category>/<scene>, or ROOT itself) holding the centre
view. An unknown key or an impossible value is one line naming the file (DataError, exit 2).
"""

from __future__ import annotations

import math
import os
import string
from pathlib import Path
from typing import Any

from lfbench.data.dataset import DEFAULT_METRICS, Dataset, DatasetProtocol
from lfbench.data.disparity import EVALUATION_BORDER_PX
from lfbench.data.pattern import GT_FORMATS, PatternScene, ViewLayout, find_scene_dirs
from lfbench.data.scene import Benchmark, check_scene_names
from lfbench.utils.errors import DataError, LFBenchError
from lfbench.utils.tomlfile import read_toml

__all__ = ["SPEC_FILE", "GenericDataset", "read_dataset_spec"]

SPEC_FILE = "lfbench-dataset.toml"
MAX_ANGULAR = 33  # views per axis
_KEYS: dict[str, set[str]] = {
    "views": {"pattern", "angular", "first", "reverse_rows", "reverse_columns", "transpose"},
    "ground_truth": {"file", "format", "scale", "offset"},
    "protocol": {"border", "metrics", "disparity_range", "disparity_interval", "scorer"},
}
DEFAULT_PROTOCOL = DatasetProtocol(border_px=EVALUATION_BORDER_PX, metrics=DEFAULT_METRICS, disparity_range=(-4.0, 4.0))


def _number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _file_name(value: Any, key: str, path: Path) -> str:
    """A plain file name inside the scene folder (no folder part: paths read back must stay inside it)."""
    if not isinstance(value, str) or not value or "/" in value or "\\" in value or value in (".", ".."):
        raise DataError(f"'{key}' must be a file name inside the scene folder, got {str(value)[:60]!r}", path)
    return value


def _check_fields(pattern: str, path: Path) -> None:
    """DataError unless every replacement field of ``pattern`` is a bare ``{v}``, ``{u}`` or ``{k}`` (no positional
    field such as ``{0}``, no conversion, no format spec such as ``{v:>999999999}``, balanced braces): checked
    before the pattern formats a name."""
    try:
        parsed = list(string.Formatter().parse(pattern))
    except ValueError:
        raise DataError(f"'views.pattern' has unbalanced braces: {pattern[:60]!r}", path) from None
    for _, name, spec, conversion in parsed:
        if name is not None and (name not in ("u", "v", "k") or spec or conversion):
            shown = "{" + name + (f"!{conversion}" if conversion else "") + (f":{spec}" if spec else "") + "}"
            raise DataError(f"'views.pattern' may hold only the fields {{v}}, {{u}} and {{k}} (no format spec); got "
                            f"{shown[:40]!r}", path)


def read_dataset_spec(path: str | Path) -> tuple[ViewLayout, DatasetProtocol]:
    """The view layout and scoring protocol ``lfbench-dataset.toml`` declares; DataError naming the file and
    the key for an unknown key or an impossible value."""
    path = Path(path)
    try:
        table, _ = read_toml(path, "dataset description")
    except LFBenchError as exc:
        raise DataError(str(exc).removeprefix(f"{path}: "), path) from None
    unknown = sorted(set(table) - set(_KEYS))
    if unknown:
        raise DataError(f"unknown section or key {unknown[0]!r}; known: {', '.join(_KEYS)}", path)
    for section, keys in _KEYS.items():
        if not isinstance(table.get(section, {}), dict):
            raise DataError(f"'{section}' must be a table ([{section}])", path)
        extra = sorted(set(table.get(section, {})) - keys)
        if extra:
            raise DataError(f"unknown key '{section}.{extra[0]}'; known: {', '.join(sorted(keys))}", path)
    views, gt, proto = (table.get(s, {}) for s in _KEYS)

    pattern = _file_name(views.get("pattern"), "views.pattern", path)
    _check_fields(pattern, path)
    fields = {f for f in ("{u}", "{v}", "{k}") if f in pattern}
    if fields not in ({"{u}", "{v}"}, {"{k}"}):
        raise DataError("'views.pattern' must name a view by {v} and {u} (row, column) or by {k}, e.g. "
                        f"'view_{{v}}_{{u}}.png'; got {pattern!r}", path)
    if not pattern.lower().endswith(".png"):
        raise DataError(f"'views.pattern' must name PNG files, got {pattern!r}", path)
    angular = views.get("angular")
    angular = [angular, angular] if isinstance(angular, int) and not isinstance(angular, bool) else angular
    if (not isinstance(angular, list) or len(angular) != 2
            or not all(isinstance(a, int) and not isinstance(a, bool) and 1 <= a <= MAX_ANGULAR for a in angular)
            or angular[0] * angular[1] < 2):
        raise DataError(f"'views.angular' must be [rows, columns] (or one number) from 1 to {MAX_ANGULAR}, at least "
                        f"2 views; got {views.get('angular')!r}", path)
    first = views.get("first", 0)
    if first not in (0, 1) or isinstance(first, bool):
        raise DataError(f"'views.first' must be 0 or 1, got {first!r}", path)

    gt_file = _file_name(gt["file"], "ground_truth.file", path) if "file" in gt else None
    fmt = gt.get("format", Path(gt_file).suffix.lstrip(".").lower() if gt_file else "npy")
    if fmt not in GT_FORMATS:
        raise DataError(f"'ground_truth.format' must be one of {', '.join(GT_FORMATS)}, got {fmt!r}", path)
    scale, offset = gt.get("scale", 1.0), gt.get("offset", 0.0)
    if not _number(scale) or scale == 0 or not _number(offset):
        raise DataError(f"'ground_truth.scale' must be a finite non-zero number and 'offset' finite, got {scale!r}, "
                        f"{offset!r}", path)
    turns = {key: views.get(key, False) for key in ("reverse_rows", "reverse_columns", "transpose")}
    for key, value in turns.items():
        if not isinstance(value, bool):
            raise DataError(f"'views.{key}' must be true or false, got {str(value)[:40]!r}", path)
    if turns["transpose"] and angular[0] != angular[1]:
        raise DataError(f"'views.transpose' needs a square grid of views, got {angular[0]}x{angular[1]}", path)

    border = proto.get("border", DEFAULT_PROTOCOL.border_px)
    if not isinstance(border, int) or isinstance(border, bool) or not 0 <= border <= 1024:
        raise DataError(f"'protocol.border' must be a whole number of px from 0 to 1024, got {border!r}", path)
    metrics = proto.get("metrics", list(DEFAULT_PROTOCOL.metrics))
    if not isinstance(metrics, list) or not metrics or not all(isinstance(m, str) for m in metrics):
        raise DataError(f"'protocol.metrics' must be a non-empty list of metric ids, got {metrics!r}", path)
    rng = proto.get("disparity_range", list(DEFAULT_PROTOCOL.disparity_range))
    if not isinstance(rng, list) or len(rng) != 2 or not all(_number(x) for x in rng) or not rng[0] < rng[1]:
        raise DataError(f"'protocol.disparity_range' must be [min, max] px with min < max, got {rng!r}", path)
    step = proto.get("disparity_interval")
    if step is not None and (not _number(step) or not 0 < step <= rng[1] - rng[0]):
        raise DataError(f"'protocol.disparity_interval' must be a number of px > 0 and at most the range's max - min "
                        f"({rng[1] - rng[0]:g}), got {step!r}", path)

    scorer = proto.get("scorer", "lfbench")
    if scorer not in ("lfbench", "paper-author"):
        raise DataError(f"'protocol.scorer' must be \"lfbench\" or \"paper-author\", got {str(scorer)[:40]!r}", path)

    layout = ViewLayout(pattern=pattern, angular=(angular[0], angular[1]), first=first, gt_file=gt_file,
                        gt_format=fmt, gt_scale=float(scale), gt_offset=float(offset),
                        transpose=turns["transpose"], reverse_rows=turns["reverse_rows"],
                        reverse_cols=turns["reverse_columns"])
    protocol = DatasetProtocol(border_px=border, metrics=tuple(metrics), source=path,  # ids checked where scored
                               disparity_range=(float(rng[0]), float(rng[1])), angular_size=layout.angular,
                               disparity_interval=None if step is None else float(step),
                               reference_view=f"centre view {layout.view_name(*layout.centre)}", scorer=scorer)
    return layout, protocol


class GenericDataset(Dataset):
    """A dataset described by ``lfbench-dataset.toml`` at its root (README, "Your own dataset")."""

    name = "toml"
    summary = f"any dataset described by {SPEC_FILE} at its root (views, ground truth, protocol)"
    layout = f"ROOT/{SPEC_FILE} and ROOT/[<category>/]<scene>/ with views named by its pattern"
    protocol = DEFAULT_PROTOCOL

    @classmethod
    def matches(cls, root: Path) -> bool:
        return (root / SPEC_FILE).is_file()

    @classmethod
    def protocol_for(cls, root: Path) -> DatasetProtocol:
        return read_dataset_spec(Path(root) / SPEC_FILE)[1]

    @classmethod
    def open(cls, root: Path) -> Benchmark:
        root = Path(root)
        layout, _ = read_dataset_spec(root / SPEC_FILE)
        centre = layout.view_name(*layout.centre)
        found = find_scene_dirs(root, lambda folder: os.path.lexists(folder / centre))  # a FIFO: refused, not skipped
        scenes = [PatternScene(folder, layout, category) for folder, category in found]
        if not scenes:
            raise DataError(f"no scene folders holding {centre} (the centre view {SPEC_FILE} names)", root)
        return Benchmark(root=root, scenes=tuple(check_scene_names(scenes)), splits={})  # type: ignore[arg-type]
