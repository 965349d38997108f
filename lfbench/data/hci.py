"""The HCI 4D Light Field Benchmark as a dataset adapter (``hci``): the layout, file names and scoring
protocol of the benchmark live here (the scene reader itself is :class:`lfbench.data.scene.Scene`).

Layout: ``ROOT/<category>/<scene>/`` with ``parameters.cfg``, views ``input_Cam000.png`` ..
``input_Cam080.png``, ground truth ``gt_disp_lowres.pfm`` (and ``gt_disp_highres.pfm``), evaluation masks
``<name>_lowres.png``; ROOT may also be a folder of scenes or one scene. Protocol: 512x512 views, 9x9,
15 px border, backgammon / dots / stripes at high resolution (x10) where their ground truth exists,
BadPix 0.07 / 0.03 / 0.01, MSE x100 and Q25, disparity searched in [-4, 4] px.
"""

from __future__ import annotations

from pathlib import Path

from lfbench.data.dataset import Dataset, DatasetProtocol
from lfbench.data.disparity import EVALUATION_BORDER_PX
from lfbench.data.pattern import matches_at_depth
from lfbench.data.scene import HIGHRES, LOWRES, Benchmark

__all__ = ["HCIDataset", "HCI_PROTOCOL", "HCI_HIGHRES_SCENES"]

#: The scenes the benchmark scores at high resolution where their high-resolution ground truth exists.
HCI_HIGHRES_SCENES = frozenset({"backgammon", "dots", "stripes"})

HCI_PROTOCOL = DatasetProtocol(
    border_px=EVALUATION_BORDER_PX, metrics=("badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100"),
    disparity_range=(-4.0, 4.0), resolutions=(LOWRES, HIGHRES), highres_scenes=HCI_HIGHRES_SCENES,
    spatial_size=(512, 512), angular_size=(9, 9), reference_view="centre view input_Cam040.png")

_MARKER = "parameters.cfg"


class HCIDataset(Dataset):
    """The HCI 4D Light Field Benchmark (Honauer et al. 2016)."""

    name = "hci"
    summary = "HCI 4D Light Field Benchmark: input_CamNNN.png views, parameters.cfg, PFM ground truth"
    layout = "ROOT/<category>/<scene>/parameters.cfg with input_Cam000.png .. and gt_disp_lowres.pfm"
    protocol = HCI_PROTOCOL

    @classmethod
    def matches(cls, root: Path) -> bool:
        return matches_at_depth(root, lambda folder: (folder / _MARKER).is_file())

    @classmethod
    def open(cls, root: Path) -> Benchmark:
        return Benchmark.discover(root)
