"""The HCI 4D Light Field Benchmark as a dataset adapter (``hci``): the layout, file names and scoring
protocol of the benchmark (the scene reader is :class:`lfbench.data.hci.scene.HCIScene`).

Layout: ``ROOT/<category>/<scene>/`` with ``parameters.cfg``, views ``input_Cam000.png`` ..
``input_Cam080.png``, ground truth ``gt_disp_lowres.pfm`` (and ``gt_disp_highres.pfm``), evaluation masks
``<name>_lowres.png``; ROOT may also be a folder of scenes or one scene. Protocol: 512x512 views, 9x9,
15 px border, backgammon / dots / stripes at high resolution (x10) where their ground truth exists,
BadPix 0.07 / 0.03 / 0.01, MSE x100 and Q25, disparity searched in [-4, 4] px at each method's own interval
(the plane sweep's 0.25 px, SubFocal's 0.5 as in its paper, LFattNet's 1: HCI's numbers are those methods'
defaults, so HCI declares no interval of its own).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from lfbench.data.dataset import DEFAULT_METRICS, Dataset, DatasetProtocol
from lfbench.data.disparity import EVALUATION_BORDER_PX
from lfbench.data.hci.scene import SPLITS, discover, is_scene_folder
from lfbench.data.pattern import matches_at_depth
from lfbench.data.scene import HIGHRES, LOWRES, Benchmark

__all__ = ["HCIDataset", "HCI_PROTOCOL", "HCI_HIGHRES_SCENES", "HCI_BORDER_PX"]

#: The benchmark's evaluation border: px left out at every side at low resolution (x10 at high resolution).
HCI_BORDER_PX = EVALUATION_BORDER_PX

#: The scenes the benchmark scores at high resolution where their high-resolution ground truth exists.
HCI_HIGHRES_SCENES = frozenset({"backgammon", "dots", "stripes"})

HCI_PROTOCOL = DatasetProtocol(
    border_px=HCI_BORDER_PX, metrics=(*DEFAULT_METRICS, "q25_x100"),
    disparity_range=(-4.0, 4.0), disparity_interval=None, resolutions=(LOWRES, HIGHRES),
    highres_scenes=HCI_HIGHRES_SCENES, spatial_size=(512, 512), angular_size=(9, 9),
    reference_view="centre view input_Cam040.png")


class HCIDataset(Dataset):
    """The HCI 4D Light Field Benchmark (Honauer et al. 2016)."""

    name = "hci"
    summary = "HCI 4D Light Field Benchmark: input_CamNNN.png views, parameters.cfg, PFM ground truth"
    layout = "ROOT/<category>/<scene>/parameters.cfg with input_Cam000.png .. and gt_disp_lowres.pfm"
    protocol = HCI_PROTOCOL
    splits = SPLITS

    @classmethod
    def matches(cls, root: Path) -> bool:
        return matches_at_depth(root, is_scene_folder)

    @classmethod
    def open(cls, root: Path) -> Benchmark:
        return discover(root)

    @classmethod
    def write_scene(cls, folder: Path, scene: Any) -> Path:
        from lfbench.data.hci.write import write_generated_scene

        return write_generated_scene(folder, scene)
