"""The scenes a training run reads: the synthetic sets it generates, the HCI-layout roots it discovers, the
training / validation selection, and the check of all of it before anything is generated or written."""

from __future__ import annotations

import logging
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from lfbench.data.scene import Benchmark, Scene, check_scene_names
from lfbench.data.synth import write_benchmark
from lfbench.training.config import TrainConfig, expand_path
from lfbench.training.validate import check_validation_area
from lfbench.utils.atomic import fresh_dir
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.hardware import available_cores


def prepare_synthetic(cfg: TrainConfig, data_dir: Path, log=logging.getLogger(__name__).info) -> None:
    """Generate each [[data.synthetic]] set in use (DataConfig.synthetic_in_use) into data_dir/<category>
    unless it is already there (generated in a temporary folder and renamed, so a killed run never leaves
    half a set)."""
    for spec in cfg.data.synthetic_in_use():
        target = data_dir / spec.category
        if target.is_dir():
            continue
        data_dir.mkdir(parents=True, exist_ok=True)
        log(f"generating {spec.scenes} synthetic scenes ({spec.size} px, seed {spec.seed}) into {target}")
        tmp = fresh_dir(data_dir, f".{spec.category}.")
        try:
            write_benchmark(tmp, seed=spec.seed, size=spec.size, scenes=spec.scenes, category=spec.category,
                            workers=available_cores())
            produced = tmp / spec.category
            if not produced.is_dir():
                raise DataError(f"lfbench.data.synth wrote no {spec.category}/ folder", tmp)
            os.replace(produced, target)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)


def _roots(cfg: TrainConfig, data_dir: Path) -> list[Path]:
    roots = [expand_path(r, cfg.source) for r in cfg.data.roots]
    return [*roots, data_dir] if cfg.data.synthetic_in_use() else roots


def discover(cfg: TrainConfig, data_dir: Path) -> Benchmark:
    """All scenes of the configured roots and the generated synthetic sets, as one benchmark."""
    roots = _roots(cfg, data_dir)
    scenes: list[Scene] = []
    for root in roots:
        scenes += Benchmark.discover(root).scenes
    return Benchmark(root=roots[0], scenes=tuple(scenes))


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

    def has_gt(self) -> bool:
        return True


def check_data(cfg: TrainConfig, data_dir: Path) -> None:
    """The config's data checked before anything is generated or written: the roots hold scenes, every
    data.train / data.validation name selects scenes of them or of the synthetic sets in use, the
    validation border leaves pixels to score, data.invalid_area is a folder (DataError / SpecError)."""
    roots = _roots(cfg, data_dir)
    real = [s for r in roots if r != data_dir for s in Benchmark.discover(r).scenes]
    in_use = cfg.data.synthetic_in_use()
    if in_use and any(p.is_dir() for p in data_dir.glob("*")):  # generated before (a resumed or re-run folder)
        real += Benchmark.discover(data_dir).scenes
    planned = [PlannedScene(name, spec.category, data_dir / spec.category / name, (spec.size, spec.size))
               for spec in in_use if not (data_dir / spec.category).is_dir() for name in spec.scene_names()]
    try:
        _, val = select_scenes(Benchmark(root=roots[0], scenes=(*real, *planned)), cfg)  # type: ignore[arg-type]
    except DataError as exc:  # a name of the config that selects nothing: the config's error
        raise SpecError(f"[data] {exc.args[0]}", cfg.source) from None
    check_validation_area(val, cfg.validation.border, cfg.validation.max_size, cfg.source)
    invalid_area(cfg)


def invalid_area(cfg: TrainConfig) -> Path | None:
    """The data.invalid_area folder (None when not given); DataError when it is not a folder."""
    path = expand_path(cfg.data.invalid_area, cfg.source) if cfg.data.invalid_area else None
    if path is not None and not path.is_dir():
        raise DataError("data.invalid_area folder not found", path)
    return path


__all__ = ["PlannedScene", "check_data", "discover", "invalid_area", "prepare_synthetic", "select_scenes"]
