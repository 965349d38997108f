"""The ``tinycnn`` plugin: one network, registered once.

:class:`TinyNet` is a ``torch.nn.Module``: 3x3 convolutions over the stacked views minus the centre view (the
differences carry the parallax), a softmax over candidate disparities and their expectation. Its constructor's
parameters, typed and documented with ``Annotated``, are everything lfbench needs to know about them.

:class:`TinyCNN` registers it (``@register_trainable``). With that alone:

- ``lfbench evaluate --method tinycnn:weights=OUT/final.pt`` runs trained weights (lfbench's generic network
  method: device, precision, exact tiles, the network's parameters as spec parameters);
- ``lfbench train`` trains it (``method = "tinycnn"``; distribution losses too: ``distribution = True``);
- ``lfbench ablate`` varies its parameters; ``lfbench bench`` times it (GFLOP/s from :meth:`TinyCNN.flops`);
- ``lfbench methods`` / ``lfbench info tinycnn`` list its parameters with their help.
"""

from __future__ import annotations

from typing import Annotated

import torch
from torch import nn

from lfbench import Range, Trainable, register_trainable


class TinyNet(nn.Module):
    """views (B, N, H, W) in [0, 1] -> (disparity (B, H, W) px, probability (B, D, H, W) over ``disparities``)."""

    def __init__(self, channels: Annotated[int, "channels of the hidden 3x3 convolutions", Range(1, 1024)] = 8,
                 layers: Annotated[int, "number of hidden 3x3 convolutions", Range(1, 32)] = 2,
                 d_min: Annotated[float, "smallest candidate disparity in px"] = -4.0,
                 d_max: Annotated[float, "largest candidate disparity in px"] = 4.0,
                 interval: Annotated[float, "step of the candidate disparities in px", Range(0.01, 8)] = 1.0,
                 angular: Annotated[int, "views per angular row (9 for the HCI scenes)", Range(1, 15)] = 9) -> None:
        super().__init__()
        if d_max <= d_min:
            raise ValueError(f"d_min must be below d_max, got d_min={d_min}, d_max={d_max}")
        self._config = {"channels": channels, "layers": layers, "d_min": float(d_min), "d_max": float(d_max),
                        "interval": float(interval), "angular": angular}
        self.angular = angular
        self.receptive_radius = layers + 1  # px: one per 3x3 convolution, so inference may run in exact tiles
        grid = torch.arange(d_min, d_max + interval / 2, interval, dtype=torch.float32)
        self.register_buffer("disparities", grid, persistent=False)
        body: list[nn.Module] = []
        cin = angular * angular
        for _ in range(layers):
            body += [nn.Conv2d(cin, channels, 3, padding=1), nn.ReLU()]
            cin = channels
        body.append(nn.Conv2d(cin, grid.numel(), 3, padding=1))
        self.body = nn.Sequential(*body)

    def config(self) -> dict:
        """The constructor arguments (stored in the weights files lfbench train writes)."""
        return dict(self._config)

    def forward(self, views: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        centre = views.shape[1] // 2  # view (angular // 2, angular // 2)
        prob = torch.softmax(self.body(views - views[:, centre:centre + 1]).float(), dim=1)
        return (prob * self.disparities[None, :, None, None]).sum(dim=1), prob


@register_trainable("tinycnn")
class TinyCNN(Trainable):
    """A tiny CNN over the stacked views (lfbench's example plugin)."""

    network = TinyNet
    distribution = True  # forward returns a probability over net.disparities

    def flops(self, net: TinyNet, height: int, width: int) -> dict[str, float]:
        """2 per multiply-add of the convolutions on an H x W light field."""
        convs = [m for m in net.modules() if isinstance(m, nn.Conv2d)]
        total = sum(2.0 * m.in_channels * m.out_channels * m.kernel_size[0] * m.kernel_size[1] for m in convs)
        return {"total": total * height * width}
