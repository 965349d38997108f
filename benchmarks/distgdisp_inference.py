"""DistgDisp CPU inference beside its own convolution floor and the authors' algorithm, in one run.

Three cases on the same light field (A x A views of S x S px, the paper network, fp32, random weights with
random BatchNorm statistics), in interleaved rounds:

- ``network``: lfbench's forward pass (``Trainable.infer``: per-view features, DSAFE as one matrix product
  per disparity, folded BatchNorm, channels-last);
- ``authors``: the straightforward implementation of the authors' algorithm (methods/distgdisp/reference.py:
  the macro-pixel image, dilated convolutions on it, one strided dilated DSAFE convolution per disparity,
  the unfused aggregation), checked to give the same map;
- ``floor``: the network's convolutions alone, each distinct shape timed once on ready inputs in the
  network's layout and multiplied by how often it occurs (19 16->16 and one 1->16 2D convolutions over the
  views, the DSAFE matrix product of one cache-sized block of rows times D x the blocks of the image, 7
  160->160 and one 160->1 3D convolutions): the time no implementation of these layers can go below with
  these kernels.

Each case reports wall seconds and CPU seconds of this process (less inflated by other jobs on the cores).
    python benchmarks/distgdisp_inference.py --size 256 --json results/bench/distgdisp_inference_256.json
"""

from __future__ import annotations

import argparse
import json
import platform
import time
from pathlib import Path

import torch
import torch.nn.functional as F
from lfbench_methods.distgdisp.network import STACK_BLOCK_VALUES, DistgDispNet, disparity_range
from lfbench_methods.distgdisp.reference import random_batch_norm, reference_forward

from lfbench.method.trainable import get_trainable


def clocked(fn) -> tuple[dict, object]:
    """Wall and CPU seconds of ``fn()`` and its result."""
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return {"wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu}, out


def floor(net: DistgDispNet, size: int) -> dict:
    """The convolutions alone (see the module docstring): seconds per shape x count, summed."""
    n = net.angular ** 2
    f, c = net.config()["features"], net.config()["channels"]
    d = net.disparities.numel()
    cl, cl3 = torch.channels_last, torch.channels_last_3d
    x16 = torch.rand(n, f, size, size).contiguous(memory_format=cl)
    x1 = torch.rand(n, 1, size, size).contiguous(memory_format=cl)
    w16, w1 = torch.rand(f, f, 3, 3).contiguous(memory_format=cl), torch.rand(f, 1, 3, 3).contiguous(memory_format=cl)
    # the DSAFE product on a cache-sized block of rows (as the network runs it), times the blocks of the image
    rows = max(1, STACK_BLOCK_VALUES // (size * n * f))
    blocks = -(-size // rows)
    stacked, kernel = torch.rand(rows * size, n * f), torch.rand(n * f, c)
    vol = torch.rand(1, c, d, size, size).contiguous(memory_format=cl3)
    w3, w31 = torch.rand(c, c, 3, 3, 3).contiguous(memory_format=cl3), torch.rand(1, c, 3, 3, 3).contiguous(
        memory_format=cl3)
    bias, bias1 = torch.zeros(c), torch.zeros(1)
    shapes = {
        "conv2d_16": (19, lambda: F.conv2d(x16, w16, None, padding=1)),
        "conv2d_1": (1, lambda: F.conv2d(x1, w1, None, padding=1)),
        "dsafe_gemm": (d * blocks, lambda: stacked @ kernel),
        "conv3d_160": (7, lambda: F.conv3d(vol, w3, bias, padding=1)),
        "conv3d_1": (1, lambda: F.conv3d(vol, w31, bias1, padding=1)),
    }
    out: dict = {"wall_s": 0.0, "cpu_s": 0.0, "parts": {}}
    with torch.inference_mode():
        for name, (count, fn) in shapes.items():
            fn()  # warm-up (oneDNN primitive creation)
            t, _ = clocked(fn)
            out["parts"][name] = {"count": count, **t}
            out["wall_s"] += count * t["wall_s"]
            out["cpu_s"] += count * t["cpu_s"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, default=256, help="px per side of every view")
    parser.add_argument("--angular", type=int, default=9)
    parser.add_argument("--d-min", type=float, default=-4.0)
    parser.add_argument("--d-max", type=float, default=4.0)
    parser.add_argument("--rounds", type=int, default=1)
    parser.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    parser.add_argument("--json", type=Path, default=None, help="write the records here")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    net = random_batch_norm(DistgDispNet(angular=args.angular, d_min=args.d_min, d_max=args.d_max)).eval()
    trainable = get_trainable("distgdisp")
    views = torch.rand(1, args.angular ** 2, args.size, args.size, generator=torch.Generator().manual_seed(1))
    flops = net.flops(args.size, args.size)["total"]
    records: dict[str, list[dict]] = {"network": [], "authors": [], "floor": []}
    diff = None
    for _ in range(args.rounds):
        t, (ours, _) = clocked(lambda: trainable.infer(net, views))
        records["network"].append(t)
        t, (theirs, _) = clocked(lambda: reference_forward(net, views))
        records["authors"].append(t)
        diff = float((ours - theirs).abs().max())
        del theirs
        records["floor"].append(floor(net, args.size))
    best = {k: {m: min(r[m] for r in v) for m in ("wall_s", "cpu_s")} for k, v in records.items()}
    lo, hi = disparity_range(args.d_min, args.d_max)
    result = {
        "bench": "distgdisp_inference", "size": args.size, "angular": args.angular, "disparities": [lo, hi],
        "threads": torch.get_num_threads(), "torch": torch.__version__,
        "cpu": platform.processor() or platform.machine(),
        "capability": torch.backends.cpu.get_cpu_capability(), "gflop": flops / 1e9, "rounds": records,
        "best": best, "max_abs_difference_px": diff,
        "network_over_floor": {m: best["network"][m] / best["floor"][m] for m in ("wall_s", "cpu_s")},
        "authors_over_network": {m: best["authors"][m] / best["network"][m] for m in ("wall_s", "cpu_s")},
    }
    for case in ("network", "authors", "floor"):
        b = best[case]
        print(f"{case:8s} wall {b['wall_s']:8.2f} s  cpu {b['cpu_s']:8.2f} s  "
              f"({flops / 1e9 / b['wall_s']:.0f} GFLOP/s wall)")
    print(f"network / floor: wall {result['network_over_floor']['wall_s']:.3f}, cpu "
          f"{result['network_over_floor']['cpu_s']:.3f}; authors / network: wall "
          f"{result['authors_over_network']['wall_s']:.2f}, cpu {result['authors_over_network']['cpu_s']:.2f}; "
          f"max |network - authors| = {diff:.2e} px")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=1) + "\n", encoding="utf-8")


if __name__ == "__main__":
    main()
