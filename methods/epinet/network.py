"""EPINET (Shin et al., CVPR 2018): the multi-stream network of the authors' released Keras code
(chshin10/epinet, ``epinet_fun/func_epinetmodel.py``), in PyTorch.

Input: four stacks of ``angular`` grey views along the lines through the centre view (see :func:`stack_views`),
each fed to its own stream of 3 blocks (Conv 2x2 -> ReLU -> Conv 2x2 -> BN -> ReLU, ``filters`` channels,
valid padding); the four streams' features concatenated (4 x filters channels) and passed through ``depth``
merged blocks of the same form, then Conv 2x2 -> ReLU -> Conv 2x2 to one channel: the disparity, regressed
directly (no cost volume, no disparity grid).

Every convolution is 2x2 and valid, so the network's own output is (H - 2R) x (W - 2R) with R = 3 + depth + 1
(11 px for the paper's depth 7): output pixel (i, j) depends on input pixels i..i+2R, j..j+2R, i.e. on the
(2R + 1)^2 square centred on input pixel (i + R, j + R). lfbench returns full-size maps: the inner part,
``[R:H-R, R:W-R]``, is exactly the network's output, and the border of R px is filled by **edge
replication of that output** (each border pixel takes the value of the nearest pixel of the network's output;
torch ``F.pad(mode="replicate")``). Training losses compare the inner part only (:attr:`EPINet.output_margin`).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from lfbench_methods.epinet.trainable import MAX_ANGULAR
from torch import nn

BN_EPS = 1e-3  # Keras BatchNormalization epsilon
BN_MOMENTUM = 0.01  # Keras momentum 0.99
STREAM_BLOCKS = 3  # the authors' layer1_multistream: 3 blocks per stream
STREAMS = ("90d", "0d", "45d", "m45d")  # the authors' input order (their input_stack_LtoRb, UtoDb, 5cb, 7cb)


def check_config(angular: int, filters: int, depth: int) -> None:
    """ValueError for an angular size without a centre view (even, < 3, > MAX_ANGULAR) or sizes < 1 / < 0."""
    if isinstance(angular, bool) or not isinstance(angular, int) or angular < 3 or angular % 2 == 0 \
            or angular > MAX_ANGULAR:
        raise ValueError(f"angular must be an odd number of views from 3 to {MAX_ANGULAR} (the stacks run through "
                         f"the centre view), got {angular!r}")
    if isinstance(filters, bool) or not isinstance(filters, int) or filters < 1:
        raise ValueError(f"filters must be an int >= 1, got {filters!r}")
    if isinstance(depth, bool) or not isinstance(depth, int) or depth < 0:
        raise ValueError(f"depth must be an int >= 0, got {depth!r}")


def stack_views(angular: int) -> dict[str, list[int]]:
    """Indices of the views in each of the four stacks, in the authors' order (lfbench's view k is at angular
    row k // angular, column k % angular; HCI's input_Cam{k:03d}.png), c = angular // 2, A = angular:

    - ``90d``: column c, rows A-1 .. 0 (bottom to top);
    - ``0d``: row c, columns 0 .. A-1 (left to right);
    - ``45d``: (row A-1-k, column k), k = 0 .. A-1 (bottom-left to top-right);
    - ``m45d``: (row k, column k) (top-left to bottom-right).

    For 9x9: 90d [76, 67, .., 4], 0d [36, .., 44], 45d [72, 64, .., 8], m45d [0, 10, .., 80] (the authors'
    func_makeinput.py and func_generate_traindata.py)."""
    a, c = angular, angular // 2
    return {"90d": [(a - 1 - k) * a + c for k in range(a)],
            "0d": [c * a + k for k in range(a)],
            "45d": [(a - 1 - k) * a + k for k in range(a)],
            "m45d": [k * a + k for k in range(a)]}


def glorot_(conv: nn.Conv2d) -> None:
    """Keras's default Conv2D initialisation: Glorot-uniform kernel, zero bias."""
    k = conv.kernel_size[0] * conv.kernel_size[1]
    limit = math.sqrt(6.0 / (conv.in_channels * k + conv.out_channels * k))
    nn.init.uniform_(conv.weight, -limit, limit)
    if conv.bias is not None:
        nn.init.zeros_(conv.bias)


def conv2x2(cin: int, cout: int) -> nn.Conv2d:
    conv = nn.Conv2d(cin, cout, 2)  # valid padding, with bias (Keras Conv2D's default)
    glorot_(conv)
    return conv


class Block(nn.Module):
    """Conv 2x2 -> ReLU -> Conv 2x2 -> BN -> ReLU (valid): (B, cin, H, W) -> (B, cout, H - 2, W - 2)."""

    def __init__(self, cin: int, cout: int) -> None:
        super().__init__()
        self.conv1 = conv2x2(cin, cout)
        self.conv2 = conv2x2(cout, cout)
        self.bn = nn.BatchNorm2d(cout, eps=BN_EPS, momentum=BN_MOMENTUM)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return F.relu(self.bn(self.conv2(F.relu(self.conv1(x)))))


class EPINet(nn.Module):
    """EPINET: four view stacks -> four streams -> merged blocks -> disparity (B, H, W), regressed (no
    probability: forward returns ``(disparity, None)``).

    The number of views per stack is ``angular`` (the 9x9 paper network: 9); the disparity is in px per view
    step with lfbench's (the HCI data's) sign, the authors' own: they train on HCI's ground truth with HCI's
    view numbering. It has no disparity range: d_min / d_max do not apply (the output is not clipped).
    """

    def __init__(self, angular: int = 9, filters: int = 70, depth: int = 7) -> None:
        """angular: views per angular row (odd), filters: per stream (the merged blocks have 4x), depth: merged
        blocks (the declared parameters, with help and bounds: EPINetTrainable.build)."""
        super().__init__()
        check_config(angular, filters, depth)
        self.angular, self.filters, self.depth = angular, filters, depth
        self.streams = nn.ModuleList(
            nn.Sequential(*(Block(angular if i == 0 else filters, filters) for i in range(STREAM_BLOCKS)))
            for _ in STREAMS)
        width = 4 * filters
        self.merged = nn.Sequential(*(Block(width, width) for _ in range(depth)))
        self.last1 = conv2x2(width, width)
        self.last2 = conv2x2(width, 1)
        index = stack_views(angular)
        self.register_buffer("stack_index", torch.tensor([index[s] for s in STREAMS], dtype=torch.long),
                             persistent=False)

    @property
    def output_margin(self) -> int:
        """px per side that the valid convolutions lose (11 for depth 7): the border lfbench fills."""
        return STREAM_BLOCKS + self.depth + 1

    @property
    def receptive_radius(self) -> int:
        """px of context a pixel of the returned map depends on: 2R (22 for depth 7). A pixel of the inner part
        depends on the (2R + 1)^2 square centred on it (every 2x2 valid conv adds one row and one column, R
        = output_margin); a border pixel copies the nearest inner pixel, up to R px farther in, whose square
        then reaches 2R px from it. Tiles computed with this much context (lfbench's generic tiling) are exact;
        the trainable's own tiles need R (they tile the inner part and fill the border once)."""
        return 2 * self.output_margin

    def config(self) -> dict:
        return {"angular": self.angular, "filters": self.filters, "depth": self.depth}

    def stacks(self, views: torch.Tensor) -> list[torch.Tensor]:
        """(B, N, H, W) views -> the four (B, angular, H, W) stacks, in the authors' order 90d, 0d, 45d, m45d."""
        if views.dim() != 4 or views.shape[1] != self.angular ** 2:
            raise ValueError(f"EPINET({self.angular}x{self.angular}) needs views (B, {self.angular ** 2}, H, W), "
                             f"got {tuple(views.shape)}")
        return [views[:, idx] for idx in self.stack_index]

    def valid(self, views: torch.Tensor) -> torch.Tensor:
        """The network's own output: (B, N, H, W) -> (B, H - 2R, W - 2R) disparity (H, W >= 2R + 1)."""
        r = self.output_margin
        h, w = views.shape[-2:]
        if h <= 2 * r or w <= 2 * r:
            raise ValueError(f"EPINET needs at least {2 * r + 1}x{2 * r + 1} px (its valid 2x2 convolutions "
                             f"lose {r} px per side), got {h}x{w}")
        feats = [stream(stack) for stream, stack in zip(self.streams, self.stacks(views), strict=True)]
        x = self.merged(torch.cat(feats, dim=1))
        return self.last2(F.relu(self.last1(x)))[:, 0]

    def forward(self, views: torch.Tensor) -> tuple[torch.Tensor, None]:
        """(B, N, H, W) grey views in [0, 1] -> ((B, H, W) disparity, None); the border of output_margin px is
        the edge replication of the network's (H - 2R) x (W - 2R) output."""
        return fill_border(self.valid(views), self.output_margin), None

    def flops(self, height: int, width: int) -> dict[str, float]:
        """FLOPs (2 per multiply-add of the convolutions; BN, ReLU, the border fill not counted) of one forward
        pass on an H x W light field: ``streams``, ``merged``, ``last``, ``total``."""
        def convs(module: nn.Module, size: tuple[int, int]) -> tuple[float, tuple[int, int]]:
            total, (h, w) = 0.0, size
            for m in module.modules():
                if isinstance(m, nn.Conv2d):
                    h, w = h - 1, w - 1
                    total += 2.0 * m.in_channels * m.out_channels * 4 * max(h, 0) * max(w, 0)
            return total, (h, w)

        one, size = convs(self.streams[0], (height, width))
        merged, size = convs(self.merged, size)
        last, _ = convs(nn.ModuleList([self.last1, self.last2]), size)
        out = {"streams": 4 * one, "merged": merged, "last": last}
        out["total"] = sum(out.values())
        return out


def fill_border(inner: torch.Tensor, margin: int) -> torch.Tensor:
    """(B, h, w) -> (B, h + 2 margin, w + 2 margin): the border filled by edge replication of ``inner``."""
    return F.pad(inner.unsqueeze(1), (margin,) * 4, mode="replicate")[:, 0]


def count_trainable(module: nn.Module) -> int:
    """Trainable parameters (BN running statistics excluded)."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


__all__ = ["EPINet", "Block", "stack_views", "fill_border", "check_config", "count_trainable",
           "STREAMS", "STREAM_BLOCKS", "BN_EPS"]
