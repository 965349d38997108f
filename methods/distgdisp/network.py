"""DistgDisp (Wang et al., TPAMI 2022, "Disentangling Light Fields for Super-Resolution and Disparity
Estimation") in PyTorch: the authors' network, layer for layer, with their module names (a released
``{'state_dict': ...}`` loads as it is).

Shapes and units: views (B, N, H, W) float32 gray in [0, 1], N = A^2, view k at angular row k // A,
column k % A (A = ``angular``); features (B * N, F, H, W) (row b * N + n); cost volume (B, C, D, H, W);
cost and probability (B, D, H, W); disparity (B, H, W) in px per view step, HCI's sign (the authors'
own: they train on HCI's ground truth with the views in HCI's file order).

The authors' layers and how they run here:

- ``init_feature``: 3x3 convolutions of dilation A and padding A on the macro-pixel image (MacPI: pixel
  (h, w) of view (u, v) at (h A + u, w A + v)). Such a convolution only ever combines pixels of one view,
  and its zero padding is each view's, so it is the same 3x3 convolution (dilation 1, padding 1) applied
  to every view: that is how it runs (the weights are the same tensors). BatchNorm statistics over the
  MacPI are those over all views and pixels, as here.
- ``build_costvolume.DSAFE``: the disparity-selective angular feature extractor, an A x A convolution of
  stride A (F -> C channels) applied for every integer disparity d of the grid with dilation
  ``d A - 1`` and padding ``A (A - 1) d / 2 - A + 1`` for d > 0, dilation ``|d| A + 1`` and padding
  ``A (A - 1) |d| / 2`` for d < 0, dilation 1 and padding 0 for d = 0. Worked out, tap (i, j) then reads
  view (u, v) at pixel (h - d (u - c), w - d (v - c)) (zero outside the image), c = (A - 1) / 2, with
  (u, v) = (i, j) for d <= 0 and (u, v) = (A - 1 - i, A - 1 - j) for d > 0: the authors' padding makes
  the kernel see the views in reverse order at positive disparities (kept: it is their network). Here
  each disparity is one matrix product of the shifted views' features with the kernel.
- ``aggregation``: 3x3x3 convolutions over (D, H, W) (zero padding also along D), BatchNorm3d, LeakyReLU
  0.1, two 3D residual blocks, down to one channel; ``regression``: softmax over D of the cost (not of
  its negative) and the expected disparity.

The disparity grid is the authors' integers, from floor(d_min) to ceil(d_max) (their [-4, 4] on HCI; the
SubFocal paper's Table III [-1, 2] for UrbanLF-Syn's [-0.5, 1.6]). Eval mode without autograd runs folded
BatchNorm and in-place activations on channels-last memory (the same numbers up to float rounding).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from lfbench_methods.distgdisp.trainable import CHANNELS, FEATURES, MAX_ABS_DISPARITY, MAX_ANGULAR
from torch import nn

NEG_SLOPE = 0.1  # LeakyReLU
SPATIAL_RES_BLOCKS = 8  # SpaResB in init_feature
AGG_RES_BLOCKS = 2  # ResB3D in aggregation
#: values of the stacked shifted views multiplied at a time in inference (8 MB in fp32: a cache's worth)
STACK_BLOCK_VALUES = 1 << 21
#: 3x3 convolutions of the feature extractor in a row (2 + 2 per residual block + 2): its radius in px.
FEATURE_RADIUS = 2 + 2 * SPATIAL_RES_BLOCKS + 2
#: 3x3x3 convolutions of the aggregation in a row (2 + 2 per residual block + 2).
AGGREGATION_RADIUS = 2 + 2 * AGG_RES_BLOCKS + 2


def disparity_range(d_min: float, d_max: float) -> tuple[int, int]:
    """The authors' integer grid covering [d_min, d_max]: (floor(d_min), ceil(d_max)); ValueError for a bad range."""
    try:
        lo, hi = float(d_min), float(d_max)
    except (TypeError, ValueError):
        raise ValueError(f"d_min and d_max must be numbers, got {d_min!r}, {d_max!r}") from None
    if not (math.isfinite(lo) and math.isfinite(hi)) or hi <= lo:
        raise ValueError(f"need finite d_min < d_max, got [{d_min}, {d_max}]")
    a, b = math.floor(lo + 1e-9), math.ceil(hi - 1e-9)
    if max(abs(a), abs(b)) > MAX_ABS_DISPARITY:
        raise ValueError(f"disparities beyond +-{MAX_ABS_DISPARITY} px per view step are not supported, "
                         f"got [{d_min}, {d_max}]")
    return a, b


def dsafe_geometry(d: int, angular: int) -> tuple[int, int]:
    """(dilation, padding) of the authors' DSAFE convolution on the MacPI at integer disparity ``d``."""
    a = angular
    if d < 0:
        return -d * a + 1, a * (a - 1) * -d // 2
    if d > 0:
        return d * a - 1, a * (a - 1) * d // 2 - a + 1
    return 1, 0


def check_config(angular: int = 9, d_min: float = -4.0, d_max: float = 4.0, features: int = FEATURES,
                 channels: int = CHANNELS) -> None:
    """ValueError for parameters the network cannot be built with (before anything is allocated)."""
    if not isinstance(angular, int) or isinstance(angular, bool) or not 2 <= angular <= MAX_ANGULAR:
        raise ValueError(f"angular must be an integer in [2, {MAX_ANGULAR}], got {angular!r}")
    if angular % 2 == 0:
        raise ValueError(f"angular must be odd (the views have a centre; DSAFE's padding needs A (A - 1) d / 2 "
                         f"whole), got {angular}")
    disparity_range(d_min, d_max)
    for name, value in (("features", features), ("channels", channels)):
        if not isinstance(value, int) or isinstance(value, bool) or not 1 <= value <= 1024:
            raise ValueError(f"{name} must be an integer in [1, 1024], got {value!r}")


def _conv_bn(cin: int, cout: int) -> list[nn.Module]:
    return [nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout)]


def _conv_bn3d(cin: int, cout: int) -> list[nn.Module]:
    return [nn.Conv3d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm3d(cout)]


class _Residual(nn.Module):
    """(conv, BN, LeakyReLU, conv, BN) + input, as the authors' ``body``."""

    def __init__(self, conv_bn, channels: int) -> None:
        super().__init__()
        self.body = nn.Sequential(*conv_bn(channels, channels), nn.LeakyReLU(NEG_SLOPE, inplace=True),
                                  *conv_bn(channels, channels))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.body(x) + x


class SpaResB(_Residual):
    """The authors' spatial residual block (3x3 convolutions of every view)."""

    def __init__(self, channels: int) -> None:
        super().__init__(_conv_bn, channels)


class ResB3D(_Residual):
    """The authors' 3D residual block (3x3x3 convolutions over disparity and space)."""

    def __init__(self, channels: int) -> None:
        super().__init__(_conv_bn3d, channels)


class BuildCostVolume(nn.Module):
    """The disparity-selective angular feature extractor (DSAFE) at every disparity of the grid.

    features (B * N, F, H, W) (row b * N + n) -> cost volume (B, C, D, H, W) (channels-last-3d memory)."""

    def __init__(self, channel_in: int, channel_out: int, angular: int, d_lo: int, d_hi: int) -> None:
        super().__init__()
        self.DSAFE = nn.Conv2d(channel_in, channel_out, angular, stride=angular, padding=0, bias=False)  # noqa: N815
        self.angular, self.d_lo, self.d_hi = angular, d_lo, d_hi

    def kernel(self, d: int) -> torch.Tensor:
        """(C, N * F) matrix of disparity ``d``: column n * F + f is view n's feature f (see the module docstring:
        the taps are the views in reverse order for d > 0)."""
        w = self.DSAFE.weight
        if d > 0:
            w = w.flip(-1, -2)
        return w.permute(0, 2, 3, 1).reshape(w.shape[0], -1)

    def forward(self, feats: torch.Tensor) -> torch.Tensor:
        a = self.angular
        n = a * a
        bn_, f, h, w = feats.shape
        b = bn_ // n
        c = (a - 1) // 2
        pad = c * max(abs(self.d_lo), abs(self.d_hi))
        # (B, H + 2P, W + 2P, N, F): zero-padded, channels innermost, so that a shifted view is a strided slice
        x = feats.reshape(b, n, f, h, w).permute(0, 3, 4, 1, 2)
        x = F.pad(x, (0, 0, 0, 0, pad, pad, pad, pad))
        disps = range(self.d_lo, self.d_hi + 1)
        grad = torch.is_grad_enabled() and (feats.requires_grad or self.DSAFE.weight.requires_grad)
        cout = self.DSAFE.out_channels
        if grad:  # autograd: one product per disparity
            slabs = [self._shifted(x, d, 0, h, w, pad) @ self.kernel(d).t() for d in disps]
            return torch.stack(slabs, dim=0).permute(1, 4, 0, 2, 3)
        out = feats.new_empty((len(disps), b, h, w, cout))  # out[i] contiguous
        # A block of rows at a time: the stacked views of a block (~STACK_BLOCK_VALUES values) stay in the cache
        # for their product instead of going to memory and back (340 MB per disparity at 256 x 256 px); each
        # output pixel is the same product of the same row, so the values are those of one product per disparity.
        rows = max(1, STACK_BLOCK_VALUES // max(1, w * n * f))
        for i, d in enumerate(disps):
            kernel = self.kernel(d).t().to(feats.dtype)
            for k in range(b):
                for top in range(0, h, rows):
                    bottom = min(h, top + rows)
                    stacked = self._shifted(x[k:k + 1], d, top, bottom, w, pad)
                    torch.mm(stacked.reshape(-1, n * f), kernel, out=out[i, k, top:bottom].view(-1, cout))
        return out.permute(1, 4, 0, 2, 3)  # (B, C, D, H, W); channels-last-3d memory for B = 1

    def _shifted(self, x: torch.Tensor, d: int, top: int, bottom: int, w: int, pad: int) -> torch.Tensor:
        """Rows ``top:bottom`` of every view shifted by disparity ``d``, stacked: (B, rows, W, N * F) from the
        padded (B, H + 2P, W + 2P, N, F) features ``x``."""
        a = self.angular
        c = (a - 1) // 2
        views = [x[:, pad - d * (u - c) + top:pad - d * (u - c) + bottom, pad - d * (v - c):pad - d * (v - c) + w,
                   u * a + v] for u in range(a) for v in range(a)]
        return torch.stack(views, dim=3).reshape(x.shape[0], bottom - top, w, -1)


class Regression(nn.Module):
    """Softmax over the disparities of the cost, and the expected disparity (the authors' soft argmax)."""

    def forward(self, cost: torch.Tensor, disparities: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        prob = torch.softmax(cost.float(), dim=1)
        return (prob * disparities.to(prob)[None, :, None, None]).sum(dim=1), prob


class DistgDispNet(nn.Module):
    """DistgDisp: per-view spatial features, DSAFE cost volume at integer disparities, 3D aggregation, soft argmin."""

    def __init__(self, angular: int = 9, d_min: float = -4.0, d_max: float = 4.0, features: int = FEATURES,
                 channels: int = CHANNELS) -> None:
        """angular: views per angular row (odd), d_min / d_max: the disparity range in px (integer grid
        floor(d_min) .. ceil(d_max)), features / channels: the authors' 16 / 160 (the declared parameters,
        with help and bounds: DistgDispTrainable.build)."""
        super().__init__()
        check_config(angular, d_min, d_max, features, channels)
        self._config = {"angular": angular, "d_min": float(d_min), "d_max": float(d_max), "features": features,
                        "channels": channels}
        self.angular = angular
        lo, hi = disparity_range(d_min, d_max)
        fc, ch = features, channels
        lrelu = nn.LeakyReLU(NEG_SLOPE, inplace=True)
        self.init_feature = nn.Sequential(
            *_conv_bn(1, fc), lrelu, *_conv_bn(fc, fc), lrelu,
            *(SpaResB(fc) for _ in range(SPATIAL_RES_BLOCKS)),
            *_conv_bn(fc, fc), lrelu, nn.Conv2d(fc, fc, 3, padding=1, bias=False))
        self.build_costvolume = BuildCostVolume(fc, ch, angular, lo, hi)
        self.aggregation = nn.Sequential(
            *_conv_bn3d(ch, ch), lrelu, *_conv_bn3d(ch, ch), lrelu,
            *(ResB3D(ch) for _ in range(AGG_RES_BLOCKS)),
            *_conv_bn3d(ch, ch), lrelu, nn.Conv3d(ch, 1, 3, padding=1, bias=False))
        self.regression = Regression()
        # not in the state dict: the authors' checkpoints hold none
        self.register_buffer("disparities", torch.arange(lo, hi + 1, dtype=torch.float32), persistent=False)
        #: px of context one output pixel depends on: the features' 3x3 stack, the farthest view shift
        #: (c * max |d|) and the aggregation's 3x3x3 stack (exact tiled inference)
        self.receptive_radius = FEATURE_RADIUS + (angular - 1) // 2 * max(abs(lo), abs(hi)) + AGGREGATION_RADIUS
        self.fast_inference = True

    def config(self) -> dict:
        """The constructor's keyword arguments (stored in checkpoints)."""
        return dict(self._config)

    def uses_fast_path(self) -> bool:
        return self.fast_inference and not self.training and not torch.is_grad_enabled()

    def features(self, views: torch.Tensor) -> torch.Tensor:
        """views (B, N, H, W) -> (B * N, F, H, W), row b * N + n (channels-last on the fast path)."""
        b, n, h, w = views.shape
        if n != self.angular ** 2:
            raise ValueError(f"expected {self.angular ** 2} views ({self.angular}x{self.angular}), got {n}")
        x = views.reshape(b * n, 1, h, w)  # row b * N + n: sample b, view n
        if self.uses_fast_path():
            return _run_folded(self.init_feature, x.contiguous(memory_format=torch.channels_last))
        return self.init_feature(x)

    def forward(self, views: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """views (B, N, H, W) -> (disparity (B, H, W), probability (B, D, H, W))."""
        feats = self.features(views)
        volume = self.build_costvolume(feats)
        if self.uses_fast_path():
            cost = _run_folded(self.aggregation, volume)
        else:
            cost = self.aggregation(volume)
        return self.regression(cost[:, 0], self.disparities)

    def flops(self, height: int, width: int) -> dict[str, float]:
        """FLOPs (2 per multiply-add) of one forward pass on an H x W light field, by part."""
        n, px = self.angular ** 2, height * width
        fc, ch = self._config["features"], self._config["channels"]
        d = self.disparities.numel()
        convs2d = [m for m in self.init_feature.modules() if isinstance(m, nn.Conv2d)]
        convs3d = [m for m in self.aggregation.modules() if isinstance(m, nn.Conv3d)]
        feats = sum(2.0 * n * px * m.weight.numel() for m in convs2d)
        dsafe = 2.0 * d * px * ch * fc * n
        agg = sum(2.0 * d * px * m.weight.numel() for m in convs3d)
        return {"total": feats + dsafe + agg, "features": feats, "cost_volume": dsafe, "aggregation": agg}


def _folded(conv: nn.Module, bn: nn.Module | None) -> tuple[torch.Tensor, torch.Tensor | None]:
    """Weight and bias of ``conv`` followed by eval-mode ``bn`` (None: the conv's own)."""
    if bn is None:
        return conv.weight, conv.bias
    scale = bn.weight * torch.rsqrt(bn.running_var + bn.eps)
    shape = (-1,) + (1,) * (conv.weight.dim() - 1)
    return conv.weight * scale.reshape(shape), bn.bias - bn.running_mean * scale


def _fused() -> bool:
    """Whether oneDNN's fused convolutions (conv + activation, conv + in-place add) run here (SubFocal's check)."""
    from lfbench_methods.subfocal.fast import fused_ops_work

    return fused_ops_work()


def _conv(m: nn.Module, bn: nn.Module | None, x: torch.Tensor, leaky: bool, add_to: torch.Tensor | None
          ) -> torch.Tensor:
    """Eval-mode ``bn(m(x))`` as one convolution, then LeakyReLU 0.1 (``leaky``) or ``add_to +=`` it in place:
    fused by oneDNN on the CPU in fp32 (one pass over the output instead of two or three), else separate ops."""
    weight, bias = _folded(m, bn)
    dims = weight.dim() - 2
    if x.device.type == "cpu" and x.dtype == torch.float32 and not torch.is_autocast_enabled("cpu") and _fused():
        fmt = torch.channels_last if dims == 2 else torch.channels_last_3d
        ops = torch.ops.mkldnn
        args = (x.contiguous(memory_format=fmt), weight.contiguous(memory_format=fmt), bias, list(m.padding),
                [1] * dims, [1] * dims, 1)
        if add_to is not None:
            return ops._convolution_pointwise_.binary(add_to, *args, "add", 1.0, None, [], None)
        return ops._convolution_pointwise(*args, "leaky_relu" if leaky else "none", [NEG_SLOPE] if leaky else [], "")
    y = (F.conv3d if dims == 3 else F.conv2d)(x, weight, bias, padding=m.padding)
    if add_to is not None:
        return add_to.add_(y)
    return F.leaky_relu_(y, NEG_SLOPE) if leaky else y


def _run_folded(seq: nn.Sequential, x: torch.Tensor, add_to: torch.Tensor | None = None) -> torch.Tensor:
    """Eval-mode ``seq(x)`` with every convolution's BatchNorm folded into it and LeakyReLU fused or in place;
    a residual block (SpaResB, ResB3D) adds its input into its last convolution's output (``add_to``: what the
    last convolution of ``seq`` adds its result to, in place). Channels-last memory is kept."""
    mods = list(seq)
    i = 0
    while i < len(mods):
        m = mods[i]
        if isinstance(m, _Residual):
            x = _run_folded(m.body, x, add_to=x)
            i += 1
            continue
        bn = mods[i + 1] if i + 1 < len(mods) and isinstance(mods[i + 1], (nn.BatchNorm2d, nn.BatchNorm3d)) else None
        i += 2 if bn is not None else 1
        leaky = i < len(mods) and isinstance(mods[i], nn.LeakyReLU)
        last = i + leaky >= len(mods)
        x = _conv(m, bn, x, leaky, add_to if last else None)
        i += leaky
    return x


def count_trainable(module: nn.Module) -> int:
    """Number of trainable parameters (BatchNorm running statistics are buffers, not counted)."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)


def network_params():
    """The constructor's declared parameters."""
    from lfbench.method.params import signature_params

    return signature_params(DistgDispNet)


__all__ = ["DistgDispNet", "BuildCostVolume", "SpaResB", "ResB3D", "Regression", "check_config", "disparity_range",
           "dsafe_geometry", "count_trainable", "FEATURES", "CHANNELS", "FEATURE_RADIUS", "AGGREGATION_RADIUS"]
