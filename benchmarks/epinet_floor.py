"""EPINET's CPU fp32 inference against its own convolution floor and a straightforward port, in one process.

    python benchmarks/epinet_floor.py --size 256 --threads 2 --repeat 2 --json OUT.json

One light field of 9x9 random views of size x size px through the paper network (random weights, eval mode):

- ``lfbench``: ``EPINetTrainable.infer`` (what ``lfbench evaluate`` / ``bench inference`` run: channels-last
  weights on the CPU, the border filled by edge replication);
- ``straightforward``: the same module layer by layer in PyTorch's default (NCHW) layout, as a direct port of the
  authors' Keras model runs;
- ``conv floor``: every convolution of the network alone (``F.conv2d`` on a random input of its own shape,
  channels-last like ``lfbench``'s), the best of ``--repeat`` runs each, summed: the time no implementation of
  these layers in this library can go below.

Times are CPU seconds of this process (``time.process_time``), which other processes on the cores inflate far
less than wall time, and wall seconds beside them; each is the best of ``--repeat`` runs after one warm-up.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def best_of(fn, repeat: int) -> tuple[float, float]:
    """(CPU s, wall s) of the fastest of ``repeat`` calls of ``fn`` (after one warm-up call)."""
    fn()
    best = (float("inf"), float("inf"))
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        fn()
        best = min(best, (time.process_time() - cpu, time.perf_counter() - wall))
    return best


def conv_floor(net, size: int, repeat: int) -> tuple[float, float, int]:
    """(CPU s, wall s, convolutions) of every convolution of ``net`` alone on an input of its shape at ``size``."""
    import torch
    import torch.nn.functional as F

    shapes = []  # (input shape, conv) in forward order, from hooks on one small forward pass
    hooks = [m.register_forward_hook(lambda m, i, o: shapes.append((tuple(i[0].shape), m)))
             for m in net.modules() if isinstance(m, torch.nn.Conv2d)]
    with torch.inference_mode():
        net.valid(torch.rand(1, net.angular ** 2, size, size))
    for h in hooks:
        h.remove()
    cpu = wall = 0.0
    with torch.inference_mode():
        for shape, conv in shapes:
            x = torch.rand(shape).contiguous(memory_format=torch.channels_last)
            w = conv.weight.detach().contiguous(memory_format=torch.channels_last)
            c, t = best_of(lambda x=x, w=w, b=conv.bias: F.conv2d(x, w, b), repeat)
            cpu, wall = cpu + c, wall + t
    return cpu, wall, len(shapes)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--size", type=int, default=256, help="light field height and width in px (default 256)")
    p.add_argument("--threads", type=int, default=0, help="torch threads (0: torch's default)")
    p.add_argument("--repeat", type=int, default=2, help="timed runs per case; the best is kept (default 2)")
    p.add_argument("--json", type=Path, default=None, help="write the record here")
    args = p.parse_args(argv)
    if not 23 <= args.size <= 2048 or not 1 <= args.repeat <= 20:
        p.error("--size must be 23..2048 and --repeat 1..20")

    import torch
    from lfbench_methods.epinet.network import EPINet

    from lfbench.method.trainable import get_trainable

    if args.threads:
        torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    views = torch.rand(1, 81, args.size, args.size)
    trainable = get_trainable("epinet")
    plain = EPINet().eval()
    fast = EPINet().eval()
    fast.load_state_dict(plain.state_dict())
    with torch.inference_mode():
        straight = best_of(lambda: plain(views), args.repeat)
        ours = best_of(lambda: trainable.infer(fast, views), args.repeat)
        same = float((trainable.infer(fast, views)[0] - plain(views)[0]).abs().max())
    floor_cpu, floor_wall, convs = conv_floor(fast, args.size, args.repeat)
    flops = fast.flops(args.size, args.size)["total"]
    record = {"bench": "epinet_floor", "size": args.size, "threads": torch.get_num_threads(), "repeat": args.repeat,
              "torch": torch.__version__, "gflop": flops / 1e9, "convolutions": convs,
              "lfbench_cpu_s": ours[0], "lfbench_wall_s": ours[1],
              "straightforward_cpu_s": straight[0], "straightforward_wall_s": straight[1],
              "conv_floor_cpu_s": floor_cpu, "conv_floor_wall_s": floor_wall,
              "ratio_to_floor_cpu": ours[0] / floor_cpu, "ratio_to_floor_wall": ours[1] / floor_wall,
              "speedup_over_straightforward_cpu": straight[0] / ours[0],
              "max_abs_difference_px": same}
    rows = [("lfbench (infer, channels-last)", ours), ("straightforward (NCHW module)", straight),
            (f"conv floor ({convs} convolutions alone)", (floor_cpu, floor_wall))]
    print(f"EPINET 9x9x{args.size}x{args.size} fp32, {torch.get_num_threads()} threads, {flops / 1e9:.1f} GFLOP")
    for name, (cpu, wall) in rows:
        print(f"  {name:40s} {cpu:8.3f} CPU s {wall:8.3f} wall s  {flops / 1e9 / cpu:6.1f} GFLOP per CPU s")
    print(f"  lfbench / floor: {record['ratio_to_floor_cpu']:.2f} (CPU), {record['ratio_to_floor_wall']:.2f} (wall); "
          f"straightforward / lfbench: {record['speedup_over_straightforward_cpu']:.2f} (CPU); max |difference| "
          f"{same:.2g} px")
    if args.json is not None:
        args.json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())
