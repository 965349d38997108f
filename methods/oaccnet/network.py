"""OACC-Net (Wang et al., CVPR 2022, "Occlusion-Aware Cost Constructor for Light Field Depth Estimation").

The layers, their order and their parameters are those of the authors' released PyTorch model
(github.com/YingqianWang/OACC-Net, model.py); module attribute names follow it, so that a state_dict saved
by the authors' code (``{'state_dict': ...}`` in a ``.pth.tar``) loads as it is:

- ``init_feature``: per-view 2D features (Conv3d with a 1x3x3 kernel over (views, H, W)): conv 1->16, BN,
  8 residual blocks (conv, BN, LeakyReLU 0.1, conv, BN; the convs with bias), conv 16->16, BN, LReLU,
  conv 16->8, BN, LReLU; then ``lastconv`` 8->8;
- ``build_cost.oacc.fuse``: the occlusion-aware cost constructor, a modulated dilated convolution: for each
  integer candidate d, cost(p) = sum_k W[:, k] m_k(p) f_k(p - s_k d) / mean_k m_k(p) with f_k the features
  of view k, s_k = (col - c, row - c) its offset and m_k the occlusion mask at the centre pixel p; the
  weight is a grouped 1x1 convolution (8 groups, one per feature channel, over the A^2 views), 512 outputs;
- ``aggregate``: 3D cost aggregation over (D, H, W): 1x1x1 conv 512->160, two 3x3x3 convs, two residual
  blocks with channel attention (``CALayer``), a 3x3x3 conv and a 160->1 conv, softmax over D, soft argmin.

Inference runs two passes (:meth:`OACCNet.forward`): the first with every mask 1 (a plain dilated
convolution), the second with the mask ``(1 - |warp_k(view k, -d1) - centre|)^2`` computed by warping each
view to the centre with the first pass's disparity d1 (:func:`occlusion_mask`). In training the network is
given the ground truth (``target``) and runs once with the mask from it (the authors' ``dispGT`` branch).

Departures from the released code, none changing a result it can produce:

- the cost constructor gathers the shifted views through a strided view of the padded features and
  contracts views and channels in bands of rows (:func:`modulated_cost`), instead of unfolding an
  8 x A^2-channel tensor (plus a repeated mask and a fold) per disparity; the 1x1x1 convolution that follows
  (``aggregate.sq.0``, linear) is folded into it, so the 512-channel cost volume is never held either;
- the disparity grid is every integer of [floor(d_min), ceil(d_max)] (the authors: -4..4, a symmetric range
  their cropping requires); any range works here, and for a symmetric one the cost equals theirs;
- in eval mode the feature extractor runs channels-last with each batch norm folded into its convolution;
- the channel attention pools over (H, W) per disparity; the authors' ``AdaptiveAvgPool3d((9, 1, 1))`` is
  that for their 9 disparities (for any other count their product does not broadcast).

Shapes and units: views (B, N, H, W) float32 gray in [0, 1], N = A^2, view k at row k // A, column k % A
(the authors' ``input_Cam0kk`` order); disparity in px per view step with the HCI sign (the authors' own:
their warp samples view (u, v) at x - (v - c) d, y - (u - c) d, the lfbench contract).
"""

from __future__ import annotations

import math
from typing import Any

import torch
import torch.nn.functional as F
from torch import nn

#: Output channels of the cost constructor and of the aggregation (the authors' 512 and 160).
COST_CHANNELS = 512
AGG_CHANNELS = 160
FEATURE_CHANNELS = 8
#: Elements of one band of the gathered, masked views (B x C x A^2 x rows x W): 64 MiB in fp32. Large bands
#: keep the matrix products efficient (at 12 rows of 128 px they ran at half the speed of whole images).
BAND_ELEMENTS = 1 << 24


def disparity_grid(d_min: float, d_max: float) -> list[int]:
    """The integer candidates floor(d_min) .. ceil(d_max) (ValueError for an empty or huge range)."""
    lo, hi = math.floor(d_min), math.ceil(d_max)
    if not (math.isfinite(d_min) and math.isfinite(d_max)) or hi <= lo:
        raise ValueError(f"d_max must be above d_min, got d_min={d_min}, d_max={d_max}")
    if hi - lo > 64:
        raise ValueError(f"at most 65 integer disparities, got [{lo}, {hi}]")
    return list(range(lo, hi + 1))


def check_config(angular: int, d_min: float, d_max: float) -> None:
    """ValueError for parameters the network cannot be built with (before anything is allocated)."""
    if not isinstance(angular, int) or angular < 3 or angular % 2 == 0:
        raise ValueError(f"angular must be an odd number of views per row (3, 5, 7, 9, ...), got {angular}")
    disparity_grid(float(d_min), float(d_max))


def view_offsets(angular: int) -> tuple[list[int], list[int]]:
    """(column offsets, row offsets) s_k = (k % A - c, k // A - c) of the A^2 views, c = A // 2."""
    c = angular // 2
    return [k % angular - c for k in range(angular * angular)], [k // angular - c for k in range(angular * angular)]


def _conv133(cin: int, cout: int, bias: bool = False) -> nn.Conv3d:
    """A per-view 3x3 convolution over (views, H, W)."""
    return nn.Conv3d(cin, cout, kernel_size=(1, 3, 3), stride=1, padding=(0, 1, 1), bias=bias)


def _conv333(cin: int, cout: int) -> nn.Conv3d:
    return nn.Conv3d(cin, cout, kernel_size=3, stride=1, padding=1, bias=False)


class ResB(nn.Module):
    """Per-view residual block of the feature extractor (its convolutions carry a bias, as the authors')."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv = nn.Sequential(_conv133(channels, channels, bias=True), nn.BatchNorm3d(channels),
                                  nn.LeakyReLU(0.1, inplace=True), _conv133(channels, channels, bias=True),
                                  nn.BatchNorm3d(channels))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x + self.conv(x)


class CALayer(nn.Module):
    """Channel attention per disparity: mean over (H, W), 1x1x1 conv C -> C/16, BN, LReLU, C/16 -> C, BN,
    sigmoid; the input scaled by it."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.conv_du = nn.Sequential(
            nn.Conv3d(channels, channels // 16, 1, 1, 0, bias=True), nn.BatchNorm3d(channels // 16),
            nn.LeakyReLU(0.1, inplace=True), nn.Conv3d(channels // 16, channels, 1, 1, 0, bias=True),
            nn.BatchNorm3d(channels), nn.Sigmoid())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return x * self.conv_du(x.mean(dim=(3, 4), keepdim=True))


class ResB3D(nn.Module):
    """Residual block of the aggregation: conv, BN, LReLU, conv, BN, channel attention, plus the input."""

    def __init__(self, channels: int) -> None:
        super().__init__()
        self.body = nn.Sequential(_conv333(channels, channels), nn.BatchNorm3d(channels),
                                  nn.LeakyReLU(0.1, inplace=True), _conv333(channels, channels),
                                  nn.BatchNorm3d(channels))
        self.calayer = CALayer(channels)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.calayer(self.body(x)) + x


def _conv_bn_relu(cin: int, cout: int, kernel: int) -> nn.Sequential:
    conv = nn.Conv3d(cin, cout, kernel, 1, kernel // 2, bias=False)
    return nn.Sequential(conv, nn.BatchNorm3d(cout), nn.LeakyReLU(0.1, inplace=True))


class Aggregate(nn.Module):
    """Cost aggregation and soft argmin: cost (B, 512, D, H, W) -> (disparity (B, H, W), probability
    (B, D, H, W)); ``projected``: the cost already went through ``sq.0`` (160 channels)."""

    def __init__(self, cin: int, channels: int) -> None:
        super().__init__()
        self.sq = _conv_bn_relu(cin, channels, 1)
        self.Conv1 = _conv_bn_relu(channels, channels, 3)
        self.Conv2 = _conv_bn_relu(channels, channels, 3)
        self.Resb1 = ResB3D(channels)
        self.Resb2 = ResB3D(channels)
        self.Conv3 = _conv_bn_relu(channels, channels, 3)
        self.Conv4 = _conv333(channels, 1)

    def forward(self, cost: torch.Tensor, disparities: torch.Tensor, projected: bool = False
                ) -> tuple[torch.Tensor, torch.Tensor]:
        x = self.sq[1:](cost) if projected else self.sq(cost)
        for block in (self.Conv1, self.Conv2, self.Resb1, self.Resb2, self.Conv3):
            x = block(x)
        prob = torch.softmax(self.Conv4(x).squeeze(1), dim=1)  # (B, D, H, W)
        disparity = (prob * disparities.to(prob.dtype).view(1, -1, 1, 1)).sum(dim=1)
        return disparity, prob


class ModulateConv2d(nn.Module):
    """The modulated convolution's weight: a grouped 1x1 convolution of C x A^2 inputs (C groups of A^2
    views) to ``cout`` outputs (``fuse``, the authors' name); applied by :func:`modulated_cost`."""

    def __init__(self, channel_in: int, channel_out: int, angular: int) -> None:
        super().__init__()
        self.fuse = nn.Conv2d(channel_in * angular * angular, channel_out, kernel_size=1, stride=1, padding=0,
                              bias=False, groups=channel_in)


class BuildCost(nn.Module):
    """The occlusion-aware cost constructor (holds ``oacc``, the modulated convolution)."""

    def __init__(self, channel_in: int, channel_out: int, angular: int) -> None:
        super().__init__()
        self.oacc = ModulateConv2d(channel_in, channel_out, angular)
        self.angular = angular

    def forward(self, feat: torch.Tensor, mask: torch.Tensor | None, disparities: list[int],
                project: torch.Tensor | None = None) -> torch.Tensor:
        """feat (B, C, N, H, W), mask (B, N, H, W) or None (all ones) -> cost (B, O, D, H, W); ``project``
        (P, O): a 1x1x1 convolution applied to the cost, folded into the constructor's weight (O = P)."""
        return modulated_cost(feat, mask, self.oacc.fuse.weight, disparities, self.angular, project)


def modulated_cost(feat: torch.Tensor, mask: torch.Tensor | None, weight: torch.Tensor, disparities: list[int],
                   angular: int, project: torch.Tensor | None = None, band_elements: int = BAND_ELEMENTS
                   ) -> torch.Tensor:
    """The modulated dilated convolution at each disparity, without unfolding.

    feat (B, C, N, H, W) view features, mask (B, N, H, W) or None (every mask 1), weight (O, N, 1, 1) of a
    grouped 1x1 convolution over the C x N inputs ordered channel-major (C groups), ``project`` (P, O) or
    None -> (B, P or O, D, H, W):

        cost[o, d, p] = sum_k weight[o, k] m_k(p) / mean_k m_k(p) * feat[c(o), k, p - s_k d]

    (zero outside the image; c(o) = o // (O / C)). The shifted views are a strided view of the zero-padded
    features (view k at row offset -(row_k - c) d, column offset -(col_k - c) d: one stride per angular
    axis); they are masked and contracted with the weight in bands of rows of about ``band_elements``,
    so neither the unfolded C x N-channel tensor nor (with ``project``) the O-channel cost exists at once.
    """
    b, ch, n, h, w = feat.shape
    a = angular
    c = a // 2
    r = c * max(abs(d) for d in disparities)
    padded = F.pad(feat, (r, r, r, r)).contiguous()
    sb, sc, sn, sh, _ = padded.stride()
    out_ch = weight.shape[0]
    group = weight.view(ch, out_ch // ch, n)  # (C, O/C, N): group g reads the N views of channel g
    dense = None
    if project is not None:  # (P, O) @ blockdiag(groups) = (P, C * N)
        dense = torch.einsum("pgo,gon->pgn", project.reshape(project.shape[0], ch, out_ch // ch), group)
        dense = dense.reshape(project.shape[0], ch * n)
    if mask is not None:
        mask = (mask / mask.mean(dim=1, keepdim=True)).view(b, 1, a, a, h, w)
    rows = max(1, min(h, band_elements // max(1, b * ch * n * w)))
    cost = feat.new_empty((b, out_ch if dense is None else dense.shape[0], len(disparities), h, w))
    # without gradients: the bands go through one reused buffer and the products straight into the cost
    inplace = dense is not None and not (torch.is_grad_enabled() and any(
        t is not None and t.requires_grad for t in (feat, mask, weight, project)))
    if inplace:
        buffer = torch.empty(b * ch * n * rows * w, dtype=feat.dtype, device=feat.device)
        dense = dense.to(feat.dtype)
        mask = None if mask is None else mask.to(feat.dtype)
    for i, d in enumerate(disparities):
        shifted = padded.as_strided((b, ch, a, a, h, w), (sb, sc, a * sn - d * sh, sn - d, sh, 1),
                                    padded.storage_offset() + (r + c * d) * sh + (r + c * d))
        for y0 in range(0, h, rows):
            y1 = min(h, y0 + rows)
            if inplace:
                band = buffer[:b * ch * n * (y1 - y0) * w].view(b, ch, a, a, y1 - y0, w)
                if mask is not None:
                    torch.mul(shifted[..., y0:y1, :], mask[..., y0:y1, :], out=band)
                else:
                    band.copy_(shifted[..., y0:y1, :])
                for k in range(b):
                    torch.mm(dense, band[k].view(ch * n, -1), out=cost[k, :, i].view(-1, h * w)[:, y0 * w:y1 * w])
                continue
            band = shifted[..., y0:y1, :]
            band = band * mask[..., y0:y1, :] if mask is not None else band.contiguous()
            if dense is not None:
                out = torch.matmul(dense, band.reshape(b, ch * n, -1))
            else:
                out = torch.matmul(group, band.reshape(b, ch, n, -1)).reshape(b, out_ch, -1)
            cost[:, :, i, y0:y1, :] = out.view(b, -1, y1 - y0, w)
    return cost


def occlusion_mask(views: torch.Tensor, disparity: torch.Tensor, angular: int) -> torch.Tensor:
    """The authors' occlusion mask: views (B, N, H, W), disparity (B, H, W) px -> (B, N, H, W)
    ``(1 - |view_k(q_k) - centre(p)|)^2`` (1 for the centre view), view k sampled bilinearly (zero outside)
    at q_k = (x W / (W - 1) - 1/2 - (col_k - c) d(p), y H / (H - 1) - 1/2 - (row_k - c) d(p)) for p = (x, y):
    the authors' grid (``linspace(0, 1, W)`` shifted by d / W, read by ``grid_sample`` without aligned
    corners), whose scale W / (W - 1) is theirs."""
    b, n, h, w = views.shape
    cols, rows = view_offsets(angular)
    su = torch.tensor(cols, dtype=views.dtype, device=views.device).view(1, n, 1, 1)
    sv = torch.tensor(rows, dtype=views.dtype, device=views.device).view(1, n, 1, 1)
    d = disparity.to(views.dtype).unsqueeze(1)  # (B, 1, H, W)
    xs = torch.linspace(0, 1, w, dtype=views.dtype, device=views.device).view(1, 1, 1, w)
    ys = torch.linspace(0, 1, h, dtype=views.dtype, device=views.device).view(1, 1, h, 1)
    gx = 2 * (xs - su * d / w) - 1  # (B, N, H, W), normalised as the authors' 2 * flow - 1
    gy = 2 * (ys - sv * d / h) - 1
    grid = torch.stack((gx, gy), dim=-1).reshape(b * n, h, w, 2)
    warped = F.grid_sample(views.reshape(b * n, 1, h, w), grid, mode="bilinear", padding_mode="zeros",
                           align_corners=False).view(b, n, h, w)
    centre = views[:, n // 2: n // 2 + 1]
    mask = (1 - (warped - centre).abs()) ** 2
    mask[:, n // 2] = 1.0
    return mask


class OACCNet(nn.Module):
    """OACC-Net (Wang et al., CVPR 2022): views (B, N, H, W) -> (disparity (B, H, W), softmax (B, D, H, W)).

    Whole images only: the channel attention pools over the whole image, so an output pixel depends on
    every pixel (no receptive radius; exact tiles do not exist)."""

    def __init__(self, angular: int = 9, d_min: float = -4.0, d_max: float = 4.0) -> None:
        """angular: views per angular row (odd), d_min / d_max: the disparity range in px (integer grid
        floor(d_min) .. ceil(d_max)) (the declared parameters, with help and bounds: OACCNetTrainable.build)."""
        super().__init__()
        check_config(angular, d_min, d_max)
        self.angular = angular
        self._config = {"angular": int(angular), "d_min": float(d_min), "d_max": float(d_max)}
        self.grid = disparity_grid(float(d_min), float(d_max))
        self.register_buffer("disparities", torch.tensor(self.grid, dtype=torch.float32), persistent=False)
        self.init_feature = nn.Sequential(
            _conv133(1, 16), nn.BatchNorm3d(16), *[ResB(16) for _ in range(8)],
            _conv133(16, 16), nn.BatchNorm3d(16), nn.LeakyReLU(0.1, inplace=True),
            _conv133(16, FEATURE_CHANNELS), nn.BatchNorm3d(FEATURE_CHANNELS), nn.LeakyReLU(0.1, inplace=True))
        self.lastconv = _conv133(FEATURE_CHANNELS, FEATURE_CHANNELS)
        self.build_cost = BuildCost(FEATURE_CHANNELS, COST_CHANNELS, angular)
        self.aggregate = Aggregate(COST_CHANNELS, AGG_CHANNELS)

    def config(self) -> dict[str, Any]:
        return dict(self._config)

    def features(self, views: torch.Tensor) -> torch.Tensor:
        """views (B, N, H, W) -> per-view features (B, 8, N, H, W), computed channels-last after the first
        convolution (oneDNN runs these 16-channel convolutions 2-2.5x faster so on the CPU); in eval mode with
        each batch norm folded into the convolution before it (:meth:`_eval_features`)."""
        if not self.training:
            return self._eval_features(views)
        x = self.init_feature[0](views.unsqueeze(1)).contiguous(memory_format=torch.channels_last_3d)
        return self.lastconv(self.init_feature[1:](x))

    def _eval_features(self, views: torch.Tensor) -> torch.Tensor:
        """The feature extractor with its running batch statistics folded into the convolutions: the same
        function in eval mode, without 19 passes of batch norm over the 16-channel features of every view."""
        seq = self.init_feature

        def conv(x: torch.Tensor, conv: nn.Conv3d, bn: nn.BatchNorm3d | None = None, relu: bool = False
                 ) -> torch.Tensor:
            weight, bias = conv.weight, conv.bias
            if bn is not None:
                scale = bn.weight / torch.sqrt(bn.running_var + bn.eps)
                weight = weight * scale.view(-1, 1, 1, 1, 1)
                bias = (bn.bias - bn.running_mean * scale if bias is None
                        else (bias - bn.running_mean) * scale + bn.bias)
            y = F.conv3d(x, weight, bias, padding=(0, 1, 1))
            return F.leaky_relu(y, 0.1, inplace=True) if relu else y

        x = conv(views.unsqueeze(1), seq[0], seq[1]).contiguous(memory_format=torch.channels_last_3d)
        for block in seq[2:10]:
            body = block.conv
            x = conv(conv(x, body[0], body[1], relu=True), body[3], body[4]).add_(x)
        x = conv(conv(x, seq[10], seq[11], relu=True), seq[13], seq[14], relu=True)
        return conv(x, self.lastconv)

    def estimate(self, feat: torch.Tensor, mask: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """One pass of cost construction and aggregation with ``mask`` (None: all ones)."""
        project = self.aggregate.sq[0].weight.flatten(1)  # (160, 512): the 1x1x1 conv folded in
        cost = modulated_cost(feat, mask, self.build_cost.oacc.fuse.weight, self.grid, self.angular, project)
        return self.aggregate(cost, self.disparities, projected=True)

    def forward(self, views: torch.Tensor, target: torch.Tensor | None = None
                ) -> tuple[torch.Tensor, torch.Tensor]:
        """Two passes (the second with the occlusion mask of the first's disparity); with ``target``
        (B, H, W) px, the ground truth in training, one pass with the mask of the target."""
        if views.dim() != 4 or views.shape[1] != self.angular ** 2:
            raise ValueError(f"expected views (B, {self.angular ** 2}, H, W), got {tuple(views.shape)}")
        feat = self.features(views)
        if target is not None:
            return self.estimate(feat, occlusion_mask(views, target, self.angular))
        disparity, _ = self.estimate(feat, None)
        return self.estimate(feat, occlusion_mask(views, disparity, self.angular))

    def flops(self, height: int, width: int) -> dict[str, float]:
        """FLOPs (2 per multiply-add) of one eval forward on an H x W light field, by part (as run here)."""
        px, n, dd = height * width, self.angular ** 2, len(self.grid)
        per_view = 2 * 9 * px * n
        features = per_view * (16 + 16 * 16 * 2 * 8 + 16 * 16 + 16 * 8 + 8 * 8)
        cost = 2 * FEATURE_CHANNELS * n * AGG_CHANNELS * dd * px
        conv3 = 2 * 27 * AGG_CHANNELS * AGG_CHANNELS * dd * px
        aggregation = 7 * conv3 + 2 * 27 * AGG_CHANNELS * dd * px
        return {"total": float(features + 2 * (cost + aggregation)), "features": float(features),
                "cost": float(2 * cost), "aggregation": float(2 * aggregation)}


__all__ = ["OACCNet", "modulated_cost", "occlusion_mask", "disparity_grid", "check_config", "view_offsets"]
