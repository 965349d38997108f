"""OACC-Net's occlusion-aware cost constructor on the CPU: lfbench's against the straightforward unfold version
and against its own convolution floor, in the same run.

    python benchmarks/oaccnet_cost.py --size 256 --threads 2 --rounds 3 --json OUT.json

One 9x9 light field of ``--size`` px, 8 random feature channels per view (what OACC-Net's extractor gives),
a random occlusion mask (the second pass), the authors' 9 disparities -4..4, fp32. Cases (the output of each
is what OACC-Net's aggregation reads: the cost after its 1x1x1 convolution 512 -> 160):

- ``unfold``: the authors' algorithm as written: views tiled into a zero-padded mosaic, per disparity an
  unfold with a dilated 9x9 kernel (8 x 81 channels per pixel), the mask repeated over the channels and
  multiplied in, a fold, the grouped 1x1 convolution to 512 channels, the division by the mask's mean; then
  the 1x1x1 convolution 512 -> 160 on the stacked 512-channel cost. It is ``unfold_cost`` of
  tests/test_oaccnet.py, the implementation the test proves lfbench's equal to;
- ``lfbench``: ``modulated_cost`` with the 1x1x1 convolution folded in (what OACCNet.estimate runs);
- ``floor``: the contraction alone, one (160 x 648) @ (648 x H W) matrix product per disparity on an operand
  prepared beforehand (the gathered, masked views): the least any implementation of the fused op does.

With ``--network S``, also the whole network (random weights, eval, two passes) on one 9x9 light field of
S x S px against its convolution floor: its FLOPs (``OACCNet.flops``) at the GFLOP/s of one 160 -> 160 3x3x3
convolution over (9, S, S) (the aggregation's, 94 % of its FLOPs) measured in the same run.

Every case is timed ``--repeat`` times per round (best wall time, mean CPU seconds), the cases interleaved over
``--rounds`` rounds so that they share the load; each record has wall and CPU seconds, and the ratios to the
floor and of unfold to lfbench (per CPU second, which other processes on the cores inflate much less).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import torch
import torch.nn.functional as F

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from lfbench_methods.oaccnet.network import AGG_CHANNELS, COST_CHANNELS, FEATURE_CHANNELS, modulated_cost  # noqa: E402
from test_oaccnet import unfold_cost  # noqa: E402

from lfbench.runs.bench import set_threads, timed  # noqa: E402

ANGULAR = 9
GRID = list(range(-4, 5))


def inputs(size: int) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    n = ANGULAR * ANGULAR
    return {"feat": torch.randn(1, FEATURE_CHANNELS, n, size, size, generator=g),
            "mask": torch.rand(1, n, size, size, generator=g) * 0.9 + 0.1,
            "weight": torch.randn(COST_CHANNELS, n, 1, 1, generator=g) * 0.1,
            "project": torch.randn(AGG_CHANNELS, COST_CHANNELS, generator=g) * 0.05}


def cases(x: dict[str, torch.Tensor]) -> dict:
    """name -> a function of no arguments returning the (1, 160, D, H, W) cost (the floor: its products)."""
    size = x["feat"].shape[-1]
    operand = torch.randn(1, FEATURE_CHANNELS * ANGULAR ** 2, size * size)
    dense = torch.randn(AGG_CHANNELS, FEATURE_CHANNELS * ANGULAR ** 2)
    out = torch.empty(len(GRID), 1, AGG_CHANNELS, size * size)

    def unfold() -> torch.Tensor:
        cost = unfold_cost(x["feat"], x["mask"], x["weight"], GRID, ANGULAR)
        return F.conv3d(cost, x["project"].view(AGG_CHANNELS, COST_CHANNELS, 1, 1, 1))

    def fast() -> torch.Tensor:
        return modulated_cost(x["feat"], x["mask"], x["weight"], GRID, ANGULAR, x["project"])

    def floor() -> torch.Tensor:
        for i in range(len(GRID)):
            torch.matmul(dense, operand, out=out[i])
        return out

    return {"unfold": unfold, "lfbench": fast, "floor": floor}


def network_case(size: int, repeat: int) -> dict:
    """The whole network's CPU and wall seconds at size x size beside its convolution floor."""
    from lfbench_methods.oaccnet.network import OACCNet

    net = OACCNet().eval()
    views = torch.rand(1, ANGULAR ** 2, size, size, generator=torch.Generator().manual_seed(1))
    conv = torch.nn.Conv3d(AGG_CHANNELS, AGG_CHANNELS, 3, 1, 1, bias=False).eval()
    volume = torch.randn(1, AGG_CHANNELS, len(GRID), size, size)
    conv_flops = 2.0 * 27 * AGG_CHANNELS ** 2 * len(GRID) * size * size
    with torch.inference_mode():
        conv(volume)
        conv_wall, conv_cpu = timed(lambda: conv(volume), repeat)
        net(views)
        wall, cpu = timed(lambda: net(views), repeat)
    flops = net.flops(size, size)["total"]
    return {"size": size, "gflop": flops / 1e9, "seconds": wall, "cpu_seconds": cpu,
            "conv_gflops_per_s": conv_flops / conv_wall / 1e9, "conv_gflops_per_cpu_s": conv_flops / conv_cpu / 1e9,
            "floor_s": flops / (conv_flops / conv_wall), "floor_cpu_s": flops / (conv_flops / conv_cpu),
            "ratio_to_floor": wall / (flops / (conv_flops / conv_wall)),
            "cpu_ratio_to_floor": cpu / (flops / (conv_flops / conv_cpu))}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=256, help="light field height and width, px (default 256)")
    p.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    p.add_argument("--repeat", type=int, default=2, help="timed calls per case and round (best wall kept)")
    p.add_argument("--rounds", type=int, default=2, help="interleaved rounds over the cases")
    p.add_argument("--network", type=int, default=0, metavar="S",
                   help="also time the whole network at S x S px against its convolution floor (0: no)")
    p.add_argument("--json", type=Path, help="write the records here")
    args = p.parse_args(argv)
    if not 8 <= args.size <= 1024:
        p.error(f"--size must be in [8, 1024], got {args.size}")
    set_threads(args.threads)
    x = inputs(args.size)
    run = cases(x)
    with torch.inference_mode():
        diff = float((run["unfold"]() - run["lfbench"]()).abs().max())  # also the warm-up
        run["floor"]()
        best: dict[str, list[float]] = {name: [float("inf"), 0.0] for name in run}
        for _ in range(max(1, args.rounds)):
            for name, fn in run.items():
                wall, cpu = timed(fn, args.repeat)
                best[name][0] = min(best[name][0], wall)
                best[name][1] += cpu / max(1, args.rounds)
    n, px = ANGULAR ** 2, args.size * args.size
    record = {"bench": "oaccnet_cost", "size": args.size, "angular": ANGULAR, "disparities": len(GRID),
              "threads": torch.get_num_threads(), "max_abs_diff": diff,
              "gflop": 2.0 * FEATURE_CHANNELS * n * AGG_CHANNELS * len(GRID) * px / 1e9,
              "unfolded_mb_per_disparity": FEATURE_CHANNELS * n * px * 4 / 1e6,
              "cases": {name: {"seconds": wall, "cpu_seconds": cpu} for name, (wall, cpu) in best.items()}}
    c = record["cases"]
    for name in ("unfold", "lfbench"):
        c[name]["ratio_to_floor"] = c[name]["seconds"] / c["floor"]["seconds"]
        c[name]["cpu_ratio_to_floor"] = c[name]["cpu_seconds"] / c["floor"]["cpu_seconds"]
    record["unfold_over_lfbench"] = c["unfold"]["seconds"] / c["lfbench"]["seconds"]
    record["unfold_over_lfbench_cpu"] = c["unfold"]["cpu_seconds"] / c["lfbench"]["cpu_seconds"]
    if args.network:
        if not 8 <= args.network <= 1024:
            p.error(f"--network must be in [8, 1024], got {args.network}")
        record["network"] = network_case(args.network, args.repeat)
    text = json.dumps(record, indent=1)
    print(text)
    if args.json:
        args.json.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
