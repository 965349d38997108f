"""Per-layer weight gradient: oneDNN's (ATen convolution_backward) against the chunked matrix products of
methods/subfocal/weight_grad.py, for the convolutions of a SubFocal width-16 training step (batch 4, 32 px:
324 view images in the extractor, 17 disparities in the aggregation), 1 thread, CPU seconds per call (best
of 3). Run as written in README.md (with and without the AVX2 switches); prints a Markdown table."""

from __future__ import annotations

import time

import torch
from lfbench_methods.subfocal.weight_grad import gemm_weight_grad

# (input shape, output channels, dilation, where in the network)
LAYERS = [
    ((4, 324, 17, 32, 32), 16, 1, "aggregation dres0a (3D, 324 -> 16)"),
    ((4, 16, 17, 32, 32), 16, 1, "aggregation, the other 3D layers (16 -> 16)"),
    ((324, 16, 32, 32), 16, 2, "extractor layer 4 (2D, dilation 2)"),
    ((324, 16, 32, 32), 16, 1, "extractor layer 3 (2D)"),
    ((324, 40, 32, 32), 16, 1, "extractor last (2D, 40 -> 16)"),
    ((324, 8, 32, 32), 8, 1, "extractor layer 2 (2D, 8 -> 8)"),
    ((324, 4, 32, 32), 4, 1, "extractor layer 1 (2D, 4 -> 4)"),
]


def best_cpu_seconds(fn, repeat: int = 3) -> float:
    fn()
    times = []
    for _ in range(repeat):
        start = time.process_time()
        fn()
        times.append(time.process_time() - start)
    return min(times)


def measure(shape: tuple[int, ...], out: int, dilation: int) -> tuple[float, float, float]:
    """(oneDNN s, GEMM s, max relative difference) of one layer's weight gradient."""
    nd = len(shape) - 2
    fmt = torch.channels_last_3d if nd == 3 else torch.channels_last
    g = torch.Generator().manual_seed(0)
    x = torch.randn(shape, generator=g).contiguous(memory_format=fmt)
    grad = torch.randn((shape[0], out, *shape[2:]), generator=g).contiguous(memory_format=fmt)
    weight = torch.zeros((out, shape[1], *[3] * nd)).contiguous(memory_format=fmt)
    args = ([1] * nd, [dilation] * nd, [dilation] * nd, False, [0] * nd, 1, [False, True, False])

    def native():
        return torch.ops.aten.convolution_backward(grad, x, weight, None, *args)[1]

    def gemm():
        return gemm_weight_grad(x, grad, 3, dilation)

    ref = native()
    diff = float((gemm() - ref).abs().max() / ref.abs().max())
    return best_cpu_seconds(native), best_cpu_seconds(gemm), diff


def main() -> None:
    torch.set_num_threads(1)
    print(f"ATen CPU capability: {torch.backends.cpu.get_cpu_capability()}, torch {torch.__version__}\n")
    print("| layer | input | oneDNN weight grad (s) | GEMM weight grad (s) | ratio | max rel. difference |")
    print("|---|---|---|---|---|---|")
    for shape, out, dilation, where in LAYERS:
        a, b, diff = measure(shape, out, dilation)
        print(f"| {where} | {tuple(shape)} | {a:.4f} | {b:.4f} | {a / b:.2f} | {diff:.1e} |")


if __name__ == "__main__":
    main()
