"""The bilinear cost volume for training (with autograd), gathered instead of grid-sampled.

The same volume as ``lfbench.data.shift.shift_views(..., "bilinear")`` up to float rounding, built the way
the eval fast path builds it (methods/subfocal/fast.py): a bilinear shift is an integer shift of a map
interpolated at the fractional part, and the fractional parts repeat across disparities, so each view is
interpolated once per distinct fraction ("slot", 2 per view at interval 0.5) and the volume is one
``index_select`` from those maps, written straight into the channels-last (B, D, H, W, 4N) memory the
first 3D convolution reads. Also:

- the channel means of the volume (the attention's input) come from the padded features and per-axis
  coverage weights (:func:`lfbench_methods.subfocal.fast.attention_sum`'s formula, in float32 with
  autograd): the 4N x D x H x W volume is never read for them;
- the attention weights (B, 4N) multiply the small interpolated maps, not the volume: gathering copies
  values, so gather(maps * a) equals gather(maps) * a exactly.

Backward: index_select's gradient (index_add into the maps), then the four weighted shifts. Shapes:
features (B, N, C, H, W) float32; padded (B, H + 2P, W + 2P, N, C); maps (B, S, gh, gw, N, C);
volume (B, N * C, D, H, W) with channels-last-3d strides (channel 4 * view + c, as the authors
concatenate). Disparities in px per view step, shifts in px.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
import torch.nn.functional as F
from lfbench_methods.subfocal.fast import ShiftPlan

__all__ = ["GatheredVolume"]


class GatheredVolume:
    """The bilinear cost volume of ``features`` (B, N, C, H, W) for a :class:`ShiftPlan`, differentiable.

    ``channel_mean()`` -> (B, N * C), the mean of every volume channel over (D, H, W);
    ``volume(weights)`` -> (B, N * C, D, H, W) channels-last-3d, times ``weights`` (B, N * C) if given.
    """

    def __init__(self, plan: ShiftPlan, features: torch.Tensor) -> None:
        b, n, c, h, w = features.shape
        self.plan, self.shape = plan, (b, n, c, h, w)
        dev = features.device
        p = plan.pad
        # (B, N, C, H, W) -> zero-padded (B, Hp, Wp, N, C)
        if features.dtype in (torch.float16, torch.bfloat16):
            features = features.float()  # interpolated in float32 under autocast, as the reference
        self.padded = F.pad(features, (p, p, p, p)).permute(0, 3, 4, 1, 2).contiguous()
        self.oy_min, oy_max = int(plan.oy.min()), int(plan.oy.max())
        self.ox_min, ox_max = int(plan.ox.min()), int(plan.ox.max())
        self.gh, self.gw = h + oy_max - self.oy_min, w + ox_max - self.ox_min
        ys, xs = p + self.oy_min, p + self.ox_min
        src = self.padded[:, ys:ys + self.gh + 1, xs:xs + self.gw + 1]  # (B, gh + 1, gw + 1, N, C)
        fx = plan.fx.to(dev, src.dtype)[None, :, None, None, :, None]  # (1, S, 1, 1, N, 1)
        fy = plan.fy.to(dev, src.dtype)[None, :, None, None, :, None]
        # Separable: along x (a + fx (b - a)) on gh + 1 rows, then along y.
        left, right = src[:, None, :, :self.gw], src[:, None, :, 1:]
        rows = torch.addcmul(left, right - left, fx)  # (B, S, gh + 1, gw, N, C)
        top, bottom = rows[:, :, :self.gh], rows[:, :, 1:]
        maps = torch.addcmul(top, bottom - top, fy)
        self.maps = maps  # (B, S, gh, gw, N, C): one interpolated map per (view, slot)

    def channel_mean(self) -> torch.Tensor:
        """(B, N * C) mean over (D, H, W) of every volume channel, from the padded features: the shifted
        map's sum is sum_{Y,X} cy[Y] cx[X] F[Y, X] with coverage (1 - f) on the window the integer shift
        selects and f on the window one pixel further."""
        b, n, c, h, w = self.shape
        _, hp, wp, _, _ = self.padded.shape
        weight = _plan_cached("mean_weight", self.plan, (h, w, str(self.padded.device), self.padded.dtype),
                              self._mean_weight)
        # sum over (Y, X) of padded (B, Y, X, N, C) * weight (Y, X, N): one batched matmul per view
        pv = self.padded.permute(3, 0, 4, 1, 2).reshape(n, b * c, hp * wp)  # (N, B*C, Hp*Wp)
        mean = torch.bmm(pv, weight)  # (N, B*C, 1)
        return mean.reshape(n, b, c).permute(1, 0, 2).reshape(b, n * c)

    def _mean_weight(self) -> torch.Tensor:
        """(N, Hp * Wp, 1) weight of every padded pixel in its view's channel means (a function of the plan,
        the image size, the device and the dtype only)."""
        plan = self.plan
        _, n, _, h, w = self.shape
        _, hp, wp, _, _ = self.padded.shape
        p = plan.pad

        def coverage(o: torch.Tensor, f: torch.Tensor, size: int, total: int) -> torch.Tensor:
            frac = f.double()[plan.slot, torch.arange(n)[None, :]]  # (D, N)
            pos = torch.arange(total, dtype=torch.int64)[None, None, :] - p - o[:, :, None]
            inside0 = ((pos >= 0) & (pos < size)).double()
            inside1 = ((pos >= 1) & (pos - 1 < size)).double()
            return (1 - frac)[:, :, None] * inside0 + frac[:, :, None] * inside1  # (D, N, total)

        cy = coverage(plan.oy, plan.fy, h, hp)
        cx = coverage(plan.ox, plan.fx, w, wp)
        weight = torch.einsum("dny,dnx->nyx", cy, cx) / (plan.disparities * h * w)  # (N, Hp, Wp)
        return weight.to(self.padded.device, self.padded.dtype).reshape(n, hp * wp, 1)

    def volume(self, weights: torch.Tensor | None = None) -> torch.Tensor:
        """(B, N * C, D, H, W) channels-last-3d: the gathered volume, times ``weights`` (B, N * C) if given."""
        b, n, c, h, w = self.shape
        maps = self.maps
        if weights is not None:
            maps = maps * weights.reshape(b, 1, 1, 1, n, c)
        vol = _Gather.apply(maps.reshape(-1, c), self._index(maps.device))  # (B * D * H * W * N, C)
        return vol.reshape(b, self.plan.disparities, h, w, n * c).permute(0, 4, 1, 2, 3)

    def _index(self, dev: torch.device) -> torch.Tensor:
        """(B * D * H * W * N,) int64 rows of the flattened maps (B * S * gh * gw * N, C), volume order."""
        b, n, c, h, w = self.shape
        return _plan_cached("index", self.plan, (b, n, h, w, str(dev)), lambda: self._make_index(dev))

    def _make_index(self, dev: torch.device) -> torch.Tensor:
        plan = self.plan
        b, n, c, h, w = self.shape
        s, gh, gw = plan.slots, self.gh, self.gw
        yy = torch.arange(h, device=dev)[:, None, None]
        xx = torch.arange(w, device=dev)[None, :, None]
        nn_ = torch.arange(n, device=dev)[None, None, :]
        base = (yy * gw + xx) * n + nn_  # (H, W, N)
        offset = ((plan.slot * gh + (plan.oy - self.oy_min)) * gw + (plan.ox - self.ox_min)) * n  # (D, N)
        idx = base[None] + offset.to(dev)[:, None, None, :]  # (D, H, W, N)
        return (idx.reshape(1, -1) + torch.arange(b, device=dev)[:, None] * (s * gh * gw * n)).reshape(-1)


# The last gather index and channel-mean weight (one training run uses one patch size and one network's
# cached plan), each as (plan, key, tensor): the plan itself is held, so identity is a safe test (two grids
# with the same D but other offsets differ).
_CACHE: dict[str, tuple[ShiftPlan, tuple, torch.Tensor]] = {}


def _plan_cached(name: str, plan: ShiftPlan, key: tuple, make: Callable[[], torch.Tensor]) -> torch.Tensor:
    """The cached ``name`` tensor of ``plan`` and ``key``, else ``make()`` (then cached in its place)."""
    held = _CACHE.get(name)
    if held is not None and held[0] is plan and held[1] == key:
        return held[2]
    value = make()
    _CACHE[name] = (plan, key, value)
    return value


class _Gather(torch.autograd.Function):
    """rows (M, C) float32, index (K,) -> rows[index] (K, C), its gradient an index_add. With C = 4 a row is
    one complex128 (forward) or two complex64 (backward, whose additions are float32 additions): one
    element per row instead of four, 1.5x faster on the CPU; other C take the plain ops."""

    @staticmethod
    def forward(ctx, rows: torch.Tensor, index: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(index)
        ctx.rows = rows.shape[0]
        m, c = rows.shape
        if c * rows.element_size() == 16 and rows.is_contiguous():
            return torch.index_select(rows.view(torch.complex128).reshape(m), 0, index).view(rows.dtype).reshape(-1, c)
        return torch.index_select(rows, 0, index)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        (index,) = ctx.saved_tensors
        grad = grad.contiguous()
        k, c = grad.shape
        out = grad.new_zeros((ctx.rows, c))
        if c % 2 == 0 and grad.dtype == torch.float32:
            out.view(torch.complex64).index_add_(0, index, grad.view(torch.complex64))
        else:
            out.index_add_(0, index, grad)
        return out, None
