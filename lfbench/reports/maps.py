"""Saved disparity maps of a run: written as predictions arrive (:class:`MapSaver`, the saving of
lfbench.reports.writers.Maps) and read back for reports: which folder holds each method's maps, one
scene's ground truth, evaluation mask, centre view and every method's map at low resolution
(:func:`load_scene_maps`), or the saved predictions themselves (:func:`saved_predictions`).

Maps are saved in the submission layout (``<maps>/<method>/disp_maps/<scene>.pfm``, runtimes beside)
by ``lfbench evaluate --save-maps`` (and ``--html``) and by ``lfbench demo``, and with uncertainty maps
(``uncertainty/<scene>.pfm``) by each ablation cell, so a report is rebuilt without re-running any method.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lfbench.data.disparity import EVALUATION_BORDER_PX
from lfbench.data.pfm import read_pfm, write_pfm
from lfbench.data.scene import LightField
from lfbench.data.submission import check_inside, find_disp_map, read_submission_map, write_submission_map
from lfbench.method.base import Prediction
from lfbench.reports.figures import disparity_range
from lfbench.scoring.prepare import SceneReference
from lfbench.scoring.rules import ScoringRules
from lfbench.utils.errors import DataError
from lfbench.utils.names import FileNames, file_names
from lfbench.utils.outputs import check_within

__all__ = ["MAPS_DIR", "UNCERTAINTY_DIR", "MapSaver", "SceneMaps", "load_scene_maps", "map_folders",
           "saved_predictions"]

MAPS_DIR = "maps"  # beside results.json
UNCERTAINTY_DIR = "uncertainty"  # beside disp_maps/, when the maps are saved with their uncertainty


class MapSaver:
    """Writes predictions in the submission layout under ``root``: ``<root>/<method>/disp_maps/<scene>.pfm``
    and ``runtimes/<scene>.txt`` (the label as a file name, lfbench.utils.names; two labels that would
    share a folder are refused), or with ``per_method=False`` one method's maps right in ``root``;
    ``uncertainty``: also ``uncertainty/<scene>.pfm`` where the prediction has one."""

    def __init__(self, root: Path, *, per_method: bool = True, uncertainty: bool = False) -> None:
        self.root, self.per_method, self.uncertainty = Path(root), per_method, uncertainty
        self._names = FileNames("method label")

    def save(self, label: str, scene: str, pred: Prediction) -> None:
        folder = self.root / self._names(label) if self.per_method else self.root
        write_submission_map(folder, scene, pred.disparity, pred.runtime_s)
        if self.uncertainty and pred.uncertainty is not None:
            write_pfm(folder / UNCERTAINTY_DIR / f"{scene}.pfm", np.asarray(pred.uncertainty, np.float32))


def map_folders(maps: str | Path, labels: Sequence[str], *, within: str | Path | None = None) -> dict[str, Path]:
    """Method label -> submission folder under ``maps`` (folder names as :class:`MapSaver` writes
    them, matched back to ``labels``); ``maps`` itself when it is one submission folder. DataError
    when it holds none, or when a folder leads out of ``maps`` (or ``maps`` out of ``within``, the
    results folder it was found in) through a symbolic link."""
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


def load_scene_maps(scene: LightField, folders: Mapping[str, str | Path],
                    border_px: int = EVALUATION_BORDER_PX) -> SceneMaps:
    """The scene's ground truth, mask and centre view and the saved map of every method in ``folders``
    that has one for it (methods without are left out)."""
    reference = SceneReference(scene, ScoringRules(border_px=border_px))
    gt = scene.gt_disparity()
    centre = np.clip(np.asarray(scene.center_view(), dtype=np.float32), 0, 1)
    if centre.ndim == 2:
        centre = np.repeat(centre[..., None], 3, axis=2)
    shape = tuple(gt.shape) if gt is not None else tuple(centre.shape[:2])
    preds = {}
    for label, folder in folders.items():
        if find_disp_map(folder, scene.name).is_file():
            disp, _ = read_submission_map(folder, scene.name, max_shape=shape)
            preds[label], _ = reference.align(disp, f"{label} on {scene.name}")
    first = next(iter(preds.values()), None)
    return SceneMaps(scene=scene, gt=gt, mask=reference.evaluation_mask(), centre=centre,
                     disp_range=disparity_range(scene, gt, first), preds=preds)


def saved_predictions(scenes: Sequence[LightField], folders: Mapping[str, str | Path],
                      within: Path | None = None) -> Iterator[tuple[str, LightField, Prediction]]:
    """(label, scene, prediction) of every saved map in ``folders`` (label -> submission folder), scene by
    scene: disparity, runtime and, when saved, the uncertainty map. Folders that do not exist are left
    out (a results/ copy keeps none); ``within``: the folder they must not lead out of (symbolic links)."""
    present = {label: Path(root) for label, root in folders.items() if Path(root).is_dir()}
    for root in present.values() if within is not None else ():
        check_within(root, within, "the ablation folder")
    for scene in scenes if present else ():
        for label, root in present.items():
            if not find_disp_map(root, scene.name).is_file():
                continue
            disp, runtime = read_submission_map(root, scene.name, max_shape=scene.spatial_size)
            unc_path = root / UNCERTAINTY_DIR / f"{scene.name}.pfm"
            unc = None
            if unc_path.is_file():
                check_inside(root, unc_path)
                unc = read_pfm(unc_path, max_shape=scene.spatial_size, what="uncertainty map")
            yield label, scene, Prediction(disparity=disp, uncertainty=unc, runtime_s=runtime)
