"""Synthetic scenes written in the UrbanLF-Syn layout (``lfbench synth --layout urbanlf-syn``), with exact
ground truth, for tests and demos of non-square light fields.

Each scene is :func:`lfbench.data.synth.generate_scene` rendered square at max(W, H) px and cropped to the
centre H x W px: the same window in every view, so the disparity between views is unchanged and the
centre view's ground truth stays exact. Written as ``OUT/<split>/Image<k>/`` with 9x9 views ``u_v.png``
(u = angular row, v = column, 1..9), the centre view's ``5_5_disparity.npy`` and ``5_5_depth.npy``
(float32, px per view step and m); the other views' disparity files of the released data are not written
(lfbench scores the centre view). The scenes' disparities are mapped into UrbanLF-Syn's released range
[-0.47, 1.55] px (:data:`lfbench.data.urbanlf.URBANLF_DISPARITY_RANGE`; ``disparity_range`` sets another), so
that a method searching the dataset's grid ([-0.5, 1.6] at 0.1 px) can be right everywhere.
"""

from __future__ import annotations

import io
import shutil
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lfbench.data.scene import png_bytes
from lfbench.data.synth import check_args, disparity_map, generate_scene, quantize, scene_seed
from lfbench.data.urbanlf import ANGULAR, URBANLF_DISPARITY_RANGE, depth_name, gt_name, view_name
from lfbench.utils.atomic import fresh_dir, replace_dir, write_bytes
from lfbench.utils.errors import DataError, SpecError

__all__ = ["write_urbanlf", "write_urbanlf_scene"]


def _npy_bytes(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(array, dtype=np.float32), allow_pickle=False)
    return buf.getvalue()


def write_urbanlf_scene(folder: str | Path, seed: int, width: int, height: int, *,
                        disparity_range: tuple[float, float] | None = URBANLF_DISPARITY_RANGE) -> Path:
    """Generate one 9x9 scene of ``width`` x ``height`` px, its disparities within ``disparity_range`` (min,
    max) px (None: the generator's own), and write it as the sample folder ``folder`` (written beside it,
    renamed into place when whole)."""
    folder = Path(folder)
    size = max(width, height)
    scene = generate_scene(seed, size=size, angular=ANGULAR, name=folder.name, category=folder.parent.name,
                           disparity_range=disparity_range)
    y0, x0 = (size - height) // 2, (size - width) // 2
    crop = (slice(y0, y0 + height), slice(x0, x0 + width))
    q = quantize(scene.views[:, :, crop[0], crop[1]])
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = fresh_dir(folder.parent, f".{folder.name}.", ".tmp")
    try:
        for r in range(ANGULAR):
            for c in range(ANGULAR):
                write_bytes(tmp / view_name(r + 1, c + 1), png_bytes(q[r, c]))
        write_bytes(tmp / gt_name(), _npy_bytes(scene.disparity[crop]))
        write_bytes(tmp / depth_name(), _npy_bytes(scene.depth[crop]))
        replace_dir(tmp, folder)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return folder


def write_urbanlf(out: str | Path, *, seed: int = 0, width: int = 640, height: int = 480, scenes: int = 2,
                  split: str = "val", force: bool = False, numbers: Sequence[int] | None = None,
                  disparity_range: tuple[float, float] | None = URBANLF_DISPARITY_RANGE) -> list[Path]:
    """Write ``scenes`` scenes as ``OUT/<split>/Image<i>/`` (i = 1..K, or the sample ``numbers``, e.g. the
    paper's Table III samples 11, 27, ...: then K = len(numbers)) and return their folders. Disparities
    within ``disparity_range`` (default UrbanLF-Syn's released [-0.47, 1.55] px; None: the generator's own).
    An existing sample folder is an error unless ``force`` (all are checked before anything is generated)."""
    for side in (width, height):
        check_args(side, ANGULAR)
    disparity_map(disparity_range)  # SpecError for an impossible range, before anything is written
    check_args(max(width, height), ANGULAR)
    if not split or split in (".", "..") or "/" in split or "\\" in split:
        raise SpecError(f"invalid split name {split!r}")
    if int(scenes) != scenes or scenes < 1:
        raise SpecError(f"scenes must be a positive integer, got {scenes}")
    if numbers is not None:
        numbers = list(numbers)
        if not numbers or any(int(n) != n or n < 1 for n in numbers) or len(set(numbers)) != len(numbers):
            raise SpecError(f"sample numbers must be distinct positive integers, got {numbers}")
    targets = [Path(out) / split / f"Image{n}" for n in (numbers or range(1, scenes + 1))]
    if not force:
        for t in targets:
            if t.exists():
                raise DataError("sample folder already exists (use --force to overwrite)", t)
    return [write_urbanlf_scene(t, scene_seed(seed, i), width, height, disparity_range=disparity_range)
            for i, t in enumerate(targets)]
