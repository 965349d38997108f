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
- the attention weights (B, 4N) multiply the source window before the interpolation, not the volume (the
  interpolation is linear and gathering copies values: the same numbers up to rounding), a pass over
  memory S times smaller than the maps and D / S times smaller than the volume.

Backward (:class:`_MapsVolume`, by hand): index_select's gradient (index_add into the maps), then the
transposed interpolations. Shapes:
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
        p = plan.pad
        # (B, N, C, H, W) -> zero-padded (B, Hp, Wp, N, C)
        if features.dtype in (torch.float16, torch.bfloat16):
            features = features.float()  # interpolated in float32 under autocast, as the reference
        self.padded = F.pad(features, (p, p, p, p)).permute(0, 3, 4, 1, 2).contiguous()
        self.oy_min, oy_max = int(plan.oy.min()), int(plan.oy.max())
        self.ox_min, ox_max = int(plan.ox.min()), int(plan.ox.max())
        self.gh, self.gw = h + oy_max - self.oy_min, w + ox_max - self.ox_min
        self.window = (p + self.oy_min, p + self.ox_min)  # top-left of the source window in the padded map

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
        dev = self.padded.device
        fx = self.plan.fx.to(dev, self.padded.dtype)[None, :, None, None, :, None]  # (1, S, 1, 1, N, 1)
        fy = self.plan.fy.to(dev, self.padded.dtype)[None, :, None, None, :, None]
        geometry = (*self.window, self.gh, self.gw)
        vol = _MapsVolume.apply(self.padded, weights, fx, fy, self._index(dev), geometry)  # (B * D * H * W * N, C)
        return vol.reshape(b, self.plan.disparities, h, w, n * c).permute(0, 4, 1, 2, 3)

    def _index(self, dev: torch.device) -> torch.Tensor:
        """(B * D * H * W * N,) int64 rows of the flattened bordered maps (B * S * (gh + 2) * (gw + 2) * N, C),
        volume order."""
        b, n, c, h, w = self.shape
        return _plan_cached("index", self.plan, (b, n, h, w, str(dev)), lambda: self._make_index(dev))

    def _make_index(self, dev: torch.device) -> torch.Tensor:
        plan = self.plan
        b, n, c, h, w = self.shape
        s, gh, gw = plan.slots, self.gh + 2, self.gw + 2  # maps with a one-pixel border (see _MapsVolume)
        yy = torch.arange(h, device=dev)[:, None, None]
        xx = torch.arange(w, device=dev)[None, :, None]
        nn_ = torch.arange(n, device=dev)[None, None, :]
        base = (yy * gw + xx) * n + nn_  # (H, W, N)
        offset = ((plan.slot * gh + (plan.oy - self.oy_min + 1)) * gw + (plan.ox - self.ox_min + 1)) * n  # (D, N)
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


class _MapsVolume(torch.autograd.Function):
    """padded (B, Hp, Wp, N, C), weights (B, N * C) or None -> volume rows (B * D * H * W * N, C): the source
    window times the weights (a copy's scale commutes with the interpolation), interpolated along x then y
    per slot (``torch.lerp``) into maps with a one-pixel zero border (B, S, gh + 2, gw + 2, N, C), gathered.

    Backward, by hand (the maps are linear in the window): the gather's index_add into zeroed bordered maps,
    then the transposed interpolations, which read the border's zeros instead of padding copies, and the sum
    over slots; nothing the size of the maps is kept between forward and backward. With C = 4 a map row is
    gathered as one complex128 and added as two complex64 (float32 additions): 1.5x faster on the CPU.
    """

    @staticmethod
    def forward(ctx, padded: torch.Tensor, weights: torch.Tensor | None, fx: torch.Tensor, fy: torch.Tensor,  # type: ignore[override]
                index: torch.Tensor, geometry: tuple[int, int, int, int]) -> torch.Tensor:
        ys, xs, gh, gw = geometry
        b, _, _, n, c = padded.shape
        src = padded[:, ys:ys + gh + 1, xs:xs + gw + 1]  # (B, gh + 1, gw + 1, N, C)
        if weights is not None:
            src = src * weights.reshape(b, 1, 1, n, c)
        rows = torch.lerp(src[:, None, :, :gw], src[:, None, :, 1:], fx)  # (B, S, gh + 1, gw, N, C)
        maps = padded.new_empty((b, fx.shape[1], gh + 2, gw + 2, n, c))  # the border is never gathered
        torch.lerp(rows[:, :, :gh], rows[:, :, 1:], fy, out=maps[:, :, 1:gh + 1, 1:gw + 1])
        ctx.save_for_backward(padded if weights is not None else None, weights, fx, fy, index)
        ctx.geometry, ctx.padded_shape = geometry, padded.shape
        flat = maps.view(-1, c)
        if c * flat.element_size() == 16:
            return torch.index_select(flat.view(torch.complex128).reshape(-1), 0, index).view(maps.dtype).reshape(-1, c)
        return torch.index_select(flat, 0, index)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        padded, weights, fx, fy, index = ctx.saved_tensors
        ys, xs, gh, gw = ctx.geometry
        b, _, _, n, c = ctx.padded_shape
        grad = grad.contiguous()
        gmaps = grad.new_zeros((b, fx.shape[1], gh + 2, gw + 2, n, c))
        flat = gmaps.view(-1, c)
        if c % 2 == 0 and grad.dtype == torch.float32:
            flat.view(torch.complex64).index_add_(0, index, grad.view(torch.complex64))
        else:
            flat.index_add_(0, index, grad)
        # maps[y] = lerp(rows[y], rows[y + 1], fy): rows[y'] gets (1 - fy) maps[y'] + fy maps[y' - 1]; the
        # border rows/columns of gmaps are the zeros beyond either end.
        grows = torch.lerp(gmaps[:, :, 1:], gmaps[:, :, :-1], fy)  # (B, S, gh + 1, gw + 2, N, C)
        gsrc = torch.lerp(grows[:, :, :, 1:], grows[:, :, :, :-1], fx).sum(1)  # (B, gh + 1, gw + 1, N, C)
        grad_weights = None
        if weights is not None:
            if ctx.needs_input_grad[1]:
                src = padded[:, ys:ys + gh + 1, xs:xs + gw + 1]
                grad_weights = (gsrc * src).sum(dim=(1, 2)).reshape(b, n * c)
            gsrc = gsrc * weights.reshape(b, 1, 1, n, c)
        grad_padded = None
        if ctx.needs_input_grad[0]:
            grad_padded = gsrc.new_zeros(ctx.padded_shape)
            grad_padded[:, ys:ys + gh + 1, xs:xs + gw + 1] = gsrc
        return grad_padded, grad_weights, None, None, None, None
