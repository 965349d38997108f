"""A convolution whose weight gradient is a few large matrix products: faster than oneDNN's on AVX2 CPUs.

oneDNN's weight gradient of SubFocal's first 3D convolution (4N = 324 channels in, 16 out, 3x3x3) runs at a
quarter of its AVX-512 speed with AVX2 kernels (0.75 s against 0.20 s per training step, width 16, batch 4,
32 px, 1 thread), a quarter of the whole step. Its stride-1 'same' correlation is

    grad_weight[o, c, k] = sum over batch and positions p of grad_out[o, p] * x_padded[c, p + dilation * k].

In channels-last memory, zero-padded, a position p + dilation * k is the flat row of p plus a constant offset
per tap k, so with grad_out written into the same padded grid (zero outside the outputs), every tap is one
product of two contiguous matrices: grad_out rows^T (O, R) @ x rows shifted by the tap's offset (R, C). Rows
are taken in chunks of ~4k so that a chunk's rows for all taps stay in cache; zero rows between samples are
skipped. Measured per layer with AVX2 kernels (ATEN_CPU_CAPABILITY=avx2, ONEDNN_MAX_CPU_ISA=AVX2,
MKL_ENABLE_INSTRUCTIONS=AVX2), 1 thread, per call (results/training_speed/weight_grad_layers_avx2.md): the
324-channel 3D convolution 0.42 s against 0.75 s, the dilated 2D convolutions of the extractor (324 views x
32 x 32) 0.044 s against 0.053 s; oneDNN stays faster on the other layers, and on every layer with AVX-512
kernels (weight_grad_layers_avx512.md).

The input gradient and the forward pass stay oneDNN's. Results equal oneDNN's up to float rounding
(tests/test_training_fast_path.py).
"""

from __future__ import annotations

import itertools

import torch
import torch.nn.functional as F
from torch import nn

__all__ = ["WEIGHT_GRADS", "check_weight_grad", "conv_with_gemm_weight_grad", "gemm_weight_grad", "pays_off",
           "training_conv"]

#: ``weight_grad`` choices of :meth:`SubFocalNet.set_training_path`: ``auto`` (the GEMM gradient on the layers
#: where it measured faster, when ATen runs its AVX2 kernels), ``gemm`` (on every layer it applies to), ``native``
#: (PyTorch's own, i.e. oneDNN's on the CPU).
WEIGHT_GRADS = ("auto", "gemm", "native")



def check_weight_grad(weight_grad: str) -> None:
    """ValueError naming the choices unless ``weight_grad`` is one of :data:`WEIGHT_GRADS`."""
    if weight_grad not in WEIGHT_GRADS:
        raise ValueError(f"Unknown weight_grad {weight_grad!r}. Available: {', '.join(WEIGHT_GRADS)}")


ROWS_PER_CHUNK = 4096  # rows of a product: chunk + the largest tap offset (~2.4k rows of 324 floats) fit in L3


def _applies(conv: nn.Module, x: torch.Tensor) -> bool:
    """True for a stride-1, ungrouped, bias-free, odd-kernel 'same' Conv2d/Conv3d on a float32 or float64 CPU tensor."""
    if not isinstance(conv, (nn.Conv2d, nn.Conv3d)) or conv.bias is not None or conv.groups != 1:
        return False
    if any(s != 1 for s in conv.stride) or conv.padding_mode != "zeros" or isinstance(conv.padding, str):
        return False
    shape = zip(conv.kernel_size, conv.padding, conv.dilation, strict=True)
    if any(k % 2 == 0 or p != d * (k // 2) for k, p, d in shape):
        return False
    if len(set(conv.kernel_size)) != 1 or len(set(conv.dilation)) != 1:
        return False
    return x.device.type == "cpu" and x.dtype in (torch.float32, torch.float64) and not torch.is_autocast_enabled("cpu")


def pays_off(conv: nn.Module) -> bool:
    """The layers where the GEMM gradient measured faster with AVX2 kernels (see the module docstring): 3D
    convolutions of >= 64 input channels and dilated 2D convolutions."""
    if isinstance(conv, nn.Conv3d):
        return conv.in_channels >= 64
    return isinstance(conv, nn.Conv2d) and conv.dilation[0] > 1 and conv.kernel_size[0] > 1


def _avx2_kernels() -> bool:
    """True when ATen runs its AVX2 kernels (an AVX2 CPU, or ATEN_CPU_CAPABILITY=avx2): where the GEMM gradient
    was measured faster. Elsewhere (AVX-512, ARM, ...) ``auto`` keeps oneDNN's."""
    return str(torch.backends.cpu.get_cpu_capability()).upper() == "AVX2"


def training_conv(conv: nn.Module, x: torch.Tensor, weight_grad: str = "auto") -> torch.Tensor:
    """``conv(x)``, with the GEMM weight gradient when ``weight_grad`` asks for it and the layer allows it:
    ``gemm`` wherever :func:`_applies`, ``auto`` also only where :func:`pays_off` and ATen runs its AVX2
    kernels, ``native`` never."""
    check_weight_grad(weight_grad)
    use = weight_grad == "gemm" or (weight_grad == "auto" and pays_off(conv) and _avx2_kernels())
    if use and torch.is_grad_enabled() and conv.weight.requires_grad and _applies(conv, x):
        return conv_with_gemm_weight_grad(x, conv.weight, conv.dilation[0])
    return conv(x)


def conv_with_gemm_weight_grad(x: torch.Tensor, weight: torch.Tensor, dilation: int = 1) -> torch.Tensor:
    """Stride-1 'same' convolution (B, C, *S) x (O, C, *K) -> (B, O, *S) (2 or 3 spatial dimensions, odd
    cubic kernel, zero padding dilation * (K // 2)) whose weight gradient is :func:`gemm_weight_grad`."""
    return _ConvGemmWeightGrad.apply(x, weight, dilation)


class _ConvGemmWeightGrad(torch.autograd.Function):
    @staticmethod
    def forward(ctx, x: torch.Tensor, weight: torch.Tensor, dilation: int) -> torch.Tensor:  # type: ignore[override]
        ctx.save_for_backward(x, weight)
        ctx.dilation = dilation
        conv = F.conv3d if x.dim() == 5 else F.conv2d
        return conv(x, weight, None, 1, dilation * (weight.shape[-1] // 2), dilation)

    @staticmethod
    def backward(ctx, grad: torch.Tensor):  # type: ignore[override]
        x, weight = ctx.saved_tensors
        d = ctx.dilation
        nd = x.dim() - 2
        grad_x = grad_w = None
        if ctx.needs_input_grad[0]:
            grad_x = torch.ops.aten.convolution_backward(
                grad, x, weight, None, [1] * nd, [d * (weight.shape[-1] // 2)] * nd, [d] * nd, False, [0] * nd, 1,
                [True, False, False])[0]
        if ctx.needs_input_grad[1]:
            grad_w = torch.empty_like(weight).copy_(gemm_weight_grad(x, grad, weight.shape[-1], d))  # weight's strides
        return grad_x, grad_w, None


def gemm_weight_grad(x: torch.Tensor, grad_out: torch.Tensor, kernel: int, dilation: int = 1,
                     rows_per_chunk: int = ROWS_PER_CHUNK) -> torch.Tensor:
    """Weight gradient (O, C, *[kernel] * n) of a stride-1 'same' convolution (zero padding
    dilation * (kernel // 2)) of x (B, C, *S) giving grad_out (B, O, *S), n = len(S) spatial dimensions:
    one matrix product per tap and chunk of rows of the zero-padded channels-last grid."""
    nd = x.dim() - 2
    b, c, *size = x.shape
    o = grad_out.shape[1]
    pad = dilation * (kernel // 2)
    padded = [s + 2 * pad for s in size]
    to_last = (0, *range(2, nd + 2), 1)
    xp = x.new_empty((b, *padded, c))
    for i in range(nd):  # zero the padding only: the copy below writes the rest
        xp[(slice(None),) * (i + 1) + (slice(0, pad),)] = 0
        xp[(slice(None),) * (i + 1) + (slice(pad + size[i], None),)] = 0
    xp[(slice(None), *(slice(pad, pad + s) for s in size))] = x.permute(to_last)
    gp = grad_out.new_zeros((b, *padded, o))
    gp[(slice(None), *(slice(0, s) for s in size))] = grad_out.permute(to_last)  # at the corner: p + k stays in
    xf, gf = xp.view(-1, c), gp.view(-1, o)
    strides = [1] * nd
    for i in range(nd - 2, -1, -1):
        strides[i] = strides[i + 1] * padded[i + 1]
    taps = itertools.product(range(kernel), repeat=nd)
    offsets = [dilation * sum(k * s for k, s in zip(tap, strides, strict=True)) for tap in taps]
    last = xf.shape[0] - offsets[-1]  # rows of gp past this are zero (the last sample's padding)
    per_sample = strides[0] * padded[0]
    spans = _merged([(i * per_sample, min(i * per_sample + size[0] * strides[0], last)) for i in range(b)],
                    gap=rows_per_chunk // 8)
    out = x.new_zeros((len(offsets), o, c))
    for start, stop in spans:
        for q in range(start, stop, rows_per_chunk):
            r = min(rows_per_chunk, stop - q)
            g = gf[q:q + r].t()
            for tap, off in enumerate(offsets):
                out[tap].addmm_(g, xf[q + off:q + off + r])
    return out.view(*[kernel] * nd, o, c).permute(nd, nd + 1, *range(nd))


def _merged(spans: list[tuple[int, int]], gap: int) -> list[tuple[int, int]]:
    """Sorted row spans with those less than ``gap`` rows apart joined (fewer, longer products)."""
    out: list[list[int]] = []
    for start, stop in spans:
        if out and start - out[-1][1] < gap:
            out[-1][1] = max(out[-1][1], stop)
        elif stop > start:
            out.append([start, stop])
    return [(a, b) for a, b in out]
