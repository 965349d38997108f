"""The SubFocal network (Chao et al., TCI 2023) in PyTorch, faithful to the authors' Keras code.

Shapes and units: views (B, N, H, W) float32 gray in [0, 1] with channel k = view k (angular row
k // 9, column k % 9); features (B, N, 4, H, W); cost volume (B, 4N, D, H, W) with channel
4 * view + c (view-major, as the authors concatenate); cost and probability (B, D, H, W);
disparity (B, H, W) in px per view step.

Eval mode without autograd (``torch.no_grad`` / ``torch.inference_mode``) runs the fast path of
methods/subfocal/fast.py (folded BatchNorm, channels-last, fused oneDNN ops; the bilinear cost
volume gathered from interpolated maps): the same results up to float rounding. Eval with autograd
on runs the layer-by-layer modules below; ``net.fast_inference = False`` forces them. Training runs
them with four faster equivalents (``set_training_path("reference")`` turns them off): per-view
BatchNorm as one fused autograd function on the channels-last memory, the one-channel stem
convolution as a grouped convolution, the bilinear volume gathered with its attention applied
before the interpolation (methods/subfocal/volume.py), and, with AVX2 kernels, the weight gradients
of the 324-channel 3D and the dilated 2D convolutions as matrix products (methods/subfocal/weight_grad.py).

Conventions taken from Keras: BatchNorm eps 1e-3 and momentum 0.99 (PyTorch momentum 0.01),
glorot_uniform kernels, zero biases, 'same' average pooling that leaves padded cells out of the
mean, bilinear upsampling with align_corners=True. The shared feature extractor is applied to
every view; in training mode its BatchNorm layers normalise each view with the statistics of
that view's batch (Keras calls the shared model once per view) and update the running
statistics once per view, view 0 first.
"""

from __future__ import annotations

import functools
import math
import numbers
from typing import Annotated

import torch
import torch.nn.functional as F
from lfbench_methods.subfocal.weight_grad import check_weight_grad, training_conv
from torch import nn

from lfbench.data.shift import INTERPOLATIONS, angular_offsets, disparity_grid, shift_views
from lfbench.method.params import Param, Range, signature_params

BN_EPS = 1e-3
BN_MOMENTUM = 0.01  # Keras momentum 0.99
FEATURES = 4  # channels per view after the extractor
MAX_WIDTH = 1024  # channels of the 3D aggregation (the paper: 150); bounds a stored config before allocation
MAX_ANGULAR = 15  # views per angular row (HCI: 9)
SPP_POOLS = (2, 4, 8, 16)


def _tile_rows(length: int, limit: int = 64) -> int:
    """The largest power of two <= ``limit`` dividing ``length``: rows of (L, C) folded into one (L/K, K*C) row,
    so that per-channel broadcasts run over long contiguous rows instead of C-element ones."""
    k = limit
    while k > 1 and length % k:
        k //= 2
    return k


#: Channels from which a CPU view batch norm runs PyTorch's own channels-last batch-norm kernels once per group
#: (fewer passes over memory) instead of the folded elementwise ops. Measured per layer, forward + backward,
#: G = 81, L = 4 x 32 x 32, 1 thread, AVX-512: C = 16 20 ms against 28-40 ms; C = 8 level; C = 4 four times
#: slower (4 channels do not fill a SIMD register). Whole width-16 training step (batch 4, 32 px), best of 3
#: interleaved rounds: 2.58 against 2.68 CPU s on AVX-512, 3.04 against 3.17 with AVX2 kernels.
NATIVE_BN_CHANNELS = 16


def _channels_last_rows(t: torch.Tensor) -> torch.Tensor:
    """(L, C) contiguous -> the same memory as a (1, C, L, 1) channels-last tensor (what ATen's batch norm reads)."""
    length, c = t.shape
    return t.view(1, length, 1, c).permute(0, 3, 1, 2)


def _native_forward(x: torch.Tensor, gamma: torch.Tensor, beta: torch.Tensor, eps: float):
    """y (G, L, C), mean and 1/sigma (G, C): ATen's training batch norm of every group into one output."""
    g, _, c = x.shape
    y, mean, invstd = torch.empty_like(x), x.new_empty(g, c), x.new_empty(g, c)
    for i in range(g):
        torch.ops.aten.native_batch_norm.out(_channels_last_rows(x[i]), gamma, beta, None, None, True, 0.0, eps,
                                             out=_channels_last_rows(y[i]), save_mean=mean[i], save_invstd=invstd[i])
    return y, mean, invstd


def _native_backward(dy: torch.Tensor, x: torch.Tensor, gamma: torch.Tensor, mean: torch.Tensor,
                     invstd: torch.Tensor, eps: float):
    """dx (G, L, C), dgamma, dbeta (C,) of :func:`_native_forward`, ATen's batch-norm backward per group."""
    g, _, c = x.shape
    dx, dgamma, dbeta = torch.empty_like(x), x.new_empty(g, c), x.new_empty(g, c)
    for i in range(g):
        torch.ops.aten.native_batch_norm_backward.out(
            _channels_last_rows(dy[i]), _channels_last_rows(x[i]), gamma, None, None, mean[i], invstd[i], True, eps,
            [True, True, True], out0=_channels_last_rows(dx[i]), out1=dgamma[i], out2=dbeta[i])
    return dx, dgamma.sum(0), dbeta.sum(0)


class _ViewBatchNormFn(torch.autograd.Function):
    """Training-mode batch norm of G groups at once, with its closed-form backward.

    x (G, L, C) float32 (L = samples x pixels of one group, C channels innermost: the memory of a
    channels-last (G * B, C, H, W) activation), gamma, beta (C,). Returns y (G, L, C), and (not
    differentiable) the per-group mean and biased variance (G, C). Statistics in two passes (mean, then
    the mean square of x - mean) with the rows folded K at a time into (G, L/K, K*C), so every pass is a
    plain reduction or a long contiguous broadcast; the backward is BatchNorm's
    dx = gamma / sigma * (dy - mean(dy) - xhat * mean(dy * xhat)) as two fused multiply-adds. On the CPU
    with at least :data:`NATIVE_BN_CHANNELS` channels, ATen's batch-norm kernels per group instead.
    """

    @staticmethod
    def forward(ctx, x: torch.Tensor, gamma: torch.Tensor, beta: torch.Tensor, eps: float):  # type: ignore[override]
        ctx.dtype = x.dtype
        if x.dtype in (torch.float16, torch.bfloat16):
            x = x.float()  # statistics in float32 under autocast (the next convolution casts again)
        g, length, c = x.shape
        ctx.native = (c >= NATIVE_BN_CHANNELS and x.device.type == "cpu" and x.is_contiguous()
                      and gamma.dtype == torch.float32)
        if ctx.native:
            y, mean, invstd = _native_forward(x, gamma, beta, eps)
            ctx.save_for_backward(x, mean, invstd, gamma)
            ctx.eps = eps
            var = invstd.pow(-2).sub_(eps)
            ctx.mark_non_differentiable(mean, var)
            return y, mean, var
        k = _tile_rows(length)
        xr = x.reshape(g, length // k, k * c)

        def channel_sum(t: torch.Tensor) -> torch.Tensor:  # (G, L/K, K*C) -> (G, 1, C)
            return t.sum(1).reshape(g, k, c).sum(1, keepdim=True)

        mean = channel_sum(xr) / length  # (G, 1, C)
        centred = xr - mean.repeat(1, 1, k)
        var = channel_sum(centred * centred) / length
        invstd = torch.rsqrt(var + eps)
        scale = (gamma.reshape(1, 1, c) * invstd).repeat(1, 1, k)
        y = torch.addcmul(beta.repeat(k), centred, scale)
        ctx.save_for_backward(centred, invstd, gamma)
        ctx.k = k
        mean_out, var_out = mean.reshape(g, c), var.reshape(g, c)
        ctx.mark_non_differentiable(mean_out, var_out)
        return y.reshape(g, length, c), mean_out, var_out

    @staticmethod
    def backward(ctx, dy: torch.Tensor, *_):  # type: ignore[override]
        if ctx.native:
            x, mean, invstd, gamma = ctx.saved_tensors
            dx, dgamma, dbeta = _native_backward(dy.to(x.dtype).contiguous(), x, gamma, mean, invstd, ctx.eps)
            return dx.to(ctx.dtype), dgamma, dbeta, None
        centred, invstd, gamma = ctx.saved_tensors
        g, rows, kc = centred.shape
        k = ctx.k
        c, length = kc // k, rows * ctx.k
        dyr = dy.to(centred.dtype).reshape(g, rows, kc)

        def channel_sum(t: torch.Tensor) -> torch.Tensor:
            return t.sum(1).reshape(g, k, c).sum(1, keepdim=True)

        sum_dy = channel_sum(dyr)  # (G, 1, C)
        sum_dy_centred = channel_sum(dyr * centred)
        k1 = gamma.reshape(1, 1, c) * invstd  # dx = k1 dy + k2 centred + k3
        k2 = -k1 * invstd * invstd * sum_dy_centred / length
        k3 = -k1 * sum_dy / length
        dx = torch.addcmul(k3.repeat(1, 1, k), dyr, k1.repeat(1, 1, k)).addcmul_(centred, k2.repeat(1, 1, k))
        dgamma = (invstd * sum_dy_centred).sum((0, 1))
        return dx.reshape(g, length, c).to(ctx.dtype), dgamma, sum_dy.sum((0, 1)), None


class ViewBatchNorm2d(nn.BatchNorm2d):
    """BatchNorm2d whose training statistics are taken per view group.

    The input (G * B, C, H, W) holds G view groups of B samples each (group-major). In training
    every group is normalised with its own mean and biased variance, and the running statistics
    receive G successive exponential updates (unbiased variance), group 0 first, in closed form.
    In eval mode (or with one group) this is a plain BatchNorm2d.

    ``reference = True`` computes the training statistics with separate elementwise ops (the original
    implementation, kept for the tests and the ``reference`` training bench); the default is
    :class:`_ViewBatchNormFn` on the channels-last memory (the same numbers up to float rounding).
    """

    reference = False

    def forward(self, x: torch.Tensor, groups: int = 1) -> torch.Tensor:  # type: ignore[override]
        if not self.training or groups <= 1:
            return super().forward(x)
        gb, c, h, w = x.shape
        if gb % groups:
            raise ValueError(f"batch {gb} is not a multiple of {groups} view groups")
        if self.reference:
            out, mean, var = self._reference_forward(x, groups)
        else:
            # (G * B, C, H, W) channels-last is (G, B * H * W, C) in memory: a view, not a copy.
            y, mean, var = _ViewBatchNormFn.apply(x.permute(0, 2, 3, 1).reshape(groups, -1, c), self.weight,
                                                  self.bias, self.eps)
            out = y.reshape(gb, h, w, c).permute(0, 3, 1, 2)
        self._update_running(mean, var, (gb // groups) * h * w, groups)
        return out

    def _reference_forward(self, x: torch.Tensor, groups: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        gb, c, h, w = x.shape
        xg = x.reshape(groups, gb // groups, c, h, w)
        var, mean = torch.var_mean(xg, dim=(1, 3, 4), unbiased=False)  # (G, C)
        out = (xg - mean[:, None, :, None, None]) * torch.rsqrt(var + self.eps)[:, None, :, None, None]
        out = out * self.weight[None, None, :, None, None] + self.bias[None, None, :, None, None]
        return out.reshape(gb, c, h, w), mean, var

    def _update_running(self, mean: torch.Tensor, var: torch.Tensor, n: int, groups: int) -> None:
        """G successive running-statistics updates from per-group mean and biased variance (G, C) of n values."""
        if not self.track_running_stats or self.running_mean is None:
            return
        with torch.no_grad():
            mean, var = mean.detach(), var.detach()
            unbiased = var * (n / max(n - 1, 1))
            m = self.momentum if self.momentum is not None else 0.1
            # m_G = (1-m)^G m_0 + sum_g m (1-m)^(G-1-g) s_g: the sequential updates, group 0 first.
            decay = (1.0 - m) ** torch.arange(groups - 1, -1, -1, device=mean.device, dtype=var.dtype)
            self.running_mean.mul_((1.0 - m) ** groups).add_((m * decay[:, None] * mean).sum(0))
            self.running_var.mul_((1.0 - m) ** groups).add_((m * decay[:, None] * unbiased).sum(0))
            self.num_batches_tracked.add_(groups)


class ConvBN2d(nn.Module):
    """Keras ``convbn``: Conv2D 'same' without bias, then BatchNorm."""

    def __init__(self, cin: int, cout: int, kernel: int, dilation: int = 1) -> None:
        super().__init__()
        self.conv = nn.Conv2d(cin, cout, kernel, padding=dilation * (kernel // 2), dilation=dilation, bias=False)
        self.bn = ViewBatchNorm2d(cout, eps=BN_EPS, momentum=BN_MOMENTUM)

    reference = False  # see SubFocalNet.set_training_path
    weight_grad = "auto"

    def forward(self, x: torch.Tensor, groups: int = 1) -> torch.Tensor:
        if self.training and not self.reference and self.conv.in_channels == 1 and x.shape[0] > 1:
            # One input channel: the M images as the channels of one image, one group each (the kernel
            # repeated M times, so its gradient is the sum over them): oneDNN runs this 3-4x faster
            # than a batch of M single-channel images.
            m, _, h, w = x.shape
            c = self.conv
            y = F.conv2d(x.reshape(1, m, h, w), c.weight.repeat(m, 1, 1, 1), None, padding=c.padding,
                         dilation=c.dilation, groups=m).reshape(m, -1, h, w)
        elif self.training and not self.reference:
            y = training_conv(self.conv, x, self.weight_grad)
        else:
            y = self.conv(x)
        return self.bn(y, groups)


class BasicBlock2d(nn.Module):
    """convbn3x3 -> ReLU -> convbn3x3, plus the (optionally 1x1-projected) input; no ReLU after."""

    def __init__(self, cin: int, planes: int, dilation: int, project: bool) -> None:
        super().__init__()
        # Keras creates the projection first (conv, BN), then the block's two convbn layers.
        self.downsample = ConvBN2d(cin, planes, 1) if project else None
        self.conv1 = ConvBN2d(cin, planes, 3, dilation)
        self.conv2 = ConvBN2d(planes, planes, 3, dilation)

    def forward(self, x: torch.Tensor, groups: int = 1) -> torch.Tensor:
        skip = x if self.downsample is None else self.downsample(x, groups)
        return self.conv2(F.relu(self.conv1(x, groups)), groups) + skip


class ResLayer2d(nn.Module):
    """``_make_layer``: blocks of ``planes`` channels; the first projects its skip when planes != 4."""

    def __init__(self, cin: int, planes: int, blocks: int, dilation: int = 1) -> None:
        super().__init__()
        self.blocks = nn.ModuleList(
            BasicBlock2d(cin if i == 0 else planes, planes, dilation, project=(i == 0 and planes != FEATURES))
            for i in range(blocks))

    def forward(self, x: torch.Tensor, groups: int = 1) -> torch.Tensor:
        for block in self.blocks:
            x = block(x, groups)
        return x


def keras_avg_pool_same(x: torch.Tensor, p: int) -> torch.Tensor:
    """Keras AveragePooling2D(p, p, 'same'): ceil(n/p) outputs, padding split floor(total/2) before,
    padded cells left out of the mean. (M, C, H, W) -> (M, C, ceil(H/p), ceil(W/p))."""
    h, w = x.shape[-2:]
    ph, pw = math.ceil(h / p) * p - h, math.ceil(w / p) * p - w
    if ph == 0 and pw == 0:
        return F.avg_pool2d(x, p, p)
    pad = (pw // 2, pw - pw // 2, ph // 2, ph - ph // 2)
    summed = F.avg_pool2d(F.pad(x, pad), p, p)
    ones = torch.ones((1, 1, h, w), dtype=x.dtype, device=x.device)
    frac = F.avg_pool2d(F.pad(ones, pad), p, p)  # share of real cells in each window
    return summed / frac


class SPPBranch(nn.Module):
    """Average pool p ('same') -> convbn 1x1 to 4 ch -> ReLU -> bilinear upsample (align_corners)."""

    def __init__(self, pool: int, cin: int = 16) -> None:
        super().__init__()
        self.pool = pool
        self.convbn = ConvBN2d(cin, FEATURES, 1)

    def forward(self, x: torch.Tensor, groups: int = 1) -> torch.Tensor:
        y = F.relu(self.convbn(keras_avg_pool_same(x, self.pool), groups))
        return F.interpolate(y, size=x.shape[-2:], mode="bilinear", align_corners=True)


class FeatureExtractor(nn.Module):
    """The shared per-view extractor: (M, 1, H, W) -> (M, 4, H, W)."""

    def __init__(self) -> None:
        super().__init__()
        self.stem1 = ConvBN2d(1, 4, 3)
        self.stem2 = ConvBN2d(4, 4, 3)
        self.layer1 = ResLayer2d(4, 4, 2)
        self.layer2 = ResLayer2d(4, 8, 8)
        self.layer3 = ResLayer2d(8, 16, 2)
        self.layer4 = ResLayer2d(16, 16, 2, dilation=2)
        self.spp = nn.ModuleList(SPPBranch(p) for p in SPP_POOLS)  # created pool 2 first, as in Keras
        self.last = ConvBN2d(8 + 16 + FEATURES * len(SPP_POOLS), 16, 3)
        self.out = nn.Conv2d(16, FEATURES, 1, bias=False)

    def forward(self, x: torch.Tensor, groups: int = 1) -> torch.Tensor:
        x = F.relu(self.stem2(F.relu(self.stem1(x, groups)), groups))
        l2 = self.layer2(self.layer1(x, groups), groups)
        l4 = self.layer4(self.layer3(l2, groups), groups)
        branches = [b(l4, groups) for b in self.spp]
        x = torch.cat([l2, l4, *branches[::-1]], dim=1)  # [layer2, layer4, pool16, pool8, pool4, pool2]
        return self.out(F.relu(self.last(x, groups)))


def attention_index(angular: int = 9) -> torch.Tensor:
    """(angular^2,) index into the attention vector for each view.

    The k = (a+1)(a+2)/2 values (a = angular // 2; 15 for 9x9) fill the upper triangle of a
    symmetric (a+1)x(a+1) matrix row-major; it is reflect-padded to angular x angular:
    A[v, u] = A5[f(v), f(u)], f(i) = min(i, angular - 1 - i).
    """
    a = angular // 2 + 1
    tri = {}
    for i in range(a):
        for j in range(i, a):
            tri[(i, j)] = len(tri)
    f = [min(i, angular - 1 - i) for i in range(angular)]
    idx = [tri[(min(f[v], f[u]), max(f[v], f[u]))] for v in range(angular) for u in range(angular)]
    return torch.tensor(idx, dtype=torch.long)


class ChannelAttention(nn.Module):
    """Per-view weights from the cost volume's channel means: (B, 4N) -> (B, 4N) in (0, 1)."""

    def __init__(self, angular: int = 9, hidden: int = 170) -> None:
        super().__init__()
        n = angular * angular
        a = angular // 2 + 1
        self.fc1 = nn.Linear(FEATURES * n, hidden)
        self.fc2 = nn.Linear(hidden, a * (a + 1) // 2)
        self.register_buffer("index", attention_index(angular).repeat_interleave(FEATURES), persistent=False)

    def forward(self, channel_mean: torch.Tensor) -> torch.Tensor:
        w = torch.sigmoid(self.fc2(F.relu(self.fc1(channel_mean))))
        return w[:, self.index]


class ConvBN3d(nn.Module):
    """Conv3D 3x3x3 'same' (zero padding along D too), no bias, then BatchNorm."""

    def __init__(self, cin: int, cout: int) -> None:
        super().__init__()
        self.conv = nn.Conv3d(cin, cout, 3, padding=1, bias=False)
        self.bn = nn.BatchNorm3d(cout, eps=BN_EPS, momentum=BN_MOMENTUM)

    reference = False  # see SubFocalNet.set_training_path
    weight_grad = "auto"

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if self.training and not self.reference:
            return self.bn(training_conv(self.conv, x, self.weight_grad))
        return self.bn(self.conv(x))


class Aggregation(nn.Module):
    """The 3D aggregation ``basic``: (B, 4N, D, H, W) -> raw cost (B, D, H, W).

    Eight 3x3x3 convolutions in a row (324 -> w, six w -> w, w -> 1; the residual paths skip some),
    so a pixel depends on inputs up to 8 px away.
    """

    RECEPTIVE_RADIUS = 8

    def __init__(self, cin: int, width: int) -> None:
        super().__init__()
        self.dres0a, self.dres0b = ConvBN3d(cin, width), ConvBN3d(width, width)
        self.dres1a, self.dres1b = ConvBN3d(width, width), ConvBN3d(width, width)
        self.dres4a, self.dres4b = ConvBN3d(width, width), ConvBN3d(width, width)
        self.classify = ConvBN3d(width, width)
        self.out = nn.Conv3d(width, 1, 3, padding=1, bias=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        x = F.relu(self.dres0b(F.relu(self.dres0a(x))))
        x = self.dres1b(F.relu(self.dres1a(x))) + x
        x = self.dres4b(F.relu(self.dres4a(x))) + x
        return self.out(F.relu(self.classify(x))).squeeze(1)


@functools.cache
def network_params() -> dict[str, Param]:
    """The declared build parameters of :class:`SubFocalNet` (type, default, help, :class:`Range`)."""
    return signature_params(SubFocalNet)


def check_config(d_min: float, d_max: float, interval: float, interpolation: str, width: int | None = None,
                 attention: bool | None = None, angular: int | None = None) -> None:
    """ValueError naming the first bad :class:`SubFocalNet` build parameter (the grid: a bad or oversized one),
    before anything is allocated; the network, the ``subfocal`` trainable and the method all check with it.
    width, attention, angular: None = not checked (the method has its own width and fixes angular to 9)."""
    if interpolation not in INTERPOLATIONS:
        raise ValueError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, "
                         f"got {str(interpolation)[:40]!r}")
    declared = network_params()
    for name, value in (("width", width), ("attention", attention), ("angular", angular)):
        if value is None:
            continue
        if isinstance(value, numbers.Integral) and not isinstance(value, bool):
            value = int(value)  # a numpy integer
        problem = declared[name].problem(value)
        if problem:
            raise ValueError(f"{name}: {problem}")
    if angular is not None and angular % 2 == 0:
        raise ValueError(f"angular must be odd, got {angular}")
    disparity_grid(d_min, d_max, interval)


class SubFocalNet(nn.Module):
    """SubFocal / LFattNet: views (B, N, H, W) -> (disparity (B, H, W), probability (B, D, H, W)).

    The parameters are those of the ``subfocal`` trainable network (``[model]`` keys, ablation axes).
    """

    def __init__(self, d_min: Annotated[float, "smallest candidate disparity in px"] = -4.0,
                 d_max: Annotated[float, "largest candidate disparity in px"] = 4.0,
                 interval: Annotated[float, "disparity step of the cost volume in px (paper 0.5)"] = 0.5,
                 interpolation: Annotated[str, "sub-pixel shift of the features: nearest, bilinear (paper) or "
                                               "phase (Fourier)"] = "bilinear",
                 width: Annotated[int, "channels of the 3D aggregation (paper 150)", Range(1, MAX_WIDTH)] = 150,
                 attention: Annotated[bool, "channel attention over the views on/off"] = True,
                 angular: Annotated[int, "views per angular row, odd (9 for the HCI scenes)",
                                    Range(1, MAX_ANGULAR)] = 9) -> None:
        super().__init__()
        check_config(d_min, d_max, interval, interpolation, width, attention, angular)  # before any allocation
        self._config = {"d_min": float(d_min), "d_max": float(d_max), "interval": float(interval),
                        "interpolation": interpolation, "width": int(width), "attention": bool(attention),
                        "angular": int(angular)}
        self.interpolation = interpolation
        self.angular = angular
        self.register_buffer("disparities", disparity_grid(d_min, d_max, interval), persistent=False)
        self.register_buffer("offsets", angular_offsets(angular), persistent=False)
        channels = FEATURES * angular * angular
        self.extractor = FeatureExtractor()
        self.attention = ChannelAttention(angular) if attention else None
        self.aggregation = Aggregation(channels, width)
        self.reset_parameters()

    fast_inference = True  # eval mode without autograd takes methods/subfocal/fast.py
    reference = False  # set_training_path("reference"): the original training ops

    def config(self) -> dict:
        """The constructor keyword arguments (stored in checkpoints)."""
        return dict(self._config)

    def flops(self, height: int, width: int) -> dict[str, float]:
        """Floating-point operations of one eval forward pass on an H x W light field (2 per multiply-add of
        the convolutions and linear layers; BN, ReLU, shifts and softmax not counted): ``extractor`` (all
        views, SPP convs at their pooled size), ``attention``, ``aggregation`` (D disparities), ``total``."""
        n, d = self.angular ** 2, self.disparities.numel()
        pooled = {id(b.convbn.conv): math.ceil(height / b.pool) * math.ceil(width / b.pool) for b in self.extractor.spp}
        ext = 0.0
        for m in self.extractor.modules():
            if isinstance(m, nn.Conv2d):
                k = m.kernel_size[0] * m.kernel_size[1]
                ext += 2.0 * m.in_channels * m.out_channels * k * pooled.get(id(m), height * width)
        agg = sum(2.0 * m.in_channels * m.out_channels * 27 for m in self.aggregation.modules()
                  if isinstance(m, nn.Conv3d)) * d * height * width
        att = 0.0 if self.attention is None else sum(2.0 * m.in_features * m.out_features
                                                     for m in self.attention.modules() if isinstance(m, nn.Linear))
        out = {"extractor": ext * n, "attention": att, "aggregation": agg}
        out["total"] = sum(out.values())
        return out

    TRAINING_PATHS = ("fast", "reference")

    def set_training_path(self, path: str, *, weight_grad: str = "auto") -> SubFocalNet:
        """``fast`` (default): training runs the fused per-view BatchNorm, the grouped stem convolution, the
        gathered cost volume and, where it pays, convolution weight gradients as matrix products
        (methods/subfocal/weight_grad.py; ``weight_grad``: auto, gemm or native); ``reference``: the original
        layer-by-layer ops (same results up to float rounding; kept for the equivalence tests and as the
        "before" of ``lfbench bench train``)."""
        if path not in self.TRAINING_PATHS:
            raise ValueError(f"Unknown training path {path!r}. Available: {', '.join(self.TRAINING_PATHS)}")
        check_weight_grad(weight_grad)
        for m in self.modules():
            if hasattr(type(m), "reference"):
                m.reference = path == "reference"
            if hasattr(type(m), "weight_grad"):
                m.weight_grad = weight_grad
        return self

    def uses_fast_path(self) -> bool:
        """True when a call now takes the fast path: eval mode, autograd off, ``fast_inference``."""
        return self.fast_inference and not self.training and not torch.is_grad_enabled()

    def reset_parameters(self) -> None:
        """Keras defaults: glorot_uniform kernels, zero biases, BN gamma 1, beta 0, mean 0, var 1."""
        for m in self.modules():
            if isinstance(m, (nn.Conv2d, nn.Conv3d, nn.Linear)):
                nn.init.xavier_uniform_(m.weight)
                if m.bias is not None:
                    nn.init.zeros_(m.bias)
            elif isinstance(m, nn.modules.batchnorm._BatchNorm):
                m.reset_parameters()

    # -- stages (used by forward and by tiled inference) --------------------------------------

    def features(self, views: torch.Tensor, view_chunk: int = 0) -> torch.Tensor:
        """(B, N, H, W) -> (B, N, 4, H, W). In eval mode ``view_chunk`` > 0 extracts that many
        views at a time (identical results, less memory); training always batches all views."""
        b, n, h, w = views.shape
        if n != self.angular * self.angular:
            raise ValueError(f"expected {self.angular ** 2} views, got {n}")
        x = views.transpose(0, 1).reshape(n * b, 1, h, w)  # view-major: group g = view g
        if self.uses_fast_path():
            from lfbench_methods.subfocal.fast import FastExtractor

            extractor = FastExtractor(self.extractor)
            chunks = x.split(view_chunk * b) if view_chunk and view_chunk < n else [x]
            f = torch.cat([extractor(c) for c in chunks], dim=0)  # channels-last
        elif self.training:
            f = self.extractor(x, groups=n)
        elif view_chunk and view_chunk * b < n * b:
            f = torch.cat([self.extractor(c) for c in x.split(view_chunk * b)], dim=0)
        else:
            f = self.extractor(x)
        return f.reshape(n, b, FEATURES, h, w).transpose(0, 1)

    def cost_volume(self, features: torch.Tensor) -> torch.Tensor:
        """(B, N, 4, H, W) -> (B, 4N, D, H, W): every view shifted by every candidate disparity."""
        b, n, c, h, w = features.shape
        if self.interpolation == "bilinear" and self.uses_fast_path():
            from lfbench_methods.subfocal.inference import region_volume

            return region_volume(self, features, 0, h, 0, w)
        vol = shift_views(features, self.offsets, self.disparities, self.interpolation)  # (B, D, N, C, H, W)
        return vol.reshape(b, -1, n * c, h, w).transpose(1, 2)

    def attention_weights(self, channel_mean: torch.Tensor) -> torch.Tensor | None:
        """(B, 4N) mean of the cost volume over (D, H, W) -> (B, 4N) weights, or None without attention."""
        return None if self.attention is None else self.attention(channel_mean)

    def regress(self, cost: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Raw cost (B, D, H, W) -> (disparity (B, H, W), probability (B, D, H, W)); softmax of +cost."""
        prob = torch.softmax(cost.float(), dim=1)
        disp = (prob * self.disparities[None, :, None, None]).sum(dim=1)
        return disp, prob

    def forward(self, views: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """views (B, N, H, W) float32 in [0, 1] -> (disparity (B, H, W) px, probability (B, D, H, W))."""
        if self.uses_fast_path():
            from lfbench_methods.subfocal.inference import eval_cost

            h, w = views.shape[-2:]
            return self.regress(eval_cost(self, views.float(), h, w, halo=0, max_memory_gb=1e6))
        features = self.features(views)
        if self.training and self.interpolation == "bilinear" and not self.reference:
            # Training: the volume gathered from interpolated maps, its channel means from the features,
            # the attention applied to the maps (methods/subfocal/volume.py): the same numbers.
            from lfbench_methods.subfocal.volume import GatheredVolume

            gathered = GatheredVolume(self._shift_plan(), features)
            vol = gathered.volume(self.attention_weights(gathered.channel_mean()))
            return self.regress(self.aggregation(vol))
        vol = self.cost_volume(features)
        weights = self.attention_weights(vol.mean(dim=(2, 3, 4)))
        if weights is not None:
            vol = vol * weights[:, :, None, None, None]
        return self.regress(self.aggregation(vol))

    def _shift_plan(self):
        """The bilinear :class:`~lfbench_methods.subfocal.fast.ShiftPlan` of this grid (cached; config-only)."""
        plan = self.__dict__.get("_plan_cache")
        if plan is None:
            from lfbench_methods.subfocal.fast import net_shift_plan

            plan = self.__dict__["_plan_cache"] = net_shift_plan(self)
        return plan


def count_trainable(module: nn.Module) -> int:
    """Number of trainable parameters (BN running statistics excluded)."""
    return sum(p.numel() for p in module.parameters() if p.requires_grad)
