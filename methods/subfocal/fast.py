"""The eval-mode fast path of :class:`SubFocalNet` (inference only, no autograd).

Same results as the layer-by-layer eval forward pass up to float rounding, computed with:

- BatchNorm folded into the convolutions (eval statistics), channels-last 2D/3D activations,
  ReLU and residual additions fused into oneDNN convolutions on the CPU (in-place add: two live
  150-channel activations instead of three), no bias/BN/ReLU passes over memory;
- a bilinear cost volume built by one gather per element: a bilinear shift by (sx, sy) is an
  integer shift of a map interpolated at the fractional part, and the fractional parts repeat
  across disparities (2 per view at interval 0.5), so each view is interpolated once per
  distinct fraction ("slot") and the volume is gathered from those maps straight into the
  (B, D, H, W, 4N) channels-last buffer the first 3D convolution reads;
- the attention mean of the volume computed analytically (a bilinear shift is a separable linear
  map, so the sum of a shifted map is a weighted sum of the map with row/column coverage weights):
  the volume is never built twice;
- the channel attention folded into the first 3D convolution's weights (conv(x * a) = conv'(x)),
  that convolution run over slabs of disparities so the 324-channel volume never exists whole,
  and the last 150 -> 1 convolution done as one matmul to 27 taps plus 27 shifted adds;
- bfloat16 (``dtype``) for the 3D aggregation when asked: volume and activations in bf16,
  accumulation in fp32 inside oneDNN, the last layer and the softmax in fp32.

Shapes: padded features (B, H + 2P, W + 2P, N, C) float32 (C = 4, view-major channels 4 * n + c);
volume slabs (B, k, rows, cols, 4N); cost (B, D, rows, cols) float32. Disparities are in px per
view step, shifts in px.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

FEATURES = 4
LAST_BLOCK = 4096  # voxels per matrix product of the last 3D convolution (float32 block: 2.4 MB at width 150)


# --------------------------------------------------------------------------- fused convolutions

@functools.cache
def fused_ops_work() -> bool:
    """True when oneDNN's fused convolution ops (conv + ReLU, conv + in-place add) run here."""
    try:
        ops = torch.ops.mkldnn
        x = torch.ones(1, 2, 3, 3).contiguous(memory_format=torch.channels_last)
        w = torch.ones(2, 2, 1, 1).contiguous(memory_format=torch.channels_last)
        y = ops._convolution_pointwise(x, w, None, [0, 0], [1, 1], [1, 1], 1, "relu", [], "")
        ops._convolution_pointwise_.binary(y, x, w, None, [0, 0], [1, 1], [1, 1], 1, "add", 1.0, None, [], None)
        return bool(torch.all(y == 4.0))
    except Exception:  # noqa: BLE001 - any failure means: use the plain ops
        return False


def conv(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None, padding: tuple[int, ...],
         dilation: int = 1, relu: bool = False, add_to: torch.Tensor | None = None, groups: int = 1) -> torch.Tensor:
    """conv2d/conv3d (stride 1) of channels-last ``x``; then ReLU, or ``add_to += result`` in place
    (returning ``add_to``). oneDNN fuses both on the CPU; elsewhere they are separate ops."""
    dims = x.dim() - 2
    dil = [dilation] * dims
    if x.device.type == "cpu" and fused_ops_work():
        ops = torch.ops.mkldnn
        if add_to is not None:  # the binary op wants the bias in the input's dtype
            b = None if bias is None else bias.to(x.dtype)
            return ops._convolution_pointwise_.binary(add_to, x, weight, b, list(padding), [1] * dims, dil,
                                                      groups, "add", 1.0, None, [], None)
        return ops._convolution_pointwise(x, weight, bias, list(padding), [1] * dims, dil, groups,
                                          "relu" if relu else "none", [], "")
    fmt = torch.channels_last if dims == 2 else torch.channels_last_3d
    fn = F.conv2d if dims == 2 else F.conv3d
    y = fn(x.contiguous(memory_format=fmt), weight, None if bias is None else bias.to(x.dtype), padding=padding,
           dilation=dilation, groups=groups)
    if add_to is not None:
        return add_to.add_(y)
    return y.relu_() if relu else y


def fold(conv_module: nn.Conv2d | nn.Conv3d, bn: nn.modules.batchnorm._BatchNorm | None,
         dtype: torch.dtype = torch.float32) -> tuple[torch.Tensor, torch.Tensor | None]:
    """(weight, bias) of ``bn(conv(x))`` in eval mode as one convolution: W * s, beta - mean * s with
    s = gamma / sqrt(var + eps). Weight channels-last in ``dtype``; bias float32 (or None)."""
    w = conv_module.weight.detach().float()
    b = None if conv_module.bias is None else conv_module.bias.detach().float()
    if bn is not None:
        s = bn.weight.detach().float() * torch.rsqrt(bn.running_var.float() + bn.eps)
        shift = bn.bias.detach().float() - bn.running_mean.float() * s
        w = w * s.reshape(-1, *([1] * (w.dim() - 1)))
        b = shift if b is None else b * s + shift
    fmt = torch.channels_last if w.dim() == 4 else torch.channels_last_3d
    return w.to(dtype).contiguous(memory_format=fmt), b


# --------------------------------------------------------------------------- 2D feature extractor

class FastExtractor:
    """The eval-mode feature extractor with folded BatchNorm: (M, 1, H, W) -> (M, 4, H, W) float32
    channels-last. (Always fp32: in bf16 its small convolutions run 2-3x faster here, but on the Keras
    reference the bf16 disparity error doubled, mean 0.018 -> 0.039 px.)"""

    def __init__(self, extractor: nn.Module) -> None:
        from lfbench_methods.subfocal.network import keras_avg_pool_same

        self._pool = keras_avg_pool_same
        e = extractor

        def cb(m) -> tuple:  # ConvBN2d -> (weight, bias, padding, dilation)
            w, b = fold(m.conv, m.bn)
            return w, b, m.conv.padding, m.conv.dilation[0]

        self.stem = [cb(e.stem1), cb(e.stem2)]
        self.layers = [[(cb(blk.downsample) if blk.downsample is not None else None, cb(blk.conv1), cb(blk.conv2))
                        for blk in layer.blocks] for layer in (e.layer1, e.layer2, e.layer3, e.layer4)]
        self.spp = [(branch.pool, cb(branch.convbn)) for branch in e.spp]
        self.last = cb(e.last)
        self.out = fold(e.out, None)

    @staticmethod
    def _apply(x: torch.Tensor, p: tuple, relu: bool = False, add_to: torch.Tensor | None = None) -> torch.Tensor:
        w, b, pad, dil = p
        return conv(x, w, b, pad, dil, relu=relu, add_to=add_to)

    def _stem(self, x: torch.Tensor) -> torch.Tensor:
        """The 1 -> 4 channel first conv as one grouped conv over the views (views as channels, 4 outputs
        each): 3x faster here than a batch of single-channel images. (M, 1, H, W) -> (M, 4, H, W) channels-last."""
        m, _, h, w = x.shape
        wt, b, pad, dil = self.stem[0]
        y = conv(x.reshape(1, m, h, w).float().contiguous(memory_format=torch.channels_last), wt.repeat(m, 1, 1, 1),
                 None if b is None else b.repeat(m), pad, dil, relu=True, groups=m)  # (1, 4M, H, W)
        y = y.permute(0, 2, 3, 1).reshape(h, w, m, wt.shape[0]).permute(2, 0, 1, 3).contiguous()  # (M, H, W, 4)
        return y.permute(0, 3, 1, 2)

    def __call__(self, x: torch.Tensor) -> torch.Tensor:
        x = self._stem(x)
        for p in self.stem[1:]:
            x = self._apply(x, p, relu=True)
        outs = []
        for layer in self.layers:
            for proj, c1, c2 in layer:
                # The block input is owned here and read by nothing after the block: the identity
                # skip may take the in-place add.
                skip = x if proj is None else self._apply(x, proj)
                x = self._apply(self._apply(x, c1, relu=True), c2, add_to=skip)
            outs.append(x)
        l2, l4 = outs[1], outs[3]
        size = l4.shape[-2:]
        branches = []
        for pool, p in self.spp:
            y = self._pool(l4, pool).contiguous(memory_format=torch.channels_last)
            y = self._apply(y, p, relu=True)
            branches.append(F.interpolate(y, size=size, mode="bilinear", align_corners=True))
        x = torch.cat([l2, l4, *branches[::-1]], dim=1).contiguous(memory_format=torch.channels_last)
        x = self._apply(x, self.last, relu=True)
        w, b = self.out
        return conv(x, w, b, (0, 0))


# --------------------------------------------------------------------------- bilinear shifts

@dataclass(frozen=True)
class ShiftPlan:
    """Bilinear shifts of every view n by every disparity d: source = pixel + (o + f) per axis.

    ox, oy (D, N) int64: floor(-shift); slot (D, N) int64: which interpolated map of view n the
    pair (fx, fy) is; fx, fy (S, N) float32: the fractions of each slot (unused slots repeat slot 0);
    pad: zero padding of the feature map (px) that keeps every source pixel inside it.
    out(y, x) = (1-fy)(1-fx) F[y+oy, x+ox] + (1-fy) fx F[y+oy, x+ox+1] + fy (1-fx) F[y+oy+1, x+ox]
    + fy fx F[y+oy+1, x+ox+1], F zero outside the image (as grid_sample with zero padding).
    """

    ox: torch.Tensor
    oy: torch.Tensor
    slot: torch.Tensor
    fx: torch.Tensor
    fy: torch.Tensor
    pad: int

    @property
    def slots(self) -> int:
        return int(self.fx.shape[0])

    @property
    def disparities(self) -> int:
        return int(self.ox.shape[0])


def shift_plan(d_min: float, interval: float, count: int, offsets: torch.Tensor) -> ShiftPlan:
    """The plan for the grid d_k = d_min + k * interval (k < count, float64 as lfbench.data.shift builds it)
    and view offsets (N, 2) of (u - uc, v - vc); view n at disparity d is shifted by (d du, d dv)."""
    d = torch.tensor([d_min + k * interval for k in range(count)], dtype=torch.float64)
    off = offsets.to(torch.float64).cpu()
    n = off.shape[0]

    def split(shift: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        src = -shift  # source coordinate minus output coordinate
        near = torch.round(src)
        src = torch.where((src - near).abs() < 1e-9, near, src)  # exact integers stay integers
        o = torch.floor(src)
        return o.to(torch.int64), src - o

    ox, fx = split(d[:, None] * off[None, :, 0])
    oy, fy = split(d[:, None] * off[None, :, 1])
    # Distinct (fx, fy) per view, with a tolerance far below float32 resolution.
    key = torch.round(fx * 1e7).to(torch.int64) * 10**8 + torch.round(fy * 1e7).to(torch.int64)
    big = 10**16
    combined = key + torch.arange(n, dtype=torch.int64)[None, :] * big  # (D, N), grouped by view
    uniq, inverse = torch.unique(combined, return_inverse=True)
    owner = uniq // big
    counts = torch.bincount(owner, minlength=n)
    start = torch.cumsum(counts, 0) - counts
    slot = inverse - start[torch.arange(n)][None, :]
    s_max = int(counts.max())
    fxs = torch.zeros((s_max, n), dtype=torch.float64)
    fys = torch.zeros((s_max, n), dtype=torch.float64)
    fxs[slot, torch.arange(n)[None, :].expand_as(slot)] = fx
    fys[slot, torch.arange(n)[None, :].expand_as(slot)] = fy
    used = torch.arange(s_max)[:, None] < counts[None, :]
    fxs = torch.where(used, fxs, fxs[:1])
    fys = torch.where(used, fys, fys[:1])
    pad = int(max(ox.abs().max(), oy.abs().max())) + 1
    return ShiftPlan(ox, oy, slot, fxs.float(), fys.float(), pad)


def net_shift_plan(net) -> ShiftPlan:
    """The :class:`ShiftPlan` of a SubFocalNet's disparity grid and views."""
    cfg = net.config()
    return shift_plan(cfg["d_min"], cfg["interval"], net.disparities.numel(), net.offsets)


def pad_features(features: torch.Tensor, pad: int) -> torch.Tensor:
    """(B, N, C, H, W) -> zero-padded channels-last (B, H + 2 pad, W + 2 pad, N, C) float32."""
    b, n, c, h, w = features.shape
    out = features.new_zeros((b, h + 2 * pad, w + 2 * pad, n, c), dtype=torch.float32)
    out[:, pad:pad + h, pad:pad + w] = features.permute(0, 3, 4, 1, 2)
    return out


def attention_sum(plan: ShiftPlan, padded: torch.Tensor, height: int, width: int,
                  row_chunk: int = 64) -> torch.Tensor:
    """Sum over (D, H, W) of every channel of the bilinear cost volume, without building it.

    The shifted map's sum is sum_{Y,X} cy[Y] cx[X] F[Y, X] with per-axis coverage weights
    (1 - f) on the window the integer shift selects plus f on the window one pixel further.
    padded (B, Hp, Wp, N, C) -> (B, N * C) float64 (channel 4 * view + c).
    """
    b, hp, wp, n, c = padded.shape
    p = plan.pad

    def coverage(o: torch.Tensor, f: torch.Tensor, slot: torch.Tensor, size: int, total: int) -> torch.Tensor:
        frac = f.double()[slot, torch.arange(n)[None, :]]  # (D, N)
        pos = torch.arange(total, dtype=torch.int64)[None, None, :] - p - o[:, :, None]  # output coord of weight 1-f
        inside0 = ((pos >= 0) & (pos < size)).double()
        inside1 = ((pos - 1 >= 0) & (pos - 1 < size)).double()
        return (1 - frac)[:, :, None] * inside0 + frac[:, :, None] * inside1  # (D, N, total)

    cy = coverage(plan.oy, plan.fy, plan.slot, height, hp)
    cx = coverage(plan.ox, plan.fx, plan.slot, width, wp)
    weight = torch.einsum("dny,dnx->yxn", cy, cx).float().to(padded.device)[..., None]  # (Hp, Wp, N, 1)
    total = torch.zeros((b, n, c), dtype=torch.float64, device=padded.device)
    for y0 in range(0, hp, row_chunk):  # row chunks bound the product's memory; sums in float64
        total += (padded[:, y0:y0 + row_chunk] * weight[y0:y0 + row_chunk]).sum(dim=(1, 2), dtype=torch.float64)
    return total.reshape(b, n * c)


class VolumeGather:
    """Gathers rows [y0, y1) x cols [x0, x1) of the bilinear cost volume, any disparity range, from
    the padded whole-image features: (B, k, rows, cols, 4N) in ``dtype``."""

    def __init__(self, plan: ShiftPlan, padded: torch.Tensor, y0: int, y1: int, x0: int, x1: int,
                 dtype: torch.dtype = torch.float32) -> None:
        b, hp, wp, n, c = padded.shape
        if c * torch.empty((), dtype=dtype).element_size() not in (8, 16):
            raise ValueError(f"{c} channels of {dtype} are not one 8- or 16-byte element")
        self.plan, self.dtype, self.shape = plan, dtype, (b, y1 - y0, x1 - x0, n, c)
        dev = padded.device
        oy_min, oy_max = int(plan.oy.min()), int(plan.oy.max())
        ox_min, ox_max = int(plan.ox.min()), int(plan.ox.max())
        gh, gw = (y1 - y0) + oy_max - oy_min, (x1 - x0) + ox_max - ox_min
        ys, xs = y0 + plan.pad + oy_min, x0 + plan.pad + ox_min
        src = padded[:, ys:ys + gh + 1, xs:xs + gw + 1]  # (B, gh + 1, gw + 1, N, C)
        s = plan.slots
        # One interpolated map per (view, slot): 4 weighted integer shifts, in float32, separate mul/add
        # (the same arithmetic for every region, so a region is exactly a crop of the whole image).
        maps = torch.empty((b, s, gh, gw, n, c), dtype=dtype, device=dev)
        fx, fy = plan.fx.to(dev), plan.fy.to(dev)
        corners = ((0, 0, (1 - fy) * (1 - fx)), (0, 1, (1 - fy) * fx), (1, 0, fy * (1 - fx)), (1, 1, fy * fx))
        acc = torch.empty((b, gh, gw, n, c), dtype=torch.float32, device=dev)
        tmp = torch.empty_like(acc)
        for k in range(s):  # distinct fractions (<= 2 per view at interval 0.5), not disparities
            for i, (dy, dx, wgt) in enumerate(corners):
                part = src[:, dy:dy + gh, dx:dx + gw]
                # The weight of every (view, channel), contiguous like a pixel's N x C values: the products
                # run over whole pixels, 3x faster than broadcasting over the innermost C channels.
                w = wgt[k][:, None].expand(n, c).contiguous()
                if i == 0:
                    torch.mul(part, w, out=acc)
                else:
                    torch.mul(part, w, out=tmp)
                    acc.add_(tmp)
            maps[:, k].copy_(acc)
        del acc, tmp
        self.maps = maps.view(torch.complex128 if c * maps.element_size() == 16 else torch.int64).reshape(b, -1)
        rows, cols = y1 - y0, x1 - x0
        big = s * gh * gw * n >= 2**31
        itype = torch.int64 if big else torch.int32
        yy = torch.arange(rows, device=dev, dtype=torch.int64)[:, None, None]
        xx = torch.arange(cols, device=dev, dtype=torch.int64)[None, :, None]
        nn_ = torch.arange(n, device=dev, dtype=torch.int64)[None, None, :]
        self.base = ((yy * gw + xx) * n + nn_).to(itype)  # (rows, cols, N)
        self.offset = ((((plan.slot * gh) + (plan.oy - oy_min)) * gw + (plan.ox - ox_min)) * n).to(dev, itype)

    def fill(self, out: torch.Tensor, d0: int, d1: int) -> None:
        """Write disparities [d0, d1) into ``out`` (B, d1 - d0, rows, cols, 4N) contiguous, ``dtype``."""
        b, rows, cols, n, c = self.shape
        k = d1 - d0
        if k <= 0:
            return
        idx = self.base[None] + self.offset[d0:d1, None, None, :]  # (k, rows, cols, N)
        view_dtype = self.maps.dtype
        flat = idx.reshape(-1)
        for i in range(b):
            dst = out[i].view(view_dtype).reshape(-1)
            torch.index_select(self.maps[i], 0, flat, out=dst)

    def release(self) -> None:
        """Free the interpolated maps (the gather cannot be used afterwards)."""
        self.maps = self.base = self.offset = None


# --------------------------------------------------------------------------- 3D aggregation

class FastAggregation:
    """The eval-mode 3D aggregation: volume slabs -> raw cost (B, D, rows, cols) float32 on a core region.

    dtype float32 or bfloat16 for the volume and the activations (the first conv's weights take the
    attention per sample; the last 150 -> 1 conv runs in float32).
    """

    def __init__(self, aggregation: nn.Module, dtype: torch.dtype = torch.float32) -> None:
        a = aggregation
        self.dtype = dtype
        self.first = fold(a.dres0a.conv, a.dres0a.bn, torch.float32)  # attention folded per call
        self.layers = [fold(m.conv, m.bn, dtype) for m in (a.dres0b, a.dres1a, a.dres1b, a.dres4a, a.dres4b,
                                                           a.classify)]
        w = a.out.weight.detach().float()  # (1, width, 3, 3, 3)
        self.taps = w[0].reshape(w.shape[1], 27).contiguous()  # (width, 27), tap = kz*9 + ky*3 + kx
        self.width = w.shape[1]
        self.channels = a.dres0a.conv.in_channels  # 4N

    def first_weights(self, attention: torch.Tensor | None) -> list[torch.Tensor]:
        """Per sample: the first conv's weights with the attention (B, 4N) folded in, ``dtype``, channels-last."""
        w, _ = self.first
        if attention is None:
            return [w.to(self.dtype).contiguous(memory_format=torch.channels_last_3d)]
        return [(w * a.float()[None, :, None, None, None]).to(self.dtype).contiguous(
            memory_format=torch.channels_last_3d) for a in attention]

    def __call__(self, source, batch: int, depth: int, rows: int, cols: int, attention: torch.Tensor | None,
                 core: tuple[int, int, int, int], slab: int = 2, device: torch.device | None = None) -> torch.Tensor:
        """source.fill(buf, d0, d1) writes volume disparities [d0, d1) into buf (B, d1-d0, rows, cols, 4N) in
        ``dtype``; source.release() is called after the first convolution (it may free its memory then).
        core (r0, r1, c0, c1): the rows/cols to return. -> cost (B, D, r1 - r0, c1 - c0) float32."""
        weights = self.first_weights(attention)
        bias0 = self.first[1]
        a = torch.empty((batch, bias0.numel(), depth, rows, cols), dtype=self.dtype, device=device,
                        memory_format=torch.channels_last_3d)
        # A rolling slab of the zero-padded volume: padded plane p holds disparity p - 1 (planes 0 and
        # D + 1 are zero). Output planes [d0, d1) read padded planes [d0, d1 + 2); the last two carry over.
        buf = torch.empty((batch, slab + 2, rows, cols, self.channels), dtype=self.dtype, device=device)

        def planes(dst: torch.Tensor, p0: int, p1: int) -> None:
            lo, hi = max(p0, 1), min(p1, depth + 1)
            if lo > p0:
                dst[:, :lo - p0].zero_()
            if hi < p1:
                dst[:, max(hi, lo) - p0:].zero_()
            if hi > lo:
                source.fill(dst[:, lo - p0:hi - p0], lo - 1, hi - 1)

        y, prev = None, 0
        for d0 in range(0, depth, slab):
            d1 = min(d0 + slab, depth)
            k = d1 - d0
            if d0 == 0:
                planes(buf[:, :k + 2], 0, k + 2)
            else:
                carry = buf[:, prev:prev + 2]
                buf[:, :2].copy_(carry if prev >= 2 else carry.clone())  # no overlapping copy
                planes(buf[:, 2:k + 2], d0 + 2, d1 + 2)
            x = buf[:, :k + 2].permute(0, 4, 1, 2, 3)  # (B, 4N, k + 2, rows, cols) with channels-last strides
            for i in range(batch):
                y = conv(x[i:i + 1], weights[min(i, len(weights) - 1)], bias0, (0, 1, 1), relu=True)
                a[i:i + 1, :, d0:d1].copy_(y)
            prev = k
        del buf, x, y
        source.release()
        layers = self.layers
        x = conv(a, *layers[0], (1, 1, 1), relu=True)
        del a
        t = conv(x, *layers[1], (1, 1, 1), relu=True)
        x = conv(t, *layers[2], (1, 1, 1), add_to=x)
        del t  # before the next conv allocates its output: two live activations, not three
        t = conv(x, *layers[3], (1, 1, 1), relu=True)
        x = conv(t, *layers[4], (1, 1, 1), add_to=x)
        del t
        c = conv(x, *layers[5], (1, 1, 1), relu=True)
        del x
        return self._last(c, core)

    def _last(self, c: torch.Tensor, core: tuple[int, int, int, int], block: int = LAST_BLOCK) -> torch.Tensor:
        """The width -> 1 conv as (voxels, width) @ (width, 27) taps in float32 (``block`` voxels at a time: the
        float32 copy of a bf16 block stays in cache, 2.5x faster than 65536 at a time), then the 27 shifted
        sums on the core region only (zero outside the tile).
        c (B, width, D, rows, cols) channels-last -> (B, D, r1 - r0, c1 - c0) float32."""
        b, width, d, rows, cols = c.shape
        r0, r1, c0, c1 = core
        flat = c.permute(0, 2, 3, 4, 1).reshape(-1, width)  # a view: channels-last is (B, D, rows, cols, width)
        taps = torch.empty((b, d, rows, cols, 27), dtype=torch.float32, device=c.device)
        tflat = taps.view(-1, 27)
        w = self.taps.to(c.device)
        for v in range(0, flat.shape[0], block):  # blocks bound the float32 copy of bf16 activations
            torch.matmul(flat[v:v + block].float(), w, out=tflat[v:v + block])
        del flat
        out = torch.zeros((b, d, r1 - r0, c1 - c0), dtype=torch.float32, device=c.device)

        def span(lo: int, hi: int, shift: int, size: int) -> tuple[slice, slice]:
            """Output range [lo, hi) reading source lo + shift .. hi + shift, clipped to [0, size)."""
            a0, a1 = max(lo, -shift), min(hi, size - shift)
            return slice(a0 - lo, max(a1, a0) - lo), slice(a0 + shift, max(a1, a0) + shift)

        for t in range(27):  # kernel taps
            (oz, sz), (oy, sy), (ox, sx) = (span(0, d, t // 9 - 1, d), span(r0, r1, (t // 3) % 3 - 1, rows),
                                            span(c0, c1, t % 3 - 1, cols))
            out[:, oz, oy, ox] += taps[:, sz, sy, sx, t]
        return out


