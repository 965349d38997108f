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
import logging
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

from lfbench.data.scene import LOWRES, Benchmark, Scene
from lfbench.utils.errors import DataError, LFBenchError, SpecError, exception_line
from lfbench.utils.registry import Registry

_log = logging.getLogger(__name__)

__all__ = ["DATASET_GROUP", "DATASETS", "DEFAULT_METRICS", "Dataset", "DatasetProtocol", "detect_dataset", "dataset_of",
           "open_datasets", "open_dataset", "method_range_params", "protocol_of"]

DATASET_GROUP = "lfbench.datasets"

#: The general metrics a protocol scores unless it says otherwise (BadPix 0.01 / 0.03 / 0.07, MSE x100); its border
#: unless it says otherwise is lfbench.data.disparity.EVALUATION_BORDER_PX.
DEFAULT_METRICS: tuple[str, ...] = ("badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100")


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
    ``angular_size``: (V, U) views where fixed; ``reference_view``: the view scored (words); ``scorer``: how BadPix
    compares and what a non-finite value counts as (lfbench.scoring.policy: 'lfbench' or 'paper-author');
    ``source``: the
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
    scorer: str = "lfbench"  # BadPix's comparison and the non-finite policy: lfbench.scoring.policy
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
        if self.scorer not in ("lfbench", "paper-author"):
            raise ValueError(f"scorer must be 'lfbench' or 'paper-author', got {self.scorer!r}")

    def check_angular_size(self, scenes: Iterable[Scene]) -> None:
        """DataError naming the first of ``scenes`` whose views' angular size (what its adapter declares: no view
        is decoded; loaded views are held to it, lfbench.data.scene.Scene) is not the protocol's, and both sizes;
        nothing to check where the protocol fixes none."""
        if self.angular_size is None:
            return
        pv, pu = self.angular_size
        for scene in scenes:
            v, u = scene.angular_size
            if (v, u) != (pv, pu):
                raise DataError(f"scene {scene.name!r} has {u}x{v} views, its dataset's protocol {pu}x{pv}: it cannot "
                                "be scored by that protocol", scene.path)

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
        if self.scorer != "lfbench":
            lines.append(f"scorer: {self.scorer} (BadPix |error| >= t, NaN good in BadPix and NaN in MSE; "
                         "lfbench.scoring.policy)")
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
    #: split name -> the category folders it selects, where the dataset names splits of several categories
    #: (HCI's train / validation / test; none where its category folders are its splits): what a training
    #: config's names select among the scenes it generates in this layout
    splits: ClassVar[Mapping[str, tuple[str, ...]]] = {}

    @classmethod
    def matches(cls, root: Path) -> bool:
        """Whether ``root`` is laid out as this dataset (by file names only: no file is decoded)."""
        raise NotImplementedError

    @classmethod
    def open(cls, root: Path) -> Benchmark:
        """The scenes under ``root`` (DataError naming the file for anything malformed)."""
        raise NotImplementedError

    @classmethod
    def write_scene(cls, folder: Path, scene: Any) -> Path:
        """Write a generated scene as one scene folder ``folder`` of this layout and return it; how ``lfbench synth``
        writes the layout (lfbench.data.synth.write_benchmark). ``scene``: a lfbench.data.synth.SyntheticScene or an
        object with its ``params`` (lfbench.data.camera.Camera), ``views`` ((V, U, H, W, 3) RGB in [0, 1], or
        None), ``disparity`` ((H, W) px per view step), ``depth`` ((H, W) m, or None) and ``masks`` (name -> (H, W)
        bool). NotImplementedError for a dataset lfbench does not write."""
        raise NotImplementedError(f"dataset {cls.name!r} has no writer of generated scenes")

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
    failed: list[str] = []
    hits = [name for name in DATASETS.names() if _matches(DATASETS.get(name), root, failed)]
    for line in failed if hits else ():
        _log.warning("dataset adapter %s; left out of the detection", line)
    if not hits:
        why = f"; adapter {failed[0]}" if failed else ""
        raise DataError(f"no scenes found: no known dataset layout ({', '.join(DATASETS.names()) or 'none installed'}; "
                        f"see `lfbench datasets`){why}", root)
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
    failed: list[str] = []
    if not _matches(dataset, root, failed):
        if failed:
            raise DataError(f"dataset adapter {failed[0]}", root)
        raise DataError(f"not laid out as dataset {name!r} ({dataset.layout})", root)
    return dataset


def _plugin(dataset: type[Dataset]) -> str | None:
    """``'name' (module.Class)`` of a plugin's adapter; None for lfbench's own (whose errors keep their traceback)."""
    module = str(getattr(dataset, "__module__", ""))
    return None if module.split(".")[0] == "lfbench" else f"{dataset.name!r} ({module}.{dataset.__qualname__})"


def _failure(what: str, exc: BaseException) -> str:
    return f"{what} failed: {exception_line(exc)}"


def _matches(dataset: type[Dataset], root: Path, failed: list[str]) -> bool:
    """``dataset.matches(root)``; a plugin's adapter whose matches() raises is left out (its line appended to
    ``failed``): one broken adapter never breaks the detection of every root."""
    plugin = _plugin(dataset)
    if plugin is None:
        return dataset.matches(root)
    try:
        return dataset.matches(root) is True
    except LFBenchError as exc:
        failed.append(f"{plugin}: {exc}")
    except Exception as exc:  # noqa: BLE001 - whatever the plugin's code raised: isolated, named
        failed.append(_failure(f"{plugin}: matches()", exc))
    return False


def _call_adapter(dataset: type[Dataset], root: Path, method: str, expected: type) -> Any:
    """``dataset.<method>(root)``; a plugin's adapter that raises (not a one-line LFBenchError) or returns another
    type than ``expected`` is one DataError naming it, the method and the root."""
    plugin = _plugin(dataset)
    if plugin is None:
        return getattr(dataset, method)(root)
    try:
        value = getattr(dataset, method)(root)
    except LFBenchError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever the plugin's code raised: one line
        raise DataError(_failure(f"dataset adapter {plugin}: {method}()", exc), root) from None
    if not isinstance(value, expected):
        raise DataError(f"dataset adapter {plugin}: {method}() returned a {type(value).__name__}, expected a "
                        f"{expected.__name__}", root)
    return value


def _open(dataset: type[Dataset], root: Path) -> Benchmark:
    """The scenes of ``root`` (:func:`_call_adapter` of ``open``)."""
    return _call_adapter(dataset, root, "open", Benchmark)


def _protocol(dataset: type[Dataset], root: Path) -> DatasetProtocol:
    """The protocol of ``root`` (:func:`_call_adapter` of ``protocol_for``)."""
    return _call_adapter(dataset, root, "protocol_for", DatasetProtocol)


def protocol_of(root: str | Path, name: str | None = None) -> DatasetProtocol:
    """The scoring protocol of ``root``'s data: its adapter's (``name``, else detected: :func:`dataset_of`; no
    scene opened), read from the root where the data declares it (:meth:`Dataset.protocol_for`)."""
    return _protocol(dataset_of(root, name), Path(root))


def open_dataset(root: str | Path, name: str | None = None) -> tuple[type[Dataset], Benchmark]:
    """The adapter (``name``, else detected: :func:`dataset_of`) and the scenes of ``root``."""
    dataset = dataset_of(root, name)
    return dataset, _open(dataset, Path(root))


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
    protocol = _protocol(dataset, roots[0])
    for root in roots[1:]:
        if name is None and _detected(root) not in (None, dataset):  # another dataset: say so, not "not laid out"
            raise DataError(f"is dataset '{_detected(root).name}', {roots[0]} is '{dataset.name}': one results file "
                            "holds one dataset's numbers (their protocols differ); evaluate each into its own --out",
                            root)
        other = dataset_of(root, name or dataset.name)
        if _protocol(other, root) != protocol:
            raise DataError(f"scored by another protocol than {roots[0]} (one results file holds one dataset's "
                            "numbers): evaluate it on its own", root)
    if check is not None:
        check(protocol)
    benches = [_open(dataset, root) for root in roots]
    scenes = tuple(s for bench in benches for s in bench.scenes)
    return dataset, protocol, dataclasses.replace(benches[0], scenes=scenes, others=tuple(roots[1:]))


def _detected(root: Path) -> type[Dataset] | None:
    """The dataset ``root`` is detected as, or None where detection fails (no or several layouts)."""
    try:
        return detect_dataset(root)
    except DataError:
        return None


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
