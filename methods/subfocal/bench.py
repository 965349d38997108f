"""SubFocal's own ``lfbench bench`` cases (contributed through ``SubFocalTrainable.benches``): the conv3d
peak the network is judged against and the cost volume alone. lfbench's inference and train benches time
the network itself through the trainable seam."""

from __future__ import annotations

from lfbench.runs.bench import case_device, current_rss_gb, peak_rss_gb, set_threads, timed, torch_dtype
from lfbench.utils.errors import SpecError

PAPER_WIDTH = 150


def bench_peak(precision: str = "fp32", depth: int = 17, size: int = 64, width: int = PAPER_WIDTH,
               repeat: int = 3, threads: int = 0, device: str = "cpu") -> dict:
    """GFLOP/s of a width -> width 3x3x3 conv3d (+ bias, ReLU) on (1, width, depth, size, size) channels-last,
    through the fused op of SubFocal's fast path; best of ``repeat`` after one warm-up."""
    import torch
    from lfbench_methods.subfocal.fast import conv

    set_threads(threads)
    dtype = torch_dtype(precision)
    dev = case_device(device)
    g = torch.Generator().manual_seed(0)
    x = torch.rand((1, width, depth, size, size), generator=g).to(dev, dtype).contiguous(
        memory_format=torch.channels_last_3d)
    w = (torch.randn((width, width, 3, 3, 3), generator=g) * 0.01).to(dev, dtype).contiguous(
        memory_format=torch.channels_last_3d)
    b = torch.zeros(width, device=dev)
    flops = 2.0 * 27 * width * width * depth * size * size
    with torch.inference_mode():
        conv(x, w, b, (1, 1, 1), relu=True)
        seconds, cpu = timed(lambda: conv(x, w, b, (1, 1, 1), relu=True), repeat, dev)
    return {"bench": "peak", "precision": precision, "device": str(dev), "shape": [width, depth, size, size],
            "seconds": seconds,
            "cpu_seconds": cpu, "gflops_per_s": flops / seconds / 1e9, "gflops_per_cpu_s": flops / cpu / 1e9}


def bench_volume(size: int = 512, interval: float = 0.5, precision: str = "fp32", method: str = "gather",
                 threads: int = 0, repeat: int = 1, chunk_disparities: int = 2) -> dict:
    """The whole bilinear cost volume (1, 4N, D, size, size) of random features, built ``chunk_disparities``
    planes at a time into one reused buffer: GB/s = volume bytes / seconds. method: ``gather`` (the fast
    path, channels-last in ``precision``) or ``grid_sample`` (lfbench.data.shift.shift_views, fp32)."""
    import torch
    from lfbench_methods.subfocal.fast import VolumeGather, pad_features, shift_plan
    from lfbench_methods.subfocal.network import FEATURES

    from lfbench.data.shift import angular_offsets, disparity_grid, shift_views

    set_threads(threads)
    dtype = torch_dtype(precision) if method == "gather" else torch.float32
    if method not in ("gather", "grid_sample"):
        raise SpecError(f"volume method must be gather or grid_sample, got {method!r}")
    grid = disparity_grid(-4.0, 4.0, interval)
    d, n = grid.numel(), 81
    offsets = angular_offsets(9)
    feats = torch.rand((1, n, FEATURES, size, size), generator=torch.Generator().manual_seed(0))
    k = max(1, chunk_disparities)
    baseline = current_rss_gb()

    def run_gather() -> None:
        plan = shift_plan(-4.0, interval, d, offsets)
        gather = VolumeGather(plan, pad_features(feats, plan.pad), 0, size, 0, size, dtype)
        buf = torch.empty((1, k, size, size, n * FEATURES), dtype=dtype)
        for d0 in range(0, d, k):
            gather.fill(buf[:, :min(k, d - d0)], d0, min(d0 + k, d))

    def run_grid() -> None:
        for d0 in range(0, d, k):
            shift_views(feats, offsets, grid[d0:d0 + k], "bilinear")

    with torch.inference_mode():
        seconds, cpu = timed(run_gather if method == "gather" else run_grid, repeat)
    item = torch.empty((), dtype=dtype).element_size()
    gb = d * size * size * n * FEATURES * item / 1e9
    return {"bench": "volume", "size": size, "interval": interval, "precision": precision if method == "gather"
            else "fp32", "method": method, "seconds": seconds, "cpu_seconds": cpu, "volume_gb": gb,
            "gb_per_s": gb / seconds, "peak_memory_gb": peak_rss_gb(), "baseline_memory_gb": baseline}


__all__ = ["bench_peak", "bench_volume"]
