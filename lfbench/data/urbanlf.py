"""UrbanLF-Syn (the LFNAT 2023 depth challenge's synthetic urban set) as a dataset adapter (``urbanlf-syn``).

Layout as released: ``ROOT/<split>/ImageN/`` for the splits train / val / test, one folder per sample,
views ``u_v.png`` with u, v = 1..9 (``5_5.png`` the centre view), per-view disparity ``u_v_disparity.npy``
(and depth / label files beside them, not read); the test split comes without disparity. ROOT may also be
one split folder or one sample folder. lfbench reads ``u_v.png`` as angular row u, column v (top to
bottom, left to right) and scores the centre view's ``5_5_disparity.npy`` (px per view step, read as the
HCI sign: positive = nearer than the focus plane). docs/datasets.md gives what public sources say about
these conventions and where they are silent.

Protocol (the challenge's): centre view, 15 px border, BadPix 0.01 / 0.03 / 0.07 and MSE x100 as the SubFocal
paper's first author scores them (scorer ``paper-author``, lfbench.scoring.policy: |error| >= t, NaN good in
BadPix and NaN in MSE), 640x480 views, disparity searched in [-0.5, 1.6] px at an interval of 0.1 px (the
released range is [-0.47, 1.55]; the grid is the SubFocal paper's for Table III).

Every scene is checked when it is opened as :class:`lfbench.data.pattern.PatternScene` checks a scene.
:meth:`UrbanLFSyn.write_scene` writes a generated scene in this layout (``lfbench synth --layout urbanlf-syn``,
lfbench.data.synth_urbanlf).
"""

from __future__ import annotations

import io
import os
from pathlib import Path
from typing import Any

import numpy as np

from lfbench.data.dataset import DEFAULT_METRICS, Dataset, DatasetProtocol
from lfbench.data.disparity import EVALUATION_BORDER_PX
from lfbench.data.pattern import PatternScene, ViewLayout, find_scene_dirs, matches_at_depth
from lfbench.data.scene import Benchmark, check_scene_names, png_bytes
from lfbench.utils.atomic import write_bytes
from lfbench.utils.errors import DataError, SpecError

__all__ = ["URBANLF_DISPARITY_RANGE", "URBANLF_LAYOUT", "URBANLF_PROTOCOL", "URBANLF_SPLITS", "UrbanLFScene",
           "UrbanLFSyn", "view_name", "gt_name"]

ANGULAR = 9
CENTRE = 5  # 1-based index of the centre view along each axis
URBANLF_SPLITS = ("train", "val", "test")
#: The disparities of the released ground truth, px per view step (the dataset's README).
URBANLF_DISPARITY_RANGE = (-0.47, 1.55)


def view_name(row: int, col: int) -> str:
    """The file of the view at 1-based angular row ``row``, column ``col``: ``'<row>_<col>.png'``."""
    return f"{row}_{col}.png"


def gt_name(row: int = CENTRE, col: int = CENTRE) -> str:
    """The disparity file of a view (default the centre's): ``'<row>_<col>_disparity.npy'``."""
    return f"{row}_{col}_disparity.npy"


def depth_name(row: int = CENTRE, col: int = CENTRE) -> str:
    """The depth file of a view (default the centre's), m, not read: ``'<row>_<col>_depth.npy'``."""
    return f"{row}_{col}_depth.npy"


#: ``u_v.png`` read as angular row u, column v (lfbench's ``{v}_{u}`` with 1-based indices).
URBANLF_LAYOUT = ViewLayout(pattern="{v}_{u}.png", angular=(ANGULAR, ANGULAR), first=1, gt_file=gt_name(),
                            gt_format="npy")

URBANLF_PROTOCOL = DatasetProtocol(
    border_px=EVALUATION_BORDER_PX, metrics=DEFAULT_METRICS,
    disparity_range=(-0.5, 1.6), disparity_interval=0.1, spatial_size=(480, 640), angular_size=(ANGULAR, ANGULAR),
    reference_view="centre view 5_5.png", scorer="paper-author")


class UrbanLFScene(PatternScene):
    """One UrbanLF-Syn sample folder (``ImageN/``): ``rgb_views()[r, c]`` is ``<r+1>_<c+1>.png``."""

    def __init__(self, path: str | Path, category: str = "other") -> None:
        super().__init__(path, URBANLF_LAYOUT, category)

    def reopen_args(self) -> tuple:
        return self.path, self.category


def npy_bytes(array: np.ndarray) -> bytes:
    """``array`` as the bytes of a float32 ``.npy`` file (the released ground truth's type)."""
    buf = io.BytesIO()
    np.save(buf, np.ascontiguousarray(array, dtype=np.float32), allow_pickle=False)
    return buf.getvalue()


def _is_sample(folder: Path) -> bool:
    """Whether ``folder`` holds a centre view: anything under its name (a FIFO or a broken link there is refused
    when the sample is opened, never a sample left out)."""
    return os.path.lexists(folder / view_name(CENTRE, CENTRE))


class UrbanLFSyn(Dataset):
    """UrbanLF-Syn (Sheng et al., TCSVT 2022), the LFNAT 2023 light-field depth challenge's data."""

    name = "urbanlf-syn"
    summary = "UrbanLF-Syn: ROOT/<train|val|test>/ImageN/ with u_v.png views and u_v_disparity.npy"
    layout = "ROOT/<split>/ImageN/ with 1_1.png .. 9_9.png and 5_5_disparity.npy"
    protocol = URBANLF_PROTOCOL

    @classmethod
    def matches(cls, root: Path) -> bool:
        return matches_at_depth(root, _is_sample)

    @classmethod
    def open(cls, root: Path) -> Benchmark:
        root = Path(root)
        scenes = [UrbanLFScene(folder, category) for folder, category in find_scene_dirs(root, _is_sample)]
        if not scenes:
            raise DataError("no UrbanLF-Syn samples found (expected <root>/<split>/ImageN/5_5.png)", root)
        return Benchmark(root=root, scenes=tuple(check_scene_names(scenes)), splits={})  # type: ignore[arg-type]

    @classmethod
    def write_scene(cls, folder: Path, scene: Any) -> Path:
        """Write a generated scene of 9x9 views as the sample folder ``folder`` (created): views ``u_v.png``
        quantized to 8 bits (lfbench.data.synth.quantize), the centre view's ``5_5_disparity.npy`` and (depth not
        None) ``5_5_depth.npy``, float32; the other views' disparity files of the released data are not written
        (lfbench scores the centre view). Each file is written atomically."""
        from lfbench.data.synth import quantize

        if scene.views is None or tuple(scene.views.shape[:2]) != (ANGULAR, ANGULAR):
            shape = None if scene.views is None else tuple(scene.views.shape[:2])
            raise SpecError(f"the UrbanLF-Syn layout has {ANGULAR}x{ANGULAR} views, got {shape}")
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        views = quantize(scene.views)
        for r in range(ANGULAR):
            for c in range(ANGULAR):
                write_bytes(folder / view_name(r + 1, c + 1), png_bytes(views[r, c]))
        write_bytes(folder / gt_name(), npy_bytes(scene.disparity))
        if scene.depth is not None:
            write_bytes(folder / depth_name(), npy_bytes(scene.depth))
        return folder
