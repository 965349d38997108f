"""Scenes whose views are named by a pattern: one folder per scene, one PNG per view, one ground-truth file
(:class:`ViewLayout`, :class:`PatternScene`). UrbanLF-Syn (lfbench.data.urbanlf) and the generic TOML
dataset (lfbench.data.generic) are both such layouts.

A pattern names a view by ``{v}`` (angular row) and ``{u}`` (angular column), as lfbench's ``views[v, u]``,
or by ``{k}`` = v * U + u (row-major); indices start at ``first`` (0 or 1). A scene is checked when it is
made, without decoding a pixel: every view present, no other file the pattern matches, all views of the
centre view's size (PNG headers), the ground truth's shape (its header, .npy and PNG). A non-finite
ground-truth value is found when it is read. Each problem is one DataError naming the file.
"""

from __future__ import annotations

import functools
import os
import re
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lfbench.data.npyfile import read_npy
from lfbench.data.pfm import read_pfm
from lfbench.data.scene import LOWRES, MAX_PNG_PIXELS, MAX_RESOLUTION_PX, MAX_VIEW_PIXELS, PNGScene, read_png
from lfbench.utils.errors import DataError
from lfbench.utils.readfile import check_regular_file, read_head

__all__ = ["GT_FORMATS", "ViewLayout", "PatternScene", "check_view_bytes", "finite_float32", "png_size"]

GT_FORMATS = ("pfm", "npy", "png16")
_FIELD = re.compile(r"\{([uvk])\}")
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@dataclass(frozen=True)
class ViewLayout:
    """How a scene folder names its views and ground truth.

    ``pattern``: view file name with ``{v}``/``{u}`` (row, column) or ``{k}`` (row-major index);
    ``angular``: (V, U) rows and columns of views; ``first``: the first index (0 or 1);
    ``gt_file``: the centre view's ground-truth disparity file (None: no ground truth);
    ``gt_format``: 'pfm', 'npy' or 'png16'; disparity = value * ``gt_scale`` + ``gt_offset`` (a negative scale
    flips a sign convention opposite to HCI's);
    ``reverse_rows`` / ``reverse_cols``: the files count rows from the bottom / columns from the right;
    ``transpose``: the files' row index is lfbench's column (square grids). Reversal applies to lfbench's
    indices, then transposition, as :class:`lfbench.data.orientation.Orientation` reads a grid, so the
    reading ``lfbench check-dataset`` names is the one these keys declare.
    """

    pattern: str
    angular: tuple[int, int]
    first: int = 0
    gt_file: str | None = None
    gt_format: str = "npy"
    gt_scale: float = 1.0
    gt_offset: float = 0.0
    transpose: bool = False
    reverse_rows: bool = False
    reverse_cols: bool = False

    def view_name(self, row: int, col: int) -> str:
        """The file of the view at 0-based angular ``row``, ``col`` (lfbench's ``views[row, col]``)."""
        rows, cols = self.angular
        row = rows - 1 - row if self.reverse_rows else row
        col = cols - 1 - col if self.reverse_cols else col
        if self.transpose:
            row, col = col, row
        return self.pattern.format(v=row + self.first, u=col + self.first, k=row * cols + col + self.first)

    @property
    def centre(self) -> tuple[int, int]:
        """0-based (row, column) of the centre view."""
        return self.angular[0] // 2, self.angular[1] // 2

    @functools.cached_property
    def regex(self) -> re.Pattern[str]:
        """Every file name the pattern could give (any indices)."""
        parts = _FIELD.split(self.pattern)
        return re.compile("".join(r"\d+" if i % 2 else re.escape(p) for i, p in enumerate(parts)) + "$")

    def names(self) -> list[str]:
        """Every view's file name, row by row."""
        v, u = self.angular
        return [self.view_name(r, c) for r in range(v) for c in range(u)]


def png_size(path: Path, what: str = "view image") -> tuple[int, int]:
    """(H, W) of a PNG from its IHDR chunk (its first 24 bytes, read without a decoder: a header that claims
    20000x20000 px is refused here, never handed to PIL); DataError naming the file when it is not a regular
    file (a FIFO is never opened blocking), not a PNG, or larger than MAX_PNG_PIXELS."""
    head = read_head(path, 24, what)
    if len(head) < 24 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise DataError(f"{what} is not a PNG file (no PNG signature and IHDR header)", path)
    w, h = struct.unpack(">II", head[16:24])
    if w == 0 or h == 0 or w * h > MAX_PNG_PIXELS:
        raise DataError(f"{what} is {w}x{h} px by its header: not a size lfbench reads (1 to {MAX_PNG_PIXELS} px)",
                        path)
    return h, w


def _npy_header(path: Path) -> tuple[tuple[int, ...], np.dtype]:
    check_regular_file(path, "ground truth")
    try:
        with open(path, "rb") as f:
            version = np.lib.format.read_magic(f)
            read = np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
            shape, _, dtype = read(f, max_header_size=10000)
    except (ValueError, OSError, EOFError, SyntaxError, TypeError):
        raise DataError("cannot read .npy: bad magic or header", path) from None
    return tuple(shape), dtype


def check_view_bytes(size: tuple[int, int], angular: tuple[int, int], path: Path) -> None:
    """DataError naming ``path`` (the centre view) unless views of ``size`` (H, W) on an ``angular`` (V, U) grid
    fit lfbench's bounds (MAX_RESOLUTION_PX per side, MAX_VIEW_PIXELS in all): checked from the headers, before
    the (V, U, H, W, 3) float32 views are allocated."""
    (h, w), (v, u) = size, angular
    if max(h, w) > MAX_RESOLUTION_PX or v * u * h * w > MAX_VIEW_PIXELS:
        gib = v * u * h * w * 3 * 4 / 1024**3
        raise DataError(f"views of {w}x{h} px on a {v}x{u} grid ({gib:.3g} GiB as float RGB): more than lfbench reads "
                        f"(at most {MAX_RESOLUTION_PX} px per side and {MAX_VIEW_PIXELS} px in all views)", path)


def finite_float32(gt: np.ndarray, path: Path) -> np.ndarray:
    """``gt`` as float32; DataError naming ``path`` when a value is NaN or infinite after the cast (a float64
    1e300 overflows float32 to inf: refused, never scored)."""
    with np.errstate(over="ignore", invalid="ignore"):
        out = np.asarray(gt, dtype=np.float32)
    bad = int(np.count_nonzero(~np.isfinite(out)))
    if bad:
        raise DataError(f"ground truth has {bad} non-finite values of {out.size} (NaN or inf, or beyond float32's "
                        "range): it cannot be scored against", path)
    return out


class PatternScene(PNGScene):
    """One scene folder of a :class:`ViewLayout`, checked when made, its pixels read when asked for."""

    layout: ViewLayout

    def __init__(self, path: str | Path, layout: ViewLayout, category: str = "other") -> None:
        self.path = Path(path)
        if not self.path.is_dir():
            raise DataError("scene folder not found", self.path)
        self.layout = layout
        self.name = self.path.name
        self.category = category
        self._spatial_size = self._view_sizes()
        self._check_gt_header()

    @property
    def spatial_size(self) -> tuple[int, int]:
        """(H, W) of every view, px (checked equal for all of them when the scene was made)."""
        return self._spatial_size

    def reopen_args(self) -> tuple:
        """Pickled as its folder, layout and category, reopened (and checked again) where it is unpickled."""
        return self.path, self.layout, self.category

    @property
    def angular_size(self) -> tuple[int, int]:
        return self.layout.angular

    def view_file(self, row: int, col: int) -> Path:
        return self.path / self.layout.view_name(row, col)

    def _view_sizes(self) -> tuple[int, int]:
        """(H, W) of the views; DataError for a missing, unexpected or differently sized view."""
        names = self.layout.names()
        expected = set(names)
        present = {p.name for p in self.path.iterdir() if self.layout.regex.match(p.name)}
        extra = sorted(present - expected)
        if extra:
            raise DataError(f"unexpected view {extra[0]} (the layout has {names[0]} .. {names[-1]})",
                            self.path / extra[0])
        missing = [n for n in names if n not in present]
        if missing:
            more = f" and {len(missing) - 3} more" if len(missing) > 3 else ""
            raise DataError(f"missing {len(missing)} of {len(names)} views: {', '.join(missing[:3])}{more}",
                            self.path)
        centre = self.view_file(*self.layout.centre)
        size = png_size(centre)
        check_view_bytes(size, self.layout.angular, centre)
        for name in names:
            got = png_size(self.path / name)
            if got != size:
                raise DataError(f"view is {got[1]}x{got[0]}, the centre view {centre.name} is {size[1]}x{size[0]}",
                                self.path / name)
        return size

    @property
    def gt_path(self) -> Path | None:
        return self.path / self.layout.gt_file if self.layout.gt_file else None

    def _gt_problem(self, shape: tuple[int, ...], dtype: np.dtype) -> str | None:
        h, w = self.spatial_size
        if shape != (h, w):
            return f"ground truth has shape {shape}, expected ({h}, {w}) (the views' H, W)"
        if dtype.kind not in "fiu":
            return f"ground truth is {dtype}, expected numbers (disparities)"
        return None

    def _check_gt_header(self) -> None:
        """The ground truth's shape (and dtype) from its header, where the format has a cheap one."""
        path = self.gt_path
        if path is None or not os.path.lexists(path):
            return
        check_regular_file(path, "ground truth")  # a folder, FIFO, device or broken link is refused, not skipped
        fmt = self.layout.gt_format
        if fmt == "npy":
            problem = self._gt_problem(*_npy_header(path))
        elif fmt == "png16":
            problem = self._gt_problem(png_size(path, "ground truth"), np.dtype(np.uint16))
        else:
            return  # PFM: read_pfm checks the shape from the header before reading the data
        if problem:
            raise DataError(problem, path)

    def has_gt(self, resolution: str = LOWRES) -> bool:
        """Whether the ground-truth file is there: anything under its name counts (a folder, FIFO or broken link
        there is an error when read, never a scene without ground truth left out of the mean)."""
        return resolution == LOWRES and self.gt_path is not None and os.path.lexists(self.gt_path)

    @functools.cached_property
    def _gt(self) -> np.ndarray | None:
        path = self.gt_path
        if path is None or not os.path.lexists(path):
            return None
        fmt, (h, w) = self.layout.gt_format, self.spatial_size
        if fmt == "npy":
            gt = read_npy(path, check=self._gt_problem).astype(np.float64)
        elif fmt == "pfm":
            gt = read_pfm(path, shape=(h, w), what="ground truth")
            if gt.ndim != 2:
                raise DataError("ground truth is a 3-channel PF map, expected a gray Pf map", path)
        else:
            raw = read_png(path, "ground truth", size=(h, w))
            if raw.dtype != np.uint16 or raw.ndim != 2:
                raise DataError("ground truth is not a 16-bit gray PNG", path)
            gt = raw.astype(np.float64)
        if (self.layout.gt_scale, self.layout.gt_offset) != (1.0, 0.0):
            gt = gt * self.layout.gt_scale + self.layout.gt_offset
        return finite_float32(gt, path)

    def gt_disparity(self, resolution: str = LOWRES) -> np.ndarray | None:
        """The centre view's disparity (H, W) float32 px per view step, or None."""
        return self._gt if resolution == LOWRES else None



def sample_order(path: Path) -> tuple[int, str]:
    """Folders in natural order: Image2 before Image10."""
    digits = re.sub(r"\D", "", path.name)
    return (int(digits) if digits else -1, path.name)


def find_scene_dirs(root: Path, is_scene) -> list[tuple[Path, str]]:
    """(folder, category) of the scene folders under ``root``: ``root`` itself, its children (``root`` a
    category folder) or its grandchildren (ROOT/<category>/<scene>), in natural order."""
    if is_scene(root):
        return [(root, root.parent.name or "other")]
    found = []
    for child in sorted((p for p in root.iterdir() if p.is_dir()), key=sample_order):
        if is_scene(child):
            found.append((child, root.name or "other"))
            continue
        found += [(g, child.name) for g in sorted((p for p in child.iterdir() if p.is_dir() and is_scene(p)),
                                                   key=sample_order)]
    return found


def matches_at_depth(root: Path, is_scene) -> bool:
    """Whether ``root``, a child or a grandchild of it is a scene folder (by ``is_scene``)."""
    if is_scene(root):
        return True
    children = [p for p in root.iterdir() if p.is_dir()]
    return any(is_scene(c) for c in children) or any(is_scene(g) for c in children for g in c.iterdir() if g.is_dir())
