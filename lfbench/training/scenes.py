"""The scenes a training run reads: the synthetic sets it generates, the data roots it opens through the
dataset seam (lfbench.data.dataset: the layout of each root detected, or the adapter data.dataset names),
the training / validation selection, and the check of all of it before anything is generated or written."""

from __future__ import annotations

import logging
import os
import shutil
from collections.abc import Collection, Sequence
from dataclasses import dataclass, replace
from pathlib import Path

from lfbench.data.dataset import DATASETS, open_dataset
from lfbench.data.scene import Benchmark, Scene, check_scene_names
from lfbench.data.synth import ANGULAR as SYNTH_ANGULAR
from lfbench.data.synth import write_benchmark
from lfbench.data.synth_urbanlf import write_urbanlf
from lfbench.training.config import SyntheticSpec, TrainConfig, expand_path
from lfbench.training.validate import check_validation_area
from lfbench.utils.atomic import fresh_dir
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.hardware import available_cores


def _write_set(spec: SyntheticSpec, tmp: Path) -> None:
    """Write the scenes of ``spec`` into ``tmp/<category>`` in its layout."""
    h, w = spec.shape
    if spec.layout == "urbanlf-syn":
        first = spec.first_index()
        write_urbanlf(tmp, seed=spec.seed, width=w, height=h, scenes=spec.scenes, split=spec.category,
                      numbers=range(first, first + spec.scenes), workers=available_cores())
    else:
        write_benchmark(tmp, seed=spec.seed, size=spec.size, scenes=spec.scenes, category=spec.category,
                        workers=available_cores())


def prepare_synthetic(cfg: TrainConfig, data_dir: Path, log=logging.getLogger(__name__).info) -> None:
    """Generate each [[data.synthetic]] set in use (DataConfig.synthetic_in_use) into data_dir/<category>
    unless it is already there (generated in a temporary folder and renamed, so a killed run never leaves
    half a set)."""
    for spec in cfg.data.synthetic_in_use():
        target = data_dir / spec.category
        if target.is_dir():
            continue
        data_dir.mkdir(parents=True, exist_ok=True)
        h, w = spec.shape
        log(f"generating {spec.scenes} synthetic scenes ({w}x{h} px, {spec.layout} layout, seed {spec.seed}) "
            f"into {target}")
        tmp = fresh_dir(data_dir, f".{spec.category}.")
        try:
            _write_set(spec, tmp)
            produced = tmp / spec.category
            if not produced.is_dir():
                raise DataError(f"lfbench.data.synth wrote no {spec.category}/ folder", tmp)
            os.replace(produced, target)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)


def _real_roots(cfg: TrainConfig) -> list[Path]:
    return [expand_path(r, cfg.source) for r in cfg.data.roots]


def _open_roots(cfg: TrainConfig) -> list[Benchmark]:
    """The scenes of every configured root, each opened with data.dataset's adapter or the one its layout
    matches (DataError, one line, for a root of no known layout or of several)."""
    return [open_dataset(root, cfg.data.dataset)[1] for root in _real_roots(cfg)]


def _open_synthetic(data_dir: Path, specs: Sequence[SyntheticSpec]) -> list[Benchmark]:
    """The generated sets among ``specs`` under data_dir, only those generated already: data_dir opened by the
    adapter of each layout (lfbench.data.dataset.DATASETS), its scenes of those sets' categories."""
    there = [s for s in specs if (data_dir / s.category).is_dir()]
    out = []
    for layout in dict.fromkeys(s.layout for s in there):
        categories = {s.category for s in there if s.layout == layout}
        found = DATASETS.get(layout).open(data_dir)
        out.append(replace(found, scenes=tuple(s for s in found.scenes if s.category in categories)))
    return out


def _combine(benches: Sequence[Benchmark], root: Path, planned: Sequence[str] = ()) -> Benchmark:
    """One benchmark of the scenes of ``benches``; its splits: those of every part and of the adapters of the
    ``planned`` layouts (sets not generated yet: HCI's train / validation / test for HCI-layout sets)."""
    splits: dict[str, tuple[str, ...]] = {}
    for layout in planned:
        for name, cats in DATASETS.get(layout).splits.items():
            splits[name] = tuple(dict.fromkeys((*splits.get(name, ()), *cats)))
    for b in benches:
        for name, cats in b.splits.items():
            splits[name] = tuple(dict.fromkeys((*splits.get(name, ()), *cats)))
    return Benchmark(root=root, scenes=tuple(s for b in benches for s in b.scenes), splits=splits)


def discover(cfg: TrainConfig, data_dir: Path) -> Benchmark:
    """All scenes of the configured roots and the generated synthetic sets, as one benchmark."""
    benches = [*_open_roots(cfg), *_open_synthetic(data_dir, cfg.data.synthetic_in_use())]
    roots = _real_roots(cfg)
    return _combine(benches, roots[0] if roots else data_dir)


def select_scenes(bench: Benchmark, cfg: TrainConfig) -> tuple[list[Scene], list[Scene]]:
    """(training scenes, validation scenes) by the config's names (default: all with gt but validation)."""
    val = bench.select(list(cfg.data.validation)) if cfg.data.validation else []
    if cfg.data.train:
        train = bench.select(list(cfg.data.train))
    else:
        train = check_scene_names(s for s in bench.scenes if s not in val and s.has_gt())
    if not train:
        raise DataError("no training scenes selected", cfg.source)
    return train, val


@dataclass(frozen=True)
class PlannedScene:
    """A scene that a [[data.synthetic]] set will hold once generated: what scene selection and the
    validation-area check read of a scene."""

    name: str
    category: str
    path: Path
    spatial_size: tuple[int, int]
    angular_size: tuple[int, int] = (SYNTH_ANGULAR.default,) * 2  # what lfbench.data.synth writes in every layout

    def has_gt(self) -> bool:
        return True


def check_data(cfg: TrainConfig, data_dir: Path, renew: Collection[str] = ()) -> None:
    """The config's data checked before anything is generated or written: the roots hold scenes, every
    data.train / data.validation name selects scenes of them or of the synthetic sets in use, the
    validation border leaves pixels to score, data.invalid_area is a folder (DataError / SpecError).
    ``renew``: categories whose folder under data_dir is replaced before training (a stale link of an ablation
    cell, re-pointed): checked as planned, never read."""
    in_use = cfg.data.synthetic_in_use()
    to_write = [spec for spec in in_use if spec.category in renew or not (data_dir / spec.category).is_dir()]
    there = [spec for spec in in_use if spec not in to_write]
    bench = _combine([*_open_roots(cfg), *_open_synthetic(data_dir, there)], data_dir,  # generated before: a rerun
                     planned=[spec.layout for spec in to_write])
    planned = [PlannedScene(name, spec.category, data_dir / spec.category / name, spec.shape)
               for spec in to_write for name in spec.scene_names()]
    try:
        train, val = select_scenes(Benchmark(root=bench.root, scenes=(*bench.scenes, *planned),  # type: ignore[arg-type]
                                         splits=bench.splits), cfg)
    except DataError as exc:  # a name of the config that selects nothing: the config's error
        raise SpecError(f"[data] {exc.args[0]}", cfg.source) from None
    check_angular_size([*train, *val])
    check_validation_area(val, cfg.validation.border, cfg.validation.max_size, cfg.source)
    invalid_area(cfg)


def check_angular_size(scenes: Sequence[Scene | PlannedScene]) -> None:
    """DataError naming the first of ``scenes`` (a run's training, then validation scenes) whose views' angular size
    differs from the first's, and both sizes: one network takes them all. Read from what each adapter declares (no
    view is decoded), for scenes not generated yet (:class:`PlannedScene`) from what the generator writes."""
    for scene in scenes[1:]:
        first, (v, u) = scenes[0], scene.angular_size
        if (v, u) != first.angular_size:
            fv, fu = first.angular_size
            raise DataError(f"training scene {scene.name!r} has {u}x{v} views, the run's first scene {first.name!r} "
                            f"{fu}x{fv} ({first.path}): the scenes a run trains and validates on share one angular "
                            "size", scene.path)


def invalid_area(cfg: TrainConfig) -> Path | None:
    """The data.invalid_area folder (None when not given); DataError when it is not a folder."""
    path = expand_path(cfg.data.invalid_area, cfg.source) if cfg.data.invalid_area else None
    if path is not None and not path.is_dir():
        raise DataError("data.invalid_area folder not found", path)
    return path


__all__ = ["PlannedScene", "check_angular_size", "check_data", "discover", "invalid_area", "prepare_synthetic",
           "select_scenes"]
