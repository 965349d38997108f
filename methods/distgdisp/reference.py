"""DistgDisp computed the way the authors' code computes it, with a :class:`DistgDispNet`'s weights: the views
arranged as a macro-pixel image (MacPI), the feature extractor's 3x3 convolutions of dilation A and padding A
on it, DSAFE as one strided, dilated convolution on the MacPI per disparity (the authors' dilation and
padding), the unfused aggregation, the soft argmin. The straightforward implementation the network is
checked against (tests) and timed against (benchmarks/distgdisp_inference.py); not a fast path.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from lfbench_methods.distgdisp.network import DistgDispNet, ResB3D, SpaResB, dsafe_geometry
from torch import nn


def random_batch_norm(net: nn.Module, seed: int = 0) -> nn.Module:
    """``net`` with random BatchNorm statistics and affine terms (in place): a fresh network's are 0 and 1, so
    folding them or not would look the same; the checks and benchmarks use this instead."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for m in net.modules():
            if isinstance(m, nn.BatchNorm2d | nn.BatchNorm3d):
                m.running_mean.copy_(torch.rand(m.running_mean.shape, generator=g) * 0.4 - 0.2)
                m.running_var.copy_(torch.rand(m.running_var.shape, generator=g) * 1.5 + 0.5)
                m.weight.copy_(torch.rand(m.weight.shape, generator=g) + 0.5)
                m.bias.copy_(torch.rand(m.bias.shape, generator=g) * 0.4 - 0.2)
    return net


def sai_array(views: torch.Tensor, angular: int) -> torch.Tensor:
    """views (B, N, H, W) -> the authors' input, the sub-aperture image array (B, 1, A H, A W): view (u, v)
    in block row u, block column v (``rearrange('u v h w -> (u h) (v w)')``)."""
    b, n, h, w = views.shape
    return views.reshape(b, angular, angular, h, w).permute(0, 1, 3, 2, 4).reshape(b, 1, angular * h, angular * w)


def sai_to_macpi(x: torch.Tensor, angular: int) -> torch.Tensor:
    """(B, C, A H, A W) sub-aperture array -> MacPI (B, C, H A, W A): pixel (h, w) of view (u, v) at
    (h A + u, w A + v)."""
    b, c, ah, aw = x.shape
    h, w = ah // angular, aw // angular
    return x.reshape(b, c, angular, h, angular, w).permute(0, 1, 3, 2, 5, 4).reshape(b, c, ah, aw)


def _macpi_sequential(seq: nn.Sequential, x: torch.Tensor, angular: int) -> torch.Tensor:
    """``seq`` on the MacPI: every 3x3 convolution with dilation A and padding A (the authors' layers)."""
    for m in seq:
        if isinstance(m, SpaResB):
            x = _macpi_sequential(m.body, x, angular) + x
        elif isinstance(m, nn.Conv2d):
            x = F.conv2d(x, m.weight, None, padding=angular, dilation=angular)
        else:
            x = m(x)
    return x


def macpi_cost_volume(net: DistgDispNet, feats: torch.Tensor) -> torch.Tensor:
    """The authors' BuildCostVolume: MacPI features (B, F, H A, W A) -> (B, C, D, H, W), one DSAFE convolution
    of stride A per disparity with their dilation and padding."""
    a = net.angular
    weight = net.build_costvolume.DSAFE.weight
    costs = []
    for d in net.disparities.round().int().tolist():
        dilation, padding = dsafe_geometry(d, a)
        costs.append(F.conv2d(feats, weight, stride=a, dilation=dilation, padding=padding))
    return torch.stack(costs, dim=2)


def _aggregate(seq: nn.Sequential, x: torch.Tensor) -> torch.Tensor:
    for m in seq:
        x = m.body(x) + x if isinstance(m, ResB3D) else m(x)
    return x


@torch.no_grad()
def reference_forward(net: DistgDispNet, views: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The authors' forward pass with ``net``'s weights (its mode decides BatchNorm's): views (B, N, H, W) ->
    (disparity (B, H, W), probability (B, D, H, W)), the expected disparity summed over D as their
    Regression does (one candidate at a time)."""
    a = net.angular
    x = sai_to_macpi(sai_array(views, a), a)
    feats = _macpi_sequential(net.init_feature, x, a)
    cost = _aggregate(net.aggregation, macpi_cost_volume(net, feats)).squeeze(1)
    score = torch.softmax(cost, dim=1)
    disp = torch.zeros_like(score[:, 0])
    for k, d in enumerate(net.disparities.tolist()):
        disp += score[:, k] * d
    return disp, score


__all__ = ["random_batch_norm", "sai_array", "sai_to_macpi", "macpi_cost_volume", "reference_forward"]
