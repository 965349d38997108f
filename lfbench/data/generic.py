"""Any dataset without code (``toml``): a small ``lfbench-dataset.toml`` beside the data says how views and
ground truth are named and how scenes are scored. README, "Your own dataset", shows one.

Its keys, each with its type, default, bounds and meaning: docs/dataset-toml.md, generated from their one
declaration (lfbench.data.dataset_file).

Scenes are the folders under the data root (or ROOT/<category>/<scene>, or ROOT itself) holding the centre
view. An unknown key or an impossible value is one line naming the file (DataError, exit 2).
"""

from __future__ import annotations

import os
from pathlib import Path

from lfbench.data.dataset import Dataset, DatasetProtocol
from lfbench.data.dataset_file import DatasetFile, ProtocolSection
from lfbench.data.pattern import PatternScene, ViewLayout, find_scene_dirs
from lfbench.data.scene import Benchmark, check_scene_names
from lfbench.utils.errors import DataError, LFBenchError
from lfbench.utils.options import Table, option_fields, parse_section
from lfbench.utils.tomlfile import read_toml

__all__ = ["SPEC_FILE", "GenericDataset", "read_dataset_spec"]

SPEC_FILE = "lfbench-dataset.toml"
_DEFAULTS = ProtocolSection()
DEFAULT_PROTOCOL = DatasetProtocol(border_px=_DEFAULTS.border, metrics=_DEFAULTS.metrics,
                                   disparity_range=_DEFAULTS.disparity_range)


def read_dataset_spec(path: str | Path) -> tuple[ViewLayout, DatasetProtocol]:
    """The view layout and scoring protocol ``lfbench-dataset.toml`` declares (its keys:
    lfbench.data.dataset_file); DataError naming the file and the key for an unknown key or an impossible
    value."""
    path = Path(path)
    try:
        raw, _ = read_toml(path, "dataset description")
        top = Table(raw, "", str(path))
        top.used |= {f.name for f, _, _ in option_fields(DatasetFile)}
        top.done()  # a misspelt section is named before a missing one
        spec = parse_section(DatasetFile, Table(raw, "", str(path)))
    except LFBenchError as exc:
        raise DataError(str(exc).removeprefix(f"{path}: "), path) from None
    views, gt, proto = spec.views, spec.ground_truth, spec.protocol
    layout = ViewLayout(pattern=views.pattern, angular=(views.angular[0], views.angular[1]), first=views.first,
                        gt_file=gt.file, gt_format=gt.format, gt_scale=gt.scale, gt_offset=gt.offset,
                        transpose=views.transpose, reverse_rows=views.reverse_rows,
                        reverse_cols=views.reverse_columns)
    protocol = DatasetProtocol(border_px=proto.border, metrics=proto.metrics, source=path,  # ids checked where scored
                               disparity_range=proto.disparity_range, angular_size=layout.angular,
                               disparity_interval=proto.disparity_interval,
                               reference_view=f"centre view {layout.view_name(*layout.centre)}", scorer=proto.scorer)
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
