"""EPINET as a trainable network (the lfbench.method.trainable seam): what ``lfbench train`` builds from
``[model]`` (angular, filters, depth), how inference runs (whole image, or exact tiles of the network's own
output), its FLOPs, and the authors' optimiser (RMSprop).

Light at import (no torch): the network module is imported when a network is built."""

from __future__ import annotations

import contextlib
from typing import TYPE_CHECKING, Annotated, Any

from lfbench.method.params import Range
from lfbench.method.trainable import StageOptions, Trainable, register_trainable, to_channels_last

if TYPE_CHECKING:
    import torch
    from lfbench_methods.epinet.network import EPINet

#: Where the network lives: imported only when one is built (``lfbench methods`` does not need torch).
NETWORK = "lfbench_methods.epinet.network:EPINet"
MAX_ANGULAR = 33  # the most views per angular row the network is built for (network.check_config)
RMSPROP_RHO = 0.9  # Keras RMSprop's rho (the authors' RMSprop(lr=...) with the other arguments left default)


@register_trainable("epinet")
class EPINetTrainable(Trainable):
    """EPINET (Shin et al., CVPR 2018): four EPI view stacks, multi-stream 2x2 convolutions, disparity regressed.

    The authors' network (chshin10/epinet) has 5,118,681 trainable parameters at 9x9 views, 70 filters and 7
    merged blocks. Its valid convolutions lose 11 px per side, so the map's border is the edge replication
    of the network's output (the inner part is exactly the network's), and training losses compare the inner
    part only (the authors' patch of 25 px trains on its inner 3 x 3 px). It regresses the disparity directly,
    so there is no disparity range (d_min and d_max do not apply) and no probability (only the l1 and mse
    losses train it).
    """

    network = NETWORK
    distribution = False
    axes = ("filters", "depth")

    def build(self,
              angular: Annotated[int, "views per angular row and column (odd: the stacks run through the centre "
                                      "view, each has this many views)", Range(3, MAX_ANGULAR)] = 9,
              filters: Annotated[int, "filters per stream (paper 70; the merged blocks have 4x)", Range(1, 512)] = 70,
              depth: Annotated[int, "merged blocks after the streams (paper 7)", Range(0, 32)] = 7) -> Any:
        """The EPINet of these parameters (declared here, so that listing them imports no torch)."""
        from lfbench_methods.epinet.network import EPINet

        return EPINet(angular=angular, filters=filters, depth=depth)

    def cost_estimate(self, model: dict[str, Any], steps: int) -> float:
        """Multiply-adds per output pixel (the merged blocks dominate: (4 filters)^2 x 8 x depth) x steps."""
        params = {**{k: p.default for k, p in self.parameters().items()}, **model}
        width = 4 * int(params["filters"])
        return float(width * width * 8 * (int(params["depth"]) + 1) * steps)

    def configure_optimizers(self, net: torch.nn.Module, stage: StageOptions) -> torch.optim.Optimizer:
        """The authors' optimiser: RMSprop (Keras: rho 0.9, epsilon outside the square root, as PyTorch's) with
        the stage's lr and eps at a constant rate; the stage's betas do not apply."""
        import torch

        return torch.optim.RMSprop(net.parameters(), lr=stage.lr, alpha=RMSPROP_RHO, eps=stage.eps)

    def can_tile(self, net: EPINet) -> bool:
        return True

    def infer(self, net: EPINet, views: torch.Tensor, *, precision: str = "fp32", max_memory_gb: float | None = None,
              tile: int = 0, timings: dict | None = None) -> tuple[torch.Tensor, None]:
        """Views (B, N, H, W) -> (disparity (B, H, W) float32, None), in fp32 or under bf16 autocast. With
        ``tile`` > 0 the network's own (H - 2R) x (W - 2R) output is computed in tiles of tile x tile px, each
        from its tile plus R px of input on every side (R = net.output_margin): exactly the whole image's
        output; the border is then filled by edge replication as forward does. On the CPU the network's weights are
        made channels-last first (benchmarks/epinet_floor.py). ``max_memory_gb`` is not used."""
        import torch
        from lfbench_methods.epinet.network import fill_border

        autocast = (torch.autocast(views.device.type, dtype=torch.bfloat16) if precision == "bf16"
                    else contextlib.nullcontext())
        net = net.eval()
        if views.device.type == "cpu":  # oneDNN runs the 2x2 convolutions ~1.5x faster channels-last (the
            to_channels_last(net)      # same values: weights re-laid out in place, once)
        r = net.output_margin
        h, w = views.shape[-2:]
        oh, ow = h - 2 * r, w - 2 * r
        with torch.inference_mode(), autocast:
            if tile <= 0 or (tile >= oh and tile >= ow) or oh <= 0 or ow <= 0:
                inner = net.valid(views).float()  # ValueError for an image smaller than 2R + 1
                count = 1
            else:
                inner = views.new_empty((views.shape[0], oh, ow), dtype=torch.float32)
                count = 0
                for y0 in range(0, oh, tile):
                    for x0 in range(0, ow, tile):
                        y1, x1 = min(y0 + tile, oh), min(x0 + tile, ow)
                        inner[:, y0:y1, x0:x1] = net.valid(views[..., y0:y1 + 2 * r, x0:x1 + 2 * r]).float()
                        count += 1
            if timings is not None:
                timings["tile"], timings["tiles"] = ((tile, tile) if count > 1 else (h, w)), count
            return fill_border(inner, r), None

    def flops(self, net: EPINet, height: int, width: int) -> dict[str, float]:
        return net.flops(height, width)


__all__ = ["EPINetTrainable", "NETWORK"]
