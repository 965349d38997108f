"""A held-out dataset plugin for the tests: a layout lfbench's own code knows nothing of, written only against
the public adapter contract (lfbench.data.dataset.Dataset, lfbench.data.scene.Scene: no private name
overridden).

Layout: ``ROOT/npy7.toml`` (the marker; empty) and ``ROOT/<category>/<scene>.views.npy``: the 7x7 views as
uint8 RGB (7, 7, H, W, 3), ``[r, c]`` the view at angular row r, column c; beside it ``<scene>.disp.npy``, the
centre view's disparity (H, W) float32 in px per view step (HCI's sign). Scored with a 4 px border, BadPix 0.07
and MSE x100, disparity searched in [-2, 2] px.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from lfbench.data.dataset import Dataset, DatasetProtocol
from lfbench.data.scene import LOWRES, Benchmark, Scene, check_scene_names
from lfbench.utils.errors import DataError

MARKER = "npy7.toml"
VIEWS, DISPARITY = ".views.npy", ".disp.npy"
ANGULAR = 7

NPY7_PROTOCOL = DatasetProtocol(border_px=4, metrics=("badpix_0.07", "mse_x100"), disparity_range=(-2.0, 2.0),
                                angular_size=(ANGULAR, ANGULAR), reference_view="centre view [3, 3]")


def write_npy7_scene(root: Path, name: str, category: str, views: np.ndarray, disparity: np.ndarray) -> Path:
    """Write one scene of this layout: ``views`` (7, 7, H, W, 3) uint8, ``disparity`` (H, W) float32."""
    folder = Path(root) / category
    folder.mkdir(parents=True, exist_ok=True)
    (Path(root) / MARKER).touch()
    np.save(folder / f"{name}{VIEWS}", np.asarray(views, dtype=np.uint8))
    np.save(folder / f"{name}{DISPARITY}", np.asarray(disparity, dtype=np.float32))
    return folder / f"{name}{VIEWS}"


class Npy7Scene(Scene):
    """One ``<scene>.views.npy`` (its header read when opened, its pixels when asked for)."""

    def __init__(self, path: str | Path, category: str = "other") -> None:
        self.path = Path(path)
        self.name = self.path.name.removesuffix(VIEWS)
        self.category = category
        views = np.load(self.path, mmap_mode="r")  # the header only
        if views.ndim != 5 or views.shape[:2] != (ANGULAR, ANGULAR) or views.shape[4] != 3:
            raise DataError(f"views are {views.shape}, expected (7, 7, H, W, 3)", self.path)
        self._shape = tuple(views.shape[2:4])

    @property
    def angular_size(self) -> tuple[int, int]:
        return ANGULAR, ANGULAR

    @property
    def spatial_size(self) -> tuple[int, int]:
        return self._shape

    def load_views(self) -> np.ndarray:
        return np.load(self.path).astype(np.float32) / np.float32(255.0)

    @property
    def _gt_path(self) -> Path:
        return self.path.with_name(self.name + DISPARITY)

    def has_gt(self, resolution: str = LOWRES) -> bool:
        return resolution == LOWRES and self._gt_path.is_file()

    def gt_disparity(self, resolution: str = LOWRES) -> np.ndarray | None:
        return np.load(self._gt_path).astype(np.float32) if self.has_gt(resolution) else None


class Npy7Dataset(Dataset):
    """7x7 views, one .npy per scene."""

    name = "npy7"
    summary = "7x7 views stored as one .npy per scene (a test plugin)"
    layout = f"ROOT/{MARKER} and ROOT/<category>/<scene>{VIEWS} with <scene>{DISPARITY}"
    protocol = NPY7_PROTOCOL

    @classmethod
    def matches(cls, root: Path) -> bool:
        return (Path(root) / MARKER).is_file()

    @classmethod
    def open(cls, root: Path) -> Benchmark:
        root = Path(root)
        scenes = [Npy7Scene(p, p.parent.name) for p in sorted(root.glob(f"*/*{VIEWS}"))]
        if not scenes:
            raise DataError(f"no <category>/<scene>{VIEWS} files", root)
        return Benchmark(root=root, scenes=tuple(check_scene_names(scenes)))
