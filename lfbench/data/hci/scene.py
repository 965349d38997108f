"""The HCI 4D Light Field Benchmark's scene folders: ``parameters.cfg``, views ``input_Cam000.png`` ..
``input_Cam080.png`` (row-major: ``views[v, u]`` is ``input_Cam{v * U + u:03d}.png``), ground truth
``gt_disp_lowres.pfm`` / ``gt_disp_highres.pfm`` (PFM), evaluation masks ``<name>_lowres.png`` /
``<name>_highres.png``, ``valid_mask.png``; and the benchmark's categories and the paper's splits.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np

from lfbench.data.hci.params import SceneParameters, read_parameters
from lfbench.data.pfm import read_pfm
from lfbench.data.scene import LOWRES, Benchmark, PNGScene, read_mask
from lfbench.utils.errors import DataError

__all__ = ["CATEGORIES", "SPLITS", "PARAMETERS_FILE", "HCIScene", "discover", "is_scene_folder",
           "view_file_name", "gt_file_name", "depth_file_name", "mask_file_name"]

CATEGORIES = ("stratified", "training", "test", "additional")
#: The paper's splits of the HCI categories.
SPLITS: dict[str, tuple[str, ...]] = {
    "train": ("additional",),
    "validation": ("stratified", "training"),
    "test": ("test",),
}
PARAMETERS_FILE = "parameters.cfg"


def view_file_name(k: int) -> str:
    """The file of view ``k`` (row-major, 0-based): ``input_Cam{k:03d}.png``."""
    return f"input_Cam{k:03d}.png"


def gt_file_name(resolution: str = LOWRES) -> str:
    """The ground-truth disparity file at ``resolution``: ``gt_disp_<resolution>.pfm``."""
    return f"gt_disp_{resolution}.pfm"


def depth_file_name(resolution: str = LOWRES) -> str:
    """The ground-truth depth file (m) at ``resolution``: ``gt_depth_<resolution>.pfm``."""
    return f"gt_depth_{resolution}.pfm"


def mask_file_name(name: str, resolution: str = LOWRES) -> str:
    """The evaluation mask ``name`` at ``resolution``: ``<name>_<resolution>.png``."""
    return f"{name}_{resolution}.png"


_MASK_RE = re.compile(r"^(?P<name>.+)_(?P<res>lowres|highres)\.png$")
_NOT_MASKS = {"gt_disp", "gt_depth", "input_Cam040", "stratified_masks"}


def is_scene_folder(folder: Path) -> bool:
    """Whether ``folder`` is an HCI scene folder (it holds ``parameters.cfg``)."""
    return (folder / PARAMETERS_FILE).is_file()

#: SubFocal's training masks of the areas to leave out, one per scene (``<data.invalid_area>/<scene>/<file>``).
INVALID_AREA_FILE = "input_Cam040_invalid_ver2.png"


class HCIScene(PNGScene):
    """An HCI scene folder, loaded lazily: nothing is read until asked for but ``parameters.cfg``."""

    size_said = "parameters.cfg says"
    invalid_area_file = INVALID_AREA_FILE  # SubFocal's training masks of the areas to leave out

    def __init__(self, path: str | Path, category: str | None = None) -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise DataError("scene folder not found", self.path)
        try:  # a name that is not UTF-8 cannot be written to results.csv, tables or submissions
            self.path.name.encode("utf-8")
        except UnicodeEncodeError:
            raise DataError("scene folder name is not valid UTF-8: rename the folder",
                            os.fsencode(self.path).decode("utf-8", "backslashreplace")) from None
        self.params: SceneParameters = read_parameters(self.path / PARAMETERS_FILE)
        self.name = self.path.name
        self.category = category or self.params.category or "other"

    @property
    def angular_size(self) -> tuple[int, int]:
        return self.params.angular_size

    @property
    def spatial_size(self) -> tuple[int, int]:
        return self.params.spatial_size

    def view_path(self, k: int) -> Path:
        return self.path / view_file_name(k)

    def check_views(self) -> None:
        v, u = self.angular_size
        missing = [k for k in range(v * u) if not os.path.lexists(self.view_path(k))]  # a FIFO: refused when read
        if missing:
            shown = ", ".join(self.view_path(k).name for k in missing[:3])
            more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
            raise DataError(f"missing {len(missing)} of {v * u} views: {shown}{more}", self.path)

    def view_file(self, row: int, col: int) -> Path:
        return self.view_path(row * self.angular_size[1] + col)

    def has_gt(self, resolution: str = LOWRES) -> bool:
        """Whether the ground-truth file is there: anything under its name counts (a folder, FIFO or broken link
        there is an error when read, never a scene left out of the mean)."""
        return os.path.lexists(self.path / gt_file_name(resolution))

    def gt_disparity(self, resolution: str = LOWRES) -> np.ndarray | None:
        """Ground-truth disparity (H, W) float32 at ``resolution``, or None if the file is absent."""
        path = self.path / gt_file_name(resolution)
        if not os.path.lexists(path):
            return None
        h, w = self.spatial_size
        scale = 1 if resolution == LOWRES else self.params.highres_scale
        gt = read_pfm(path, shape=(h * scale, w * scale), what="ground truth")  # checked before the data is read
        if gt.ndim != 2:
            raise DataError("ground truth is a 3-channel PF map, expected a gray Pf map", path)
        bad = int(np.count_nonzero(~np.isfinite(gt)))
        if bad:
            raise DataError(f"ground truth has {bad} non-finite values of {gt.size} (NaN or inf): it cannot be "
                            "scored against", path)
        return gt

    def mask_names(self, resolution: str = LOWRES) -> list[str]:
        """Names of the evaluation masks present at ``resolution`` (``<name>_<resolution>.png``)."""
        names = []
        for p in sorted(self.path.glob(f"*_{resolution}.png")):
            m = _MASK_RE.match(p.name)
            if m and m["name"] not in _NOT_MASKS:
                names.append(m["name"])
        return names

    def mask(self, name: str, resolution: str = LOWRES) -> np.ndarray:
        """Evaluation mask ``<name>_<resolution>.png`` as bool (H, W)."""
        path = self.path / mask_file_name(name, resolution)
        if not path.is_file():
            raise DataError(f"no mask {name!r} at {resolution}", path)
        h, w = self.spatial_size
        scale = 1 if resolution == LOWRES else self.params.highres_scale
        return read_mask(path, size=(h * scale, w * scale))

    def valid_mask(self) -> np.ndarray | None:
        """valid_mask.png as bool (H, W) (True = pixel may be scored), or None if absent. It is at the
        scene's low resolution (parameters.cfg): any other size is refused (DataError naming the file);
        high-resolution scoring upsamples it as it upsamples predictions (lfbench.scoring.rules)."""
        path = self.path / "valid_mask.png"
        return read_mask(path, size=self.spatial_size) if path.is_file() else None


def discover(root: str | Path) -> Benchmark:
    """The HCI scenes under ``root``: ROOT/<category>/<scene>/, a folder of scenes (category 'other') or
    one scene; category folders other than :data:`CATEGORIES` keep their own name. Splits: :data:`SPLITS`."""
    root = Path(root)
    if not root.is_dir():
        raise DataError("data root not found", root)
    scenes = []
    if is_scene_folder(root):  # the root is itself one scene
        scenes.append(HCIScene(root))
    else:
        for cat_dir in sorted(p for p in root.iterdir() if p.is_dir()):
            if is_scene_folder(cat_dir):  # a flat folder of scenes
                scenes.append(HCIScene(cat_dir, category="other"))
                continue
            for scene_dir in sorted(p for p in cat_dir.iterdir() if p.is_dir()):
                if is_scene_folder(scene_dir):
                    scenes.append(HCIScene(scene_dir, category=cat_dir.name))
    if not scenes:
        raise DataError(f"no scenes found (expected <root>/<category>/<scene>/{PARAMETERS_FILE})", root)
    return Benchmark(root=root, scenes=tuple(scenes), splits=SPLITS)
