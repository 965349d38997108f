"""Synthetic scenes written in the UrbanLF-Syn layout (``lfbench synth --layout urbanlf-syn``), with exact
ground truth, for tests and demos of non-square light fields.

Each scene is :func:`lfbench.data.synth.generate_scene` rendered square at max(W, H) px and cropped to the
centre H x W px (lfbench.data.synth.SyntheticScene.crop): the same window in every view, so the disparity
between views is unchanged and the centre view's ground truth stays exact. The scenes go the way of every
generated layout, :func:`lfbench.data.synth.write_scenes` (``--workers`` at a time, each written by the
adapter's :meth:`lfbench.data.urbanlf.UrbanLFSyn.write_scene`); this module names and checks them. Written as
``OUT/<split>/Image<k>/`` with 9x9 views ``u_v.png`` (u = angular row, v = column, 1..9), the centre view's
``5_5_disparity.npy`` and ``5_5_depth.npy`` (float32, px per view step and m); the other views' disparity files of
the released data are not written (lfbench scores the centre view). The scenes' disparities are mapped into
UrbanLF-Syn's released range [-0.47, 1.55] px (:data:`lfbench.data.urbanlf.URBANLF_DISPARITY_RANGE`;
``disparity_range`` sets another), so that a method searching the dataset's grid ([-0.5, 1.6] at 0.1 px) can be
right everywhere.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from lfbench.data.synth import check_args, disparity_map, scene_seed, write_scenes
from lfbench.data.urbanlf import ANGULAR, URBANLF_DISPARITY_RANGE, UrbanLFSyn
from lfbench.utils.errors import DataError, SpecError

__all__ = ["write_urbanlf"]


def write_urbanlf(out: str | Path, *, seed: int = 0, width: int = 640, height: int = 480, scenes: int = 2,
                  split: str = "val", force: bool = False, numbers: Sequence[int] | None = None,
                  disparity_range: tuple[float, float] | None = URBANLF_DISPARITY_RANGE, workers: int = 1,
                  progress: bool = False) -> list[Path]:
    """Write ``scenes`` scenes as ``OUT/<split>/Image<i>/`` (i = 1..K, or the sample ``numbers``, e.g. the
    paper's Table III samples 11, 27, ...: then K = len(numbers)) and return their folders. Disparities
    within ``disparity_range`` (default UrbanLF-Syn's released [-0.47, 1.55] px; None: the generator's own).
    An existing sample folder is an error unless ``force`` (all are checked before anything is generated).
    ``workers`` > 1 writes that many at a time in worker processes (the files are the same)."""
    for side in (width, height):
        check_args(side, ANGULAR)
    disparity_map(disparity_range)  # SpecError for an impossible range, before anything is written
    check_args(max(width, height), ANGULAR)
    if not split or split in (".", "..") or "/" in split or "\\" in split:
        raise SpecError(f"invalid split name {split!r}")
    if int(scenes) != scenes or scenes < 1:
        raise SpecError(f"scenes must be a positive integer, got {scenes}")
    if int(workers) != workers or workers < 1:
        raise SpecError(f"workers must be a positive integer, got {workers}")
    if numbers is not None:
        numbers = list(numbers)
        if not numbers or any(int(n) != n or n < 1 for n in numbers) or len(set(numbers)) != len(numbers):
            raise SpecError(f"sample numbers must be distinct positive integers, got {numbers}")
    targets = [Path(out) / split / f"Image{n}" for n in (numbers or range(1, scenes + 1))]
    if not force:
        for t in targets:
            if t.exists():
                raise DataError("sample folder already exists (use --force to overwrite)", t)
    return write_scenes(targets, [scene_seed(seed, i) for i in range(len(targets))], size=(width, height),
                        angular=ANGULAR, layout=UrbanLFSyn.name, disparity_range=disparity_range, workers=workers,
                        progress=progress)
