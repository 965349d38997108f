"""Saved disparity maps of a run, read back for reports: which folder holds each method's maps, and
one scene's ground truth, evaluation mask, centre view and every method's map at low resolution.

Maps are saved in the submission layout (``<maps>/<method>/disp_maps/<scene>.pfm``, runtimes beside)
by ``lfbench evaluate --save-maps`` (and ``--html``) and by ``lfbench demo``, so a report is rebuilt
without re-running any method.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lfbench.data.scene import LightField
from lfbench.utils.errors import DataError

__all__ = ["MAPS_DIR", "SceneMaps", "load_scene_maps", "map_folders"]

MAPS_DIR = "maps"  # beside results.json


def map_folders(maps: str | Path, labels: Sequence[str], *, within: str | Path | None = None) -> dict[str, Path]:
    """Method label -> submission folder under ``maps`` (folder names as ``save_prediction`` writes
    them, matched back to ``labels``); ``maps`` itself when it is one submission folder. DataError
    when it holds none, or when a folder leads out of ``maps`` (or ``maps`` out of ``within``, the
    results folder it was found in) through a symbolic link."""
    from lfbench.runs.outputs import check_within
    from lfbench.utils.names import file_names

    maps = Path(maps)
    if within is not None and (maps.exists() or maps.is_symlink()):
        check_within(maps, within, "the results folder")
    if (maps / "disp_maps").is_dir():
        return {maps.name: maps}
    folders = {p.name: p for p in sorted(maps.iterdir()) if (p / "disp_maps").is_dir()} if maps.is_dir() else {}
    if not folders:
        raise DataError("no saved maps found (expected <method>/disp_maps/<scene>.pfm)", maps)
    for folder in folders.values():
        check_within(folder, maps, "the maps folder")
    by_name = {name: label for label, name in file_names(labels, "method label").items()}
    return {by_name.get(name, name): path for name, path in folders.items()}


@dataclass
class SceneMaps:
    """One scene at low resolution: ``gt`` (H, W) px or None, evaluation ``mask`` (H, W) bool,
    ``centre`` view (H, W, 3) in [0, 1], colour range ``disp_range`` (px) and ``preds``: method label
    -> (H, W) float32 disparity aligned to the scene."""

    scene: LightField
    gt: np.ndarray | None
    mask: np.ndarray
    centre: np.ndarray
    disp_range: tuple[float, float]
    preds: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def name(self) -> str:
        return self.scene.name


def load_scene_maps(scene: LightField, folders: Mapping[str, str | Path], border_px: int = 15) -> SceneMaps:
    """The scene's ground truth, mask and centre view and the saved map of every method in ``folders``
    that has one for it (methods without are left out)."""
    from lfbench.data.submission import disp_map_path, read_submission_map
    from lfbench.reports.figures import disparity_range
    from lfbench.scoring.prepare import SceneReference
    from lfbench.scoring.rules import ScoringRules

    reference = SceneReference(scene, ScoringRules(border_px=border_px))
    gt = scene.gt_disparity()
    centre = np.clip(np.asarray(scene.center_view(), dtype=np.float32), 0, 1)
    if centre.ndim == 2:
        centre = np.repeat(centre[..., None], 3, axis=2)
    shape = tuple(gt.shape) if gt is not None else tuple(centre.shape[:2])
    preds = {}
    for label, folder in folders.items():
        if disp_map_path(folder, scene.name).is_file():
            disp, _ = read_submission_map(folder, scene.name, max_shape=shape)
            preds[label], _ = reference.align(disp, f"{label} on {scene.name}")
    first = next(iter(preds.values()), None)
    return SceneMaps(scene=scene, gt=gt, mask=reference.evaluation_mask(), centre=centre,
                     disp_range=disparity_range(scene, gt, first), preds=preds)
