"""UrbanLF-Syn (the LFNAT 2023 depth challenge's synthetic urban set) as a dataset adapter (``urbanlf-syn``).

Layout as released: ``ROOT/<split>/ImageN/`` for the splits train / val / test, one folder per sample,
views ``u_v.png`` with u, v = 1..9 (``5_5.png`` the centre view), per-view disparity ``u_v_disparity.npy``
(and depth / label files beside them, not read); the test split comes without disparity. ROOT may also be
one split folder or one sample folder. lfbench reads ``u_v.png`` as angular row u, column v (top to
bottom, left to right) and scores the centre view's ``5_5_disparity.npy`` (px per view step, read as the
HCI sign: positive = nearer than the focus plane). docs/datasets.md gives what public sources say about
these conventions and where they are silent.

Protocol (the challenge's): centre view, 15 px border, BadPix 0.01 / 0.03 / 0.07 and MSE x100, 640x480
views, disparity searched in [-0.5, 1.6] px (the released range is [-0.47, 1.55]).

Every scene is checked when it is opened (no pixel decoded: PNG headers and the .npy header only): the 81
views present, no other ``u_v.png``, all of one size; the ground truth (H, W) of the views' size and finite
when it is read. Each problem is one DataError naming the file.
"""

from __future__ import annotations

import functools
import re
from pathlib import Path

import numpy as np
from PIL import Image

from lfbench.data.dataset import Dataset, DatasetProtocol
from lfbench.data.npyfile import read_npy
from lfbench.data.scene import LOWRES, Benchmark, LightField, check_scene_names, read_rgb, rgb_to_gray
from lfbench.utils.errors import DataError

__all__ = ["URBANLF_PROTOCOL", "URBANLF_SPLITS", "UrbanLFScene", "UrbanLFSyn", "view_name", "gt_name"]

ANGULAR = 9
CENTRE = 5  # 1-based index of the centre view along each axis
URBANLF_SPLITS = ("train", "val", "test")
_VIEW_RE = re.compile(r"^(\d+)_(\d+)\.png$")

URBANLF_PROTOCOL = DatasetProtocol(
    border_px=15, metrics=("badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100"),
    disparity_range=(-0.5, 1.6), spatial_size=(480, 640), angular_size=(ANGULAR, ANGULAR),
    reference_view="centre view 5_5.png")


def view_name(row: int, col: int) -> str:
    """The file of the view at 1-based angular row ``row``, column ``col``: ``'<row>_<col>.png'``."""
    return f"{row}_{col}.png"


def gt_name(row: int = CENTRE, col: int = CENTRE) -> str:
    """The disparity file of a view (default the centre's): ``'<row>_<col>_disparity.npy'``."""
    return f"{row}_{col}_disparity.npy"


def _png_size(path: Path) -> tuple[int, int]:
    """(H, W) of a PNG from its header; DataError naming the file when it is not a readable PNG."""
    try:
        with Image.open(path) as img:
            w, h = img.size
            if img.format != "PNG":
                raise DataError(f"view is a {img.format} file, expected a PNG", path)
    except (OSError, ValueError, SyntaxError) as exc:
        raise DataError(f"cannot read view image: {' '.join(str(exc).split())[:120]}", path) from None
    return h, w


class UrbanLFScene(LightField):
    """One UrbanLF-Syn sample folder (``ImageN/``), checked when made, its pixels read when asked for."""

    def __init__(self, path: str | Path, category: str = "other") -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise DataError("sample folder not found", self.path)
        self.name = self.path.name
        self.category = category
        self.params = None  # no camera parameters file: the metrics that need one do not apply
        self.spatial_size = self._check_views()
        self._check_gt_header()

    def __repr__(self) -> str:
        return f"UrbanLFScene({self.category}/{self.name})"

    @property
    def angular_size(self) -> tuple[int, int]:
        return ANGULAR, ANGULAR

    def view_path(self, row: int, col: int) -> Path:
        """The file of the view at 0-based angular row ``row``, column ``col``."""
        return self.path / view_name(row + 1, col + 1)

    def _check_views(self) -> tuple[int, int]:
        """(H, W) of the views; DataError for a missing, unexpected or differently sized view."""
        expected = {view_name(r, c) for r in range(1, ANGULAR + 1) for c in range(1, ANGULAR + 1)}
        present = {p.name for p in self.path.iterdir() if _VIEW_RE.match(p.name)}
        extra = sorted(present - expected)
        if extra:
            raise DataError(f"unexpected view {extra[0]} (UrbanLF-Syn has views 1_1.png .. 9_9.png)",
                            self.path / extra[0])
        missing = sorted(expected - present, key=lambda n: tuple(int(x) for x in n[:-4].split("_")))
        if missing:
            more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
            raise DataError(f"missing {len(missing)} of {len(expected)} views: {', '.join(missing[:3])}{more}",
                            self.path)
        centre = self.path / view_name(CENTRE, CENTRE)
        size = _png_size(centre)
        for r in range(ANGULAR):
            for c in range(ANGULAR):
                path = self.view_path(r, c)
                got = _png_size(path)
                if got != size:
                    raise DataError(f"view is {got[1]}x{got[0]}, the centre view {centre.name} is {size[1]}x{size[0]}",
                                    path)
        return size

    @property
    def gt_path(self) -> Path:
        return self.path / gt_name()

    def _gt_problem(self, shape: tuple[int, ...], dtype: np.dtype) -> str | None:
        h, w = self.spatial_size
        if shape != (h, w):
            return f"ground truth has shape {shape}, expected ({h}, {w}) (the views' H, W)"
        if dtype.kind != "f":
            return f"ground truth is {dtype}, expected a float array of disparities"
        return None

    def _check_gt_header(self) -> None:
        """The ground truth's shape and dtype, from its .npy header (its data is read when scored)."""
        if not self.gt_path.is_file():
            return
        try:
            with open(self.gt_path, "rb") as f:
                version = np.lib.format.read_magic(f)
                read = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                        else np.lib.format.read_array_header_2_0)
                shape, _, dtype = read(f, max_header_size=10000)
        except (ValueError, OSError, EOFError, SyntaxError, TypeError):
            raise DataError("cannot read .npy: bad magic or header", self.gt_path) from None
        problem = self._gt_problem(tuple(shape), dtype)
        if problem:
            raise DataError(problem, self.gt_path)

    def has_gt(self, resolution: str = LOWRES) -> bool:
        return resolution == LOWRES and self.gt_path.is_file()

    @functools.cached_property
    def _gt(self) -> np.ndarray | None:
        if not self.gt_path.is_file():
            return None
        gt = read_npy(self.gt_path, check=self._gt_problem)
        bad = int(np.count_nonzero(~np.isfinite(gt)))
        if bad:
            raise DataError(f"ground truth has {bad} non-finite values of {gt.size} (NaN or inf): it cannot be "
                            "scored against", self.gt_path)
        return np.asarray(gt, dtype=np.float32)

    def gt_disparity(self, resolution: str = LOWRES) -> np.ndarray | None:
        """The centre view's disparity (H, W) float32 px per view step, or None (the test split)."""
        return self._gt if resolution == LOWRES else None

    def mask_names(self, resolution: str = LOWRES) -> list[str]:
        return []

    def mask(self, name: str, resolution: str = LOWRES) -> np.ndarray:
        raise DataError(f"UrbanLF-Syn has no evaluation mask {name!r}", self.path)

    def valid_mask(self) -> np.ndarray | None:
        return None

    @functools.cached_property
    def _rgb(self) -> np.ndarray:
        h, w = self.spatial_size
        views = np.empty((ANGULAR, ANGULAR, h, w, 3), dtype=np.float32)
        for r in range(ANGULAR):
            for c in range(ANGULAR):
                views[r, c] = read_rgb(self.view_path(r, c), size=(h, w))
        return views

    def rgb_views(self) -> np.ndarray:
        """(9, 9, H, W, 3) float32 RGB in [0, 1]; ``[r, c]`` is ``<r+1>_<c+1>.png``."""
        return self._rgb

    @functools.cached_property
    def _gray(self) -> np.ndarray:
        return rgb_to_gray(self._rgb)

    def gray_views(self) -> np.ndarray:
        return self._gray

    def center_view(self) -> np.ndarray:
        if "_rgb" in self.__dict__:
            return self._rgb[CENTRE - 1, CENTRE - 1]
        return read_rgb(self.view_path(CENTRE - 1, CENTRE - 1), size=self.spatial_size)


def _is_sample(folder: Path) -> bool:
    return (folder / view_name(CENTRE, CENTRE)).is_file()


class UrbanLFSyn(Dataset):
    """UrbanLF-Syn (Sheng et al., TCSVT 2022), the LFNAT 2023 light-field depth challenge's data."""

    name = "urbanlf-syn"
    summary = "UrbanLF-Syn: ROOT/<train|val|test>/ImageN/ with u_v.png views and u_v_disparity.npy"
    layout = "ROOT/<split>/ImageN/ with 1_1.png .. 9_9.png and 5_5_disparity.npy"
    protocol = URBANLF_PROTOCOL

    @classmethod
    def matches(cls, root: Path) -> bool:
        if _is_sample(root):
            return True
        children = [p for p in root.iterdir() if p.is_dir()]
        return any(_is_sample(c) for c in children) or any(
            _is_sample(g) for c in children for g in c.iterdir() if g.is_dir())

    @classmethod
    def open(cls, root: Path) -> Benchmark:
        root = Path(root)
        if _is_sample(root):
            scenes = [UrbanLFScene(root, category=root.parent.name or "other")]
        else:
            scenes = []
            for child in sorted((p for p in root.iterdir() if p.is_dir()), key=_sample_order):
                if _is_sample(child):  # a split folder given as the root
                    scenes.append(UrbanLFScene(child, category=root.name or "other"))
                    continue
                scenes += [UrbanLFScene(g, category=child.name)
                           for g in sorted((p for p in child.iterdir() if p.is_dir() and _is_sample(p)),
                                           key=_sample_order)]
        if not scenes:
            raise DataError("no UrbanLF-Syn samples found (expected <root>/<split>/ImageN/5_5.png)", root)
        check_scene_names(scenes)
        return Benchmark(root=root, scenes=tuple(scenes), splits={})  # type: ignore[arg-type]


def _sample_order(path: Path) -> tuple[int, str]:
    """Image2 before Image10."""
    digits = re.sub(r"\D", "", path.name)
    return (int(digits) if digits else -1, path.name)
