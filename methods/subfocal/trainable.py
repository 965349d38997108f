"""SubFocal and LFattNet as trainable networks (the lfbench.method.trainable seam): what ``lfbench train``
builds from ``[model]``, what ``lfbench ablate`` varies, what ``lfbench bench`` times."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import torch
from lfbench_methods.subfocal.bench import bench_peak, bench_volume
from lfbench_methods.subfocal.network import SubFocalNet, check_config

from lfbench.method.trainable import Trainable, register_trainable


@register_trainable("subfocal")
class SubFocalTrainable(Trainable):
    """SubFocal (Chao et al., TCI 2023): forward -> (disparity, softmax probability over the disparity grid).

    d_min: smallest candidate disparity in px
    d_max: largest candidate disparity in px
    interval: disparity step of the cost volume in px (paper 0.5)
    interpolation: sub-pixel shift of the features: nearest, bilinear (paper) or phase (Fourier)
    width: channels of the 3D aggregation (paper 150)
    attention: channel attention over the views on/off
    angular: views per angular row (9 for the HCI scenes)
    """

    network = SubFocalNet
    distribution = True
    axes = ("interval", "interpolation", "width", "attention", "d_min", "d_max")
    benches = {"peak": bench_peak, "volume": bench_volume}

    def check(self, params: dict[str, Any]) -> None:
        """The network's own parameter checks (network.check_config), without building the (paper-size) network."""
        check_config(**{**{k: p.default for k, p in self.parameters().items()}, **params})

    def load(self, path: str | Path, **overrides: Any) -> SubFocalNet:
        from lfbench_methods.subfocal.keras_import import build_from_checkpoint

        return build_from_checkpoint(path, **overrides)

    def infer(self, net: SubFocalNet, views: torch.Tensor, *, precision: str = "fp32",
              max_memory_gb: float | None = 4.0, tile: int = 0,
              timings: dict | None = None) -> tuple[torch.Tensor, torch.Tensor]:
        """Whole-image or exactly tiled inference on the network's device (tiles from ``max_memory_gb`` when
        tile = 0; None: the device's budget, see inference.memory_budget_gb); ``timings`` receives the phases,
        the tile size and the number of tiles."""
        from lfbench_methods.subfocal.inference import infer, memory_budget_gb, plan_tiles

        out = infer(net, views, tile=tile, max_memory_gb=max_memory_gb, precision=precision, timings=timings)
        if timings is not None and "tile" not in timings:
            h, w = views.shape[-2:]
            device = net.disparities.device
            timings["tile"] = plan_tiles(net, h, w, max_memory_gb=memory_budget_gb(device, max_memory_gb),
                                         precision=precision, device=device) if tile == 0 else (tile, tile)
        return out.disparity, out.probability

    def flops(self, net: SubFocalNet, height: int, width: int) -> dict[str, float]:
        return net.flops(height, width)


@register_trainable("lfattnet")
class LFAttNetTrainable(SubFocalTrainable):
    """LFattNet (Tsai et al., AAAI 2020), SubFocal's baseline: the same network at integer disparities.

    interval: disparity step of the cost volume in px (LFattNet 1)
    """

    defaults = {"interval": 1.0}


__all__ = ["SubFocalTrainable", "LFAttNetTrainable"]
