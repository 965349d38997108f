"""Writing scene folders in the HCI layout (synthetic scenes, through the adapter's
:meth:`~lfbench.data.hci.dataset.HCIDataset.write_scene`): the file names are :mod:`lfbench.data.hci.scene`'s, the
ones its reader opens, so writer and reader cannot drift apart.

A folder holds ``parameters.cfg``, views ``input_Cam000.png`` .. (8-bit RGB, row-major), ground truth
``gt_disp_lowres.pfm`` and ``gt_depth_lowres.pfm`` (PFM, float32) and evaluation masks ``<name>_lowres.png``
(8-bit gray, 255 = in the mask); each file is written atomically, only the parts given.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from lfbench.data.camera import Camera
from lfbench.data.hci.params import SceneParameters
from lfbench.data.hci.scene import PARAMETERS_FILE, depth_file_name, gt_file_name, mask_file_name, view_file_name
from lfbench.data.pfm import write_pfm
from lfbench.data.scene import LOWRES, png_bytes
from lfbench.utils.atomic import write_bytes

__all__ = ["write_hci_scene", "write_generated_scene"]


def write_hci_scene(folder: str | Path, params: Camera, *, views: np.ndarray | None = None,
                    disparity: np.ndarray | None = None, depth: np.ndarray | None = None,
                    masks: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write one HCI scene into ``folder`` (created) and return it.

    ``params``: its camera, written as parameters.cfg; ``views``: (V, U, H, W, 3) uint8 RGB, ``views[v, u]``
    written as view ``v * U + u``; ``disparity``: (H, W) ground truth, px per view step; ``depth``: (H, W) in m;
    ``masks``: name -> (H, W) bool evaluation masks. All at low resolution; None: that file is not written.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if views is not None:
        if views.dtype != np.uint8 or views.ndim != 5:
            raise ValueError(f"views must be (V, U, H, W, 3) uint8, got {views.dtype} {views.shape}")
        cols = views.shape[1]
        for k in range(views.shape[0] * cols):
            write_bytes(folder / view_file_name(k), png_bytes(views[k // cols, k % cols]))
    write_bytes(folder / PARAMETERS_FILE, SceneParameters.of(params).to_cfg().encode("utf-8"))
    if disparity is not None:
        write_pfm(folder / gt_file_name(LOWRES), disparity)
    if depth is not None:
        write_pfm(folder / depth_file_name(LOWRES), depth)
    for name, mask in (masks or {}).items():
        write_bytes(folder / mask_file_name(name, LOWRES), png_bytes(np.where(mask, 255, 0).astype(np.uint8)))
    return folder


def write_generated_scene(folder: str | Path, scene: Any) -> Path:
    """Write a generated scene (lfbench.data.dataset.Dataset.write_scene: lfbench.data.synth.SyntheticScene or
    the like) into ``folder`` (created): its views quantized to 8 bits, camera, ground-truth disparity and depth,
    and masks (views, depth None: not written)."""
    from lfbench.data.synth import quantize

    views = None if scene.views is None else quantize(scene.views)
    return write_hci_scene(folder, scene.params, views=views, disparity=scene.disparity,
                           depth=scene.depth, masks=scene.masks)
