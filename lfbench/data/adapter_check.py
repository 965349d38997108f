"""The contract check of a dataset adapter (``lfbench check-dataset``, ``--adapter-only``): what evaluation,
``check-dataset``, training and ``--jobs`` workers read of an adapter and its scenes, checked on a data root it
opened, each broken promise one line naming the adapter (its name, module and class), the scene (its name and
path) and the problem.

Checked: the adapter's ``name`` (the name it is registered under), ``summary`` and ``layout`` (one-line
strings), ``protocol`` and the root's protocol (:class:`~lfbench.data.dataset.DatasetProtocol`, passing its own
checks); ``matches(root)`` is True on the root it opened. On every selected scene (cheap: no view is read):
``angular_size`` is a pair of positive ints, the protocol's where it declares one; ``has_gt()`` is a bool; the
scene pickles back (what ``--jobs`` sends a worker: lfbench.runs.runner.ScoringTask) as ``type(scene)(*
scene.reopen_args())`` (:meth:`~lfbench.data.scene.Scene.reopen_args`, default ``(path, category)``) of the same
class, name, category, path and angular size. On the first :data:`VIEWS_CHECKED` selected scenes (their views
are read, one scene in memory at a time, released after): ``load_views()`` is float32 (V, U, H, W, 3) RGB or
(V, U, H, W) gray with (V, U) the angular size, finite and within [0, 1]; ``spatial_size`` is (H, W); where
``has_gt()``, ``gt_disparity()`` is a 2-D float (H, W) map with a finite value (at high resolution, where the
protocol scores it and the scene has it: an integer multiple of (H, W)).

An exception a plugin's scene raises is one line too (lfbench.data.dataset's plugin guard); a
:class:`~lfbench.utils.errors.LFBenchError` an adapter raises (a file it cannot read) is its own line, as
everywhere; lfbench's own adapters keep their tracebacks.
"""

from __future__ import annotations

import dataclasses
import pickle
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

from lfbench.data.dataset import DATASETS, Dataset, DatasetProtocol, _failure, _matches, _plugin
from lfbench.data.scene import HIGHRES, Scene
from lfbench.utils.errors import LFBenchError

__all__ = ["VIEWS_CHECKED", "AdapterCheck", "adapter_label", "check_adapter"]

#: How many of the selected scenes have their views and ground truth read by the check (the first ones): views
#: are big (81 HCI views of 512x512 px: 250 MB as float RGB), and an adapter reads every scene the same way.
VIEWS_CHECKED = 3

T = TypeVar("T")


class _Broken(Exception):
    """One broken promise of a scene (its message is the problem)."""


@dataclass(frozen=True)
class AdapterCheck:
    """What :func:`check_adapter` found: ``adapter`` (:func:`adapter_label`), the number of ``scenes`` checked and
    of those whose views were read, and one line per ``problems`` (none: the contract holds)."""

    adapter: str
    scenes: int
    views_read: int
    problems: tuple[str, ...]

    @property
    def holds(self) -> bool:
        """Whether no promise was broken."""
        return not self.problems

    def summary(self) -> str:
        """The line ``check-dataset`` prints when the contract holds."""
        return (f"adapter {self.adapter}: contract holds on {self.scenes} scene{'s' * (self.scenes != 1)} "
                f"(views and ground truth read on {self.views_read})")


def adapter_label(dataset: type[Dataset]) -> str:
    """``'name' (module.Class)``: how every line of the check names an adapter."""
    return (f"{getattr(dataset, 'name', '')!r} ({getattr(dataset, '__module__', '?')}."
            f"{getattr(dataset, '__qualname__', '?')})")


def check_adapter(dataset: type[Dataset], root: Path, protocol: DatasetProtocol, scenes: Sequence[Scene], *,
                  views_checked: int = VIEWS_CHECKED, progress: Callable[[Iterable[Scene]], Iterable[Scene]] = iter
                  ) -> AdapterCheck:
    """Check ``dataset``'s contract on the ``scenes`` it opened under ``root`` (``protocol``: the root's); the
    views of the first ``views_checked`` are read (``progress`` wraps the iteration of the scenes, e.g. a tqdm bar)."""
    label = adapter_label(dataset)
    problems = [f"adapter {label}: {p}" for p in _adapter_problems(dataset, root, protocol)]
    plugin = _plugin(dataset) is not None
    for i, scene in enumerate(progress(scenes)):
        try:
            problem = _scene_problem(scene, protocol, plugin, views=i < views_checked)
        finally:
            scene.release_views()  # one scene's views in memory at a time
        if problem is not None:
            problems.append(f"adapter {label}: {_scene_label(scene)}: {problem}")
    return AdapterCheck(label, len(scenes), min(len(scenes), views_checked), tuple(problems))


def _scene_label(scene: Scene) -> str:
    return f"scene {getattr(scene, 'name', '?')!r} ({getattr(scene, 'path', '?')})"


def _adapter_problems(dataset: type[Dataset], root: Path, protocol: DatasetProtocol) -> list[str]:
    """The adapter's own broken promises (its class attributes, protocols and ``matches``)."""
    problems = []
    name = getattr(dataset, "name", None)
    if not isinstance(name, str) or not name or name.split() != [name]:
        problems.append(f"name is {name!r}, expected a non-empty word (what --dataset takes)")
    elif DATASETS.find(name) is not dataset:
        problems.append(f"is not registered as {name!r} (its entry point in the group lfbench.datasets must be "
                        "named as its `name`)")
    for attr in ("summary", "layout"):
        value = getattr(dataset, attr, None)
        if not isinstance(value, str) or not value.strip() or "\n" in value:
            problems.append(f"{attr} is {value!r}, expected one line of text")
    for what, value in (("protocol", getattr(dataset, "protocol", None)), (f"protocol_for({root})", protocol)):
        problem = _protocol_problem(value)
        if problem is not None:
            problems.append(f"{what}: {problem}")
    failed: list[str] = []
    if not _matches(dataset, root, failed):  # lfbench.data.dataset's guard: what a plugin's matches() raised, one line
        why = f" ({failed[0]})" if failed else ""
        problems.append(f"matches({root}) did not return True on the root it opened{why}")
    return problems


def _protocol_problem(protocol: object) -> str | None:
    """Why ``protocol`` is not a valid DatasetProtocol (its own checks, and a declared angular size of two
    positive ints), or None."""
    if not isinstance(protocol, DatasetProtocol):
        return f"is a {type(protocol).__name__}, expected a lfbench.data.dataset.DatasetProtocol"
    try:
        dataclasses.replace(protocol)  # its __post_init__ checks, run again on the values it holds now
    except (TypeError, ValueError) as exc:
        return str(exc)
    if protocol.angular_size is not None and not _positive_pair(protocol.angular_size):
        return f"angular_size is {protocol.angular_size!r}, expected (rows, columns) of positive ints or None"
    return None


def _positive_pair(value: object) -> bool:
    return (isinstance(value, tuple) and len(value) == 2
            and all(isinstance(v, int | np.integer) and not isinstance(v, bool) and v > 0 for v in value))


def _scene_problem(scene: Scene, protocol: DatasetProtocol, plugin: bool, *, views: bool) -> str | None:
    """The first broken promise of ``scene`` (without reading its views unless ``views``), or None."""
    try:
        _check_scene(scene, protocol, plugin, views)
    except _Broken as exc:
        return str(exc)
    return None


def _call(plugin: bool, what: str, fn: Callable[[], T]) -> T:
    """``fn()``; where a plugin's scene raises (not a one-line LFBenchError), the problem ``<what> failed: ...``."""
    if not plugin:
        return fn()
    try:
        return fn()
    except LFBenchError:
        raise
    except Exception as exc:  # noqa: BLE001 - whatever the plugin's code raised: one line
        raise _Broken(_failure(what, exc)) from None


def _check_scene(scene: Scene, protocol: DatasetProtocol, plugin: bool, views: bool) -> None:
    angular = _call(plugin, "angular_size", lambda: scene.angular_size)
    if not _positive_pair(angular):
        raise _Broken(f"angular_size is {angular!r}, expected (rows, columns) of positive ints")
    angular = (int(angular[0]), int(angular[1]))
    if protocol.angular_size is not None and angular != tuple(protocol.angular_size):
        raise _Broken(f"angular_size is {angular}, the protocol declares {tuple(protocol.angular_size)}")
    has_gt = _call(plugin, "has_gt()", scene.has_gt)
    if not isinstance(has_gt, bool):
        raise _Broken(f"has_gt() returned a {type(has_gt).__name__}, expected a bool")
    _check_pickle(scene, plugin, angular)
    if not views:
        return
    size = _check_views(_call(plugin, "load_views()", scene.load_views), angular)
    spatial = _call(plugin, "spatial_size", lambda: scene.spatial_size)
    if not _positive_pair(spatial) or tuple(spatial) != size:
        raise _Broken(f"spatial_size is {spatial!r}, its views are {size}")
    if has_gt:
        _check_gt(_call(plugin, "gt_disparity()", scene.gt_disparity), size, 1, "gt_disparity()")
    if HIGHRES in protocol.resolutions and _call(plugin, "has_gt('highres')", lambda: scene.has_gt(HIGHRES)) is True:
        gt = _call(plugin, "gt_disparity('highres')", lambda: scene.gt_disparity(HIGHRES))
        scale = np.shape(gt)[0] // size[0] if np.ndim(gt) == 2 else 0
        _check_gt(gt, size, max(scale, 1), "gt_disparity('highres')")


def _check_pickle(scene: Scene, plugin: bool, angular: tuple[int, int]) -> None:
    """The scene survives what ``--jobs`` does to it: pickled to a worker, reopened there."""
    try:
        back = pickle.loads(pickle.dumps(scene))
    except LFBenchError:
        raise
    except Exception as exc:  # noqa: BLE001 - any scene's: a scene that does not travel is the finding
        rebuild = f"{type(scene).__name__}(*reopen_args())"
        raise _Broken(_failure(f"pickling to a --jobs worker (it is rebuilt as {rebuild})", exc)) from None
    got = {k: getattr(back, k, None) for k in ("name", "category", "path")}
    want = {k: getattr(scene, k, None) for k in got}
    if type(back) is not type(scene):
        raise _Broken(f"pickles back as a {type(back).__name__}, expected a {type(scene).__name__} (--jobs workers "
                      "rebuild a scene as type(scene)(*scene.reopen_args()))")
    for key in got:
        if got[key] != want[key]:
            raise _Broken(f"pickles back with {key} {got[key]!r}, expected {want[key]!r} (--jobs workers rebuild a "
                          f"scene as {type(scene).__name__}(*reopen_args()), default (path, category))")
    back_angular = _call(plugin, "angular_size (pickled back)", lambda: back.angular_size)
    if not _positive_pair(back_angular) or tuple(back_angular) != angular:
        raise _Broken(f"pickles back with angular_size {back_angular!r}, expected {angular}")


def _check_views(views: object, angular: tuple[int, int]) -> tuple[int, int]:
    """(H, W) of ``views`` when they are what ``load_views()`` promises."""
    v, u = angular
    expected = f"float32 ({v}, {u}, H, W, 3) RGB or ({v}, {u}, H, W) gray"
    if not isinstance(views, np.ndarray):
        raise _Broken(f"load_views() returned a {type(views).__name__}, expected a numpy array: {expected}")
    if views.ndim not in (4, 5) or views.shape[:2] != (v, u) or (views.ndim == 5 and views.shape[4] != 3) \
            or 0 in views.shape:
        raise _Broken(f"load_views() gave views of shape {views.shape}, expected {expected}")
    if views.dtype != np.float32:
        raise _Broken(f"load_views() gave {views.dtype} views, expected {expected} in [0, 1]")
    if not np.isfinite(views).all():
        raise _Broken(f"load_views() gave {int(np.count_nonzero(~np.isfinite(views)))} NaN or infinite values, "
                      "expected values in [0, 1]")
    lo, hi = float(views.min()), float(views.max())
    if lo < 0.0 or hi > 1.0:
        raise _Broken(f"load_views() gave values in [{lo:g}, {hi:g}], expected [0, 1] (8-bit: divide by 255)")
    return int(views.shape[2]), int(views.shape[3])


def _check_gt(gt: Any, size: tuple[int, int], scale: int, what: str) -> None:
    """``gt`` is a 2-D float map of ``scale`` times ``size`` with a finite value."""
    shape = (size[0] * scale, size[1] * scale)
    if not isinstance(gt, np.ndarray) or gt.ndim != 2 or not np.issubdtype(gt.dtype, np.floating):
        got = f"a {gt.dtype} array of shape {gt.shape}" if isinstance(gt, np.ndarray) else f"a {type(gt).__name__}"
        raise _Broken(f"{what} returned {got}, expected a float {shape} map")
    if gt.shape != shape:
        whose = "the views'" if scale == 1 else f"{scale} times the views'"
        raise _Broken(f"{what} is {gt.shape}, expected {shape} ({whose} (H, W))")
    if not np.isfinite(gt).any():
        raise _Broken(f"{what} has no finite value")
