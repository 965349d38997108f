"""OACC-Net as a trainable network (the lfbench.method.trainable seam): what ``lfbench train`` builds from
``[model]``, what ``lfbench ablate`` varies, what ``lfbench bench`` times, and the method
``oaccnet:weights=FILE`` (lfbench's generic network method), which also runs the authors' released
``.pth.tar`` (``{'state_dict': ...}``, their key names) as it is.

In training the loop hands the ground truth to the network (:attr:`Trainable.training_target`): one pass
with the occlusion mask of the true disparity, as the authors' ``dispGT`` branch.

Light at import (no torch): the network module is imported when a network is built."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

from lfbench.method.checkpoint import is_weights, read_checkpoint
from lfbench.method.params import Range
from lfbench.method.trainable import Trainable, network_from_state, register_trainable
from lfbench.utils.errors import DataError

if TYPE_CHECKING:
    import torch

NETWORK = "lfbench_methods.oaccnet.network:OACCNet"
#: The authors' key of the modulated convolution's weight (A^2 inputs per group: the angular size).
FUSE_KEY = "build_cost.oacc.fuse.weight"
#: The disparity grid of the authors' model.py (mindisp, maxdisp = -4, 4): what their checkpoints were trained on.
AUTHORS_RANGE = (-4.0, 4.0)


@register_trainable("oaccnet")
class OACCNetTrainable(Trainable):
    """OACC-Net (Wang et al., CVPR 2022): occlusion-aware cost constructor, two-pass inference.

    Integer disparity grid floor(d_min) .. ceil(d_max) (the authors' -4..4 on HCI; a dataset's range sets it);
    runs on whole images (its channel attention pools over the whole image). Weights: lfbench's own, or the
    authors' released ``.pth.tar`` as it is (its angular size read from the weights)."""

    network = NETWORK
    distribution = True
    training_target = True  # forward(views, target=...) in training: the mask of the true disparity
    gray_weights = (1 / 3, 1 / 3, 1 / 3)  # the authors' test.py: the mean of R, G and B
    axes = ("angular", "d_min", "d_max")

    def build(self,
              angular: Annotated[int, "views per angular row (odd; the authors 9, also 7 and 5)", Range(3, 15)] = 9,
              d_min: Annotated[float, "smallest disparity in px: the grid is every integer from floor(d_min)",
                               Range(-32, 32)] = -4.0,
              d_max: Annotated[float, "largest disparity in px: the grid ends at ceil(d_max)",
                               Range(-32, 32)] = 4.0) -> Any:
        """The OACCNet of these parameters (declared here, so that listing them imports no torch)."""
        from lfbench_methods.oaccnet.network import OACCNet

        return OACCNet(angular=angular, d_min=d_min, d_max=d_max)

    def check(self, params: dict[str, Any]) -> None:
        """The network's own parameter checks, without building it."""
        from lfbench_methods.oaccnet.network import check_config

        check_config(**{**{k: p.default for k, p in self.parameters().items()}, **params})

    def cost_estimate(self, model: dict[str, Any], steps: int) -> float:
        """Candidate disparities x steps (the 3D aggregation over the cost volume dominates)."""
        import math

        params = {**{k: p.default for k, p in self.parameters().items()}, **model}
        return (math.ceil(float(params["d_max"])) - math.floor(float(params["d_min"])) + 1) * steps

    def load(self, path: str | Path, **overrides: Any) -> torch.nn.Module:
        """lfbench weights (``final.pt``...), or the authors' checkpoint: ``{'state_dict': ...}`` with their key
        names (see :meth:`stored_config`); DataError naming the file for anything else."""
        payload = read_checkpoint(path, "weights file")
        config = authors_config(payload, path)
        if config is None:
            return super().load(path, **overrides)
        return network_from_state(self.build, payload["state_dict"], {**config, **overrides}, path)

    def stored_config(self, path: str | Path) -> dict[str, Any]:
        """The config stored in lfbench weights; for the authors' checkpoint (no config): the angular size of its
        weights and the grid their code hard-codes, -4..4 px."""
        config = authors_config(read_checkpoint(path, "weights file"), path)
        return super().stored_config(path) if config is None else config

    def flops(self, net: torch.nn.Module, height: int, width: int) -> dict[str, float]:
        return net.flops(height, width)


def authors_config(payload: dict[str, Any], path: str | Path) -> dict[str, Any] | None:
    """The network config of the authors' checkpoint ``payload`` (a ``state_dict`` and no config: ``angular``
    from the A^2 inputs per group of the modulated convolution, their model's fixed -4..4 grid), None for
    lfbench weights or a file without a state_dict (the generic reader names those); DataError naming ``path``
    for a state_dict that is not OACC-Net's."""
    if is_weights(payload) or not isinstance(payload.get("state_dict"), dict):
        return None
    fuse = payload["state_dict"].get(FUSE_KEY)
    if fuse is None or not hasattr(fuse, "shape") or len(fuse.shape) != 4:
        raise DataError(f"a checkpoint without OACC-Net's {FUSE_KEY!r}: not OACC-Net weights", path)
    angular = round(int(fuse.shape[1]) ** 0.5)
    if angular * angular != int(fuse.shape[1]):
        raise DataError(f"{FUSE_KEY} has {fuse.shape[1]} inputs per group, not a square number of views", path)
    return {"angular": angular, "d_min": AUTHORS_RANGE[0], "d_max": AUTHORS_RANGE[1]}


__all__ = ["OACCNetTrainable", "NETWORK", "authors_config"]
