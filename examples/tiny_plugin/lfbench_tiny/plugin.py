"""The ``tinycnn`` plugin: a network lfbench can train, ablate and time, and the method that runs it.

- :class:`TinyNet`: 3x3 convolutions over the stacked views minus the centre view (the differences carry
  the parallax), a softmax over candidate disparities and their expectation (so the distribution losses
  js, kl, uafl apply as well as l1);
- :class:`TinyCNN` (``@register_trainable``): tells lfbench how to build it from a training config's
  ``[model]`` table; its parameters are the ablation axes;
- :class:`TinyCNNMethod` (``@register_method``): runs a checkpoint written by ``lfbench train`` as
  ``tinycnn:weights=OUT/final.pt``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch import nn

from lfbench import DataError, Method, Prediction, Trainable, register_method, register_trainable
from lfbench.method.trainable import get_trainable


class TinyNet(nn.Module):
    """views (B, N, H, W) in [0, 1] -> (disparity (B, H, W) px, probability (B, D, H, W) over ``disparities``)."""

    def __init__(self, channels: int = 8, layers: int = 2, d_min: float = -4.0, d_max: float = 4.0,
                 interval: float = 1.0, angular: int = 9) -> None:
        super().__init__()
        if channels < 1 or layers < 1 or interval <= 0 or d_max <= d_min:
            raise ValueError(f"need channels, layers >= 1 and d_min < d_max, interval > 0; got channels={channels}, "
                             f"layers={layers}, d_min={d_min}, d_max={d_max}, interval={interval}")
        self._config = {"channels": channels, "layers": layers, "d_min": float(d_min), "d_max": float(d_max),
                        "interval": float(interval), "angular": angular}
        self.angular = angular
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
        """The constructor arguments (stored in checkpoints by lfbench train)."""
        return dict(self._config)

    def forward(self, views: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        centre = views.shape[1] // 2  # view (angular // 2, angular // 2)
        prob = torch.softmax(self.body(views - views[:, centre:centre + 1]).float(), dim=1)
        return (prob * self.disparities[None, :, None, None]).sum(dim=1), prob


@register_trainable("tinycnn")
class TinyCNN(Trainable):
    """A tiny CNN over the stacked views (lfbench's example plugin).

    channels: channels of the hidden 3x3 convolutions
    layers: number of hidden 3x3 convolutions
    d_min: smallest candidate disparity in px
    d_max: largest candidate disparity in px
    interval: step of the candidate disparities in px
    angular: views per angular row (9 for the HCI scenes)
    """

    network = TinyNet
    distribution = True  # forward returns a probability over net.disparities

    def flops(self, net: TinyNet, height: int, width: int) -> dict[str, float]:
        """2 per multiply-add of the convolutions on an H x W light field."""
        convs = [m for m in net.modules() if isinstance(m, nn.Conv2d)]
        total = sum(2.0 * m.in_channels * m.out_channels * m.kernel_size[0] * m.kernel_size[1] for m in convs)
        return {"total": total * height * width}


@register_method("tinycnn")
class TinyCNNMethod(Method):
    """A tiny CNN trained with lfbench train (lfbench's example plugin).

    weights: checkpoint .pt written by lfbench train (OUT/final.pt)
    """

    def __init__(self, weights: Path) -> None:
        super().__init__()
        self.weights = Path(weights)
        self._net: TinyNet | None = None

    def available_for(self, lf) -> str | None:
        return None if self.weights.is_file() else f"weights file {self.weights} not found"

    def network(self) -> TinyNet:
        """The checkpoint's network (eval mode), loaded once."""
        if self._net is None:
            if not self.weights.is_file():
                raise DataError("weights file not found", self.weights)
            self._net = get_trainable("tinycnn").load(self.weights)
        return self._net

    def to(self, device: str) -> TinyCNNMethod:
        self.network().to(device)
        return self

    def predict(self, lf) -> Prediction:
        net = self.network()
        v, u = lf.angular_size
        if (v, u) != (net.angular, net.angular):
            raise DataError(f"{self.label}: needs a {net.angular}x{net.angular} light field, got {v}x{u} ({lf.name})")
        views = lf.gray_views()  # (V, U, H, W) float32 in [0, 1]
        x = torch.from_numpy(np.ascontiguousarray(views.reshape(1, v * u, *views.shape[2:]), dtype=np.float32))
        device = net.disparities.device
        with torch.inference_mode():
            disp, prob = net(x.to(device))
        return Prediction(disparity=disp[0].cpu().numpy(), distribution=prob[0].cpu().numpy(),
                          disparity_values=net.disparities.cpu().numpy())
