"""The dataset seam: a dataset adapter turns a data root into scenes and declares how they are scored.

An adapter is a :class:`Dataset` subclass registered in the entry-point group ``lfbench.datasets`` (the
built-in HCI and UrbanLF-Syn adapters go through the same group, as built-in methods go through
``lfbench.methods``). It answers three things:

- :meth:`Dataset.matches`: whether a folder is laid out as this dataset (detection; cheap, by file names);
- :meth:`Dataset.open`: the scenes under the folder, as a :class:`~lfbench.data.scene.Benchmark` of
  :class:`~lfbench.data.scene.LightField` scenes (views, angular size, spatial size of any aspect ratio,
  optional ground truth, masks);
- :attr:`Dataset.protocol`: its scoring protocol (:class:`DatasetProtocol`): border, resolutions, which
  metrics apply, the scenes scored at high resolution, the disparity range a method should search and the
  spacing of its candidate disparities.

:func:`open_dataset` detects the layout of a root (or takes the adapter named) and refuses a root that
matches none or several in one line (:class:`~lfbench.utils.errors.DataError`, exit 2).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from lfbench.data.scene import LOWRES, Benchmark
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.registry import Registry

__all__ = ["DATASET_GROUP", "DATASETS", "Dataset", "DatasetProtocol", "detect_dataset", "dataset_of",
           "open_datasets", "open_dataset", "method_range_params"]

DATASET_GROUP = "lfbench.datasets"


@dataclass(frozen=True)
class DatasetProtocol:
    """How a dataset's scenes are scored and what a method should search.

    ``border_px``: pixels ignored at every border at low resolution (scaled with resolution);
    ``metrics``: the ids of the metrics scored on every scene (lfbench.scoring.metrics);
    ``resolutions``: the resolutions numbers may be scored at ('lowres', and 'highres' where the dataset
    has high-resolution ground truth); ``highres_scenes``: the scenes scored at high resolution when their
    high-resolution ground truth exists; ``disparity_range``: (min, max) px per view step a method should
    search; ``disparity_interval``: the spacing (px) of the candidate disparities a method searching that
    range should use (> 0, at most max - min), or None: each method's own (HCI: the plane sweep's 0.25,
    SubFocal's 0.5 as its paper); ``spatial_size``: (H, W) px of its views where the dataset fixes one (None: any);
    ``angular_size``: (V, U) views where fixed; ``reference_view``: the view scored (words); ``source``: the
    file that declared the protocol (errors in its metric ids name it: lfbench.scoring.metrics.scored_metrics).
    """

    border_px: int
    metrics: tuple[str, ...]
    disparity_range: tuple[float, float]
    disparity_interval: float | None = None
    resolutions: tuple[str, ...] = (LOWRES,)
    highres_scenes: frozenset[str] = frozenset()
    spatial_size: tuple[int, int] | None = None
    angular_size: tuple[int, int] | None = None
    reference_view: str = "centre view"
    source: Path | None = dataclasses.field(default=None, compare=False)  # the file that declared it, if any

    def __post_init__(self) -> None:
        lo, hi = self.disparity_range
        if not lo < hi:
            raise ValueError(f"disparity range must be (min, max) with min < max, got {self.disparity_range}")
        step = self.disparity_interval
        if step is not None and not 0 < step <= hi - lo:  # NaN fails too
            raise ValueError(f"disparity interval must be > 0 and at most max - min = {hi - lo:g} px, got {step}")
        if self.border_px < 0:
            raise ValueError(f"border must be >= 0 px, got {self.border_px}")

    def describe(self) -> list[str]:
        """The protocol as lines for ``lfbench datasets``."""
        size = f"{self.spatial_size[1]}x{self.spatial_size[0]} px (W x H)" if self.spatial_size else "any"
        views = f"{self.angular_size[1]}x{self.angular_size[0]}" if self.angular_size else "any"
        lo, hi = self.disparity_range
        lines = [f"views: {views}, {size}; scored: {self.reference_view}, {self.border_px} px border",
                 f"metrics: {', '.join(self.metrics)}", f"resolutions: {', '.join(self.resolutions)}",
                 f"disparity range: [{lo:g}, {hi:g}] px per view step, "
                 + (f"interval {self.disparity_interval:g} px" if self.disparity_interval is not None
                    else "each method's own interval")]
        if self.highres_scenes:
            lines.append(f"high-resolution scenes: {', '.join(sorted(self.highres_scenes))}")
        return lines


class Dataset:
    """A dataset adapter (subclass it and register it in the entry-point group ``lfbench.datasets``)."""

    #: the name ``--dataset`` takes
    name: ClassVar[str] = ""
    #: one line for ``lfbench datasets``
    summary: ClassVar[str] = ""
    #: how its scenes are scored
    protocol: ClassVar[DatasetProtocol]
    #: how a data root is laid out (one line)
    layout: ClassVar[str] = ""

    @classmethod
    def matches(cls, root: Path) -> bool:
        """Whether ``root`` is laid out as this dataset (by file names only: no file is decoded)."""
        raise NotImplementedError

    @classmethod
    def open(cls, root: Path) -> Benchmark:
        """The scenes under ``root`` (DataError naming the file for anything malformed)."""
        raise NotImplementedError

    @classmethod
    def protocol_for(cls, root: Path) -> DatasetProtocol:
        """The protocol of the data under ``root``: :attr:`protocol`, unless the data declares its own (the
        generic TOML adapter reads it from the root)."""
        return cls.protocol

    @classmethod
    def protocol_from_data(cls) -> bool:
        """Whether :meth:`protocol_for` reads the protocol from the data (then :attr:`protocol` is its default)."""
        return cls.protocol_for.__func__ is not Dataset.protocol_for.__func__  # type: ignore[attr-defined]


#: Every dataset adapter, by name (the ``lfbench.datasets`` entry points fill it).
DATASETS: Registry[type[Dataset]] = Registry("dataset", Dataset, group=DATASET_GROUP)


def detect_dataset(root: str | Path) -> type[Dataset]:
    """The one adapter whose layout ``root`` matches; DataError (one line) when none or several do."""
    root = Path(root)
    if not root.is_dir():
        raise DataError("data root not found", root)
    hits = [name for name in DATASETS.names() if DATASETS.get(name).matches(root)]
    if not hits:
        raise DataError(f"no scenes found: no known dataset layout ({', '.join(DATASETS.names()) or 'none installed'}; "
                        "see `lfbench datasets`)", root)
    if len(hits) > 1:
        raise DataError(f"the layout matches several datasets ({', '.join(hits)}): choose one with --dataset NAME",
                        root)
    return DATASETS.get(hits[0])


def dataset_of(root: str | Path, name: str | None = None) -> type[Dataset]:
    """The adapter of ``root``: ``name``'s, else the one whose layout it matches (DataError, one line, for a
    root of no layout or of several, or one that is not laid out as the named dataset)."""
    root = Path(root)
    if name is None:
        return detect_dataset(root)
    try:
        dataset = DATASETS.get(name)
    except SpecError as exc:
        raise DataError(str(exc)) from None
    if not root.is_dir():
        raise DataError("data root not found", root)
    if not dataset.matches(root):
        raise DataError(f"not laid out as dataset {name!r} ({dataset.layout})", root)
    return dataset


def open_dataset(root: str | Path, name: str | None = None) -> tuple[type[Dataset], Benchmark]:
    """The adapter (``name``, else detected: :func:`dataset_of`) and the scenes of ``root``."""
    dataset = dataset_of(root, name)
    return dataset, dataset.open(Path(root))


def open_datasets(roots: Sequence[str | Path], name: str | None = None, *,
                  check: Callable[[DatasetProtocol], Any] | None = None
                  ) -> tuple[type[Dataset], DatasetProtocol, Benchmark]:
    """The adapter, the scoring protocol and the scenes of one or several data roots scored together (one
    results file). Every root must be of one dataset with one protocol (DataError naming the root that is
    not); a root given twice is refused; scenes keep their names (two selected scenes of one name are refused
    when selected, lfbench.data.scene.check_scene_names). ``check``: called with the protocol before any scene
    is opened (e.g. the metric ids a dataset's file declares)."""
    roots = [Path(r) for r in roots]
    if not roots:
        raise DataError("no data root given")
    seen: dict[Path, Path] = {}
    for root in roots:
        key = root.resolve()
        if key in seen:
            raise DataError(f"data root given twice (also as {seen[key]})", root)
        seen[key] = root
    dataset = dataset_of(roots[0], name)
    protocol = dataset.protocol_for(roots[0])
    for root in roots[1:]:
        other = dataset_of(root, name or dataset.name)
        if other.protocol_for(root) != protocol:
            raise DataError(f"scored by another protocol than {roots[0]} (one results file holds one dataset's "
                            "numbers): evaluate it on its own", root)
    if check is not None:
        check(protocol)
    benches = [dataset.open(root) for root in roots]
    scenes = tuple(s for bench in benches for s in bench.scenes)
    return dataset, protocol, dataclasses.replace(benches[0], scenes=scenes, others=tuple(roots[1:]))


def method_range_params(disparity_range: tuple[float, float], interval: float | None = None
                        ) -> Callable[[Any, dict[str, Any]], dict[str, float]]:
    """A ``defaults`` hook for :func:`lfbench.method.registry.create_from_spec`: a dataset's disparity grid
    (:attr:`DatasetProtocol.disparity_range`, :attr:`DatasetProtocol.disparity_interval`) as the parameters
    ``d_min``, ``d_max`` and ``interval`` of a method that has them, where they differ from the method's
    defaults (so that the label names what was searched, and stays as it was where they agree: HCI's [-4, 4]
    is every method's default range, and HCI leaves the interval to each method).

    A spec that sets ``d_min`` or ``d_max`` decides the range and gets nothing from the dataset; a spec that
    sets ``interval`` keeps it and gets the dataset's range. A method with an ``interval`` searches a grid
    from ``d_min``: ``d_max`` is then raised to the first grid point at or above the dataset's maximum
    (UrbanLF-Syn's [-0.5, 1.6] at 0.25 px: [-0.5, 1.75]), so that the whole range is searched.

    A method whose weights fix its disparity grid (a network trained on it: the number and spacing of its
    cost-volume disparities) says so with a classmethod ``range_from_weights(info, params) -> bool``; where it
    answers True the dataset's grid is not applied (it would contradict the weights) and the weights' grid
    is searched (logged). SubFocal: ``weights=`` given, or its shipped checkpoint is the one that loads."""
    lo, hi = (float(v) for v in disparity_range)

    def defaults(info: Any, params: dict[str, Any]) -> dict[str, float]:
        keys = {"d_min", "d_max"}
        if not keys <= set(info.params) or keys & set(params):
            return {}
        out: dict[str, float] = {}
        top = hi
        if "interval" in info.params:
            step = float(params.get("interval", info.params["interval"].default))
            if "interval" not in params and interval is not None and interval != step:
                step = out["interval"] = float(interval)
            if step > 0:
                top = round(lo + math.ceil(round((hi - lo) / step, 9)) * step, 9)
        if (info.params["d_min"].default, info.params["d_max"].default) != (lo, top):
            out = {"d_min": lo, "d_max": top, **out}
        if not out:
            return {}
        fixed = getattr(info.method_class, "range_from_weights", None)
        if fixed is not None and fixed(info, params):
            import logging  # here, not at the top: only this branch logs

            logging.getLogger(__name__).info(
                "%s: searches the disparity grid its weights were trained on (the dataset's [%g, %g] px is not "
                "laid over weights)", info.name, lo, hi)
            return {}
        return out

    return defaults
