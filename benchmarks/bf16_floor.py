"""Where the time of one SubFocal inference goes, against the conv3d peak measured in the same process.

    python benchmarks/bf16_floor.py --size 128 --precision bf16 fp32 --threads 1 --json OUT.json --table OUT.md

For each precision: the conv3d peak of lfbench bench (150 -> 150 3x3x3 on (17, 64, 64), the op of the fast
path) in fp32 and in bf16, then one light field (random views, the paper network with random weights unless
``--width``/``--interval`` say otherwise) through ``infer``, ``--repeat`` times (the best is kept; the first
run also creates oneDNN's primitives). Every convolution of the fast path goes through
``lfbench_methods.subfocal.fast.conv``; this script wraps it with a clock, so each class of convolution
(2D feature extractor or 3D aggregation; channels in and out, kernel, fused ReLU or in-place add, dtype) gets
its seconds, GFLOP/s and fraction of the peak of its own dtype, and each phase its time outside
convolutions. The floor is the network's FLOPs at the peak of the run's precision (as ``lfbench bench``
computes it); ``--profile N`` adds torch.profiler's N most expensive ops (with shapes) of one more run.
``--rounds R`` repeats the precisions R times, interleaved (A/B under the same load); ``--sweep`` times
the convolution op alone on the peak's shape and on the network's own shapes at this size.

Every time is CPU seconds of this process (``time.process_time``; peaks per CPU second), which other
processes on the cores inflate far less than wall time; the wall seconds of the whole run are beside them.
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import sys
import time
from pathlib import Path


def _conv_key(x, weight, relu: bool, add_to) -> str:
    kernel = "x".join(str(k) for k in weight.shape[2:])
    op = "+add" if add_to is not None else ("+relu" if relu else "")
    dtype = str(x.dtype).removeprefix("torch.").replace("bfloat16", "bf16").replace("float32", "fp32")
    return f"{x.dim() - 2}d {x.shape[1]}->{weight.shape[0]} k{kernel}{op} {dtype}"


class ConvClock:
    """Wraps lfbench_methods.subfocal.fast.conv while active: per class of convolution, calls, seconds and
    FLOPs (2 per multiply-add of the output it returns)."""

    def __init__(self) -> None:
        self.stats: dict[str, list] = collections.defaultdict(lambda: [0, 0.0, 0.0, ""])

    def __enter__(self) -> ConvClock:
        from lfbench_methods.subfocal import fast

        self._fast, self._orig = fast, fast.conv

        def timed_conv(x, weight, bias, padding, dilation=1, relu=False, add_to=None, groups=1):
            t = time.process_time()
            y = self._orig(x, weight, bias, padding, dilation, relu, add_to, groups)
            seconds = time.process_time() - t
            macs = weight[0].numel() * y.numel()  # (Cin / groups) x kernel per output element
            s = self.stats[_conv_key(x, weight, relu, add_to)]
            s[0] += 1
            s[1] += seconds
            s[2] += 2.0 * macs
            s[3] = "bf16" if x.dtype != self._fast.torch.float32 else "fp32"
            return y

        fast.conv = timed_conv
        return self

    def __exit__(self, *exc) -> None:
        self._fast.conv = self._orig

    def reset(self) -> None:
        self.stats.clear()


def measure(size: int, precision: str, threads: int, repeat: int, peaks: dict, params: dict) -> dict:
    import torch
    from lfbench_methods.subfocal.inference import infer
    from lfbench_methods.subfocal.network import SubFocalNet

    torch.manual_seed(0)
    net = SubFocalNet(**params).eval()
    views = torch.rand((1, net.angular ** 2, size, size), generator=torch.Generator().manual_seed(0))
    flops = net.flops(size, size)
    best = None
    with ConvClock() as clock:
        for _ in range(max(1, repeat)):
            clock.reset()
            phases: dict = {}
            t, c = time.perf_counter(), time.process_time()
            infer(net, views, precision=precision, timings=phases)
            seconds, cpu = time.perf_counter() - t, time.process_time() - c
            if best is None or cpu < best["cpu_seconds"]:
                best = {"seconds": seconds, "cpu_seconds": cpu, "phases": phases["cpu"],
                        "convs": {k: list(v) for k, v in clock.stats.items()}}
    peak = peaks[precision]
    floor = flops["total"] / peak / 1e9
    convs = []
    for key, (calls, secs, fl, dtype) in sorted(best["convs"].items(), key=lambda kv: -kv[1][1]):
        rate = fl / secs / 1e9
        convs.append({"conv": key, "calls": calls, "seconds": secs, "gflop": fl / 1e9, "gflops_per_s": rate,
                      "fraction_of_peak": rate / peaks[dtype] if dtype in peaks else None})
    ph = best["phases"]
    conv2d = sum(c["seconds"] for c in convs if c["conv"].startswith("2d"))
    conv3d = sum(c["seconds"] for c in convs if c["conv"].startswith("3d"))
    return {"size": size, "precision": precision, "threads": threads, **params, "seconds": best["seconds"],
            "cpu_seconds": best["cpu_seconds"], "tflop": flops["total"] / 1e12,
            "tflop_extractor": flops["extractor"] / 1e12, "tflop_aggregation": flops["aggregation"] / 1e12,
            "peak_gflops_per_s": peak, "peaks_gflops_per_s": dict(peaks), "floor_s": floor,
            "ratio_to_floor": best["cpu_seconds"] / floor,
            "phases_s": {k: round(v, 4) for k, v in ph.items() if k.endswith("_s")},
            "features_conv_s": conv2d, "features_other_s": ph["features_s"] - conv2d,
            "aggregation_conv_s": conv3d, "aggregation_other_s": ph["aggregation_s"] - conv3d,
            "aggregation_floor_s": flops["aggregation"] / peak / 1e9,
            "features_floor_s": flops["extractor"] / peak / 1e9, "convs": convs}


def sweep(size: int, precision: str, params: dict, repeat: int = 2) -> list[dict]:
    """The fast path's convolution op alone, in the same process as the peak, on the peak's shape and on the
    network's own: a 3D layer over the widest region of the planned tiles (fused ReLU, and in-place add), the
    same over the whole image width when the plan is narrower (bf16 on AMX: oneDNN's slow path from 256 px
    wide, see lfbench_methods.subfocal.inference.AMX_MAX_CONV_WIDTH), and a slab of the first 3D convolution
    (4N channels in). GFLOP per CPU second, best of ``repeat`` after one warm-up. A class of the network's
    convolutions far below the peak at its own shape but near it here says: the shape (width, channels);
    near the peak here too: something around the op (layout, copies)."""
    import torch
    from lfbench_methods.subfocal.bench import PAPER_WIDTH
    from lfbench_methods.subfocal.fast import conv
    from lfbench_methods.subfocal.inference import _SLAB, EXACT_HALO, _spans, plan_tiles
    from lfbench_methods.subfocal.network import SubFocalNet

    net = SubFocalNet(**params)
    width, d, channels = params["width"], net.disparities.numel(), net.angular ** 2 * 4
    th, tw = plan_tiles(net, size, size, precision=precision)
    rows = max(r1 - r0 for *_, r0, r1 in _spans(size, th, EXACT_HALO))
    cols = max(c1 - c0 for *_, c0, c1 in _spans(size, tw, EXACT_HALO))
    dtype = torch.float32 if precision == "fp32" else torch.bfloat16
    g = torch.Generator().manual_seed(0)
    cl = torch.channels_last_3d

    def case(name: str, cin: int, cout: int, depth: int, h: int, w: int, padding: tuple, add: bool) -> dict:
        x = torch.rand((1, cin, depth, h, w), generator=g).to(dtype).contiguous(memory_format=cl)
        wt = (torch.randn((cout, cin, 3, 3, 3), generator=g) * 0.01).to(dtype).contiguous(memory_format=cl)
        b = torch.zeros(cout)
        out_depth = depth - 2 + 2 * padding[0]
        acc = torch.zeros((1, cout, out_depth, h, w), dtype=dtype).contiguous(memory_format=cl) if add else None
        flops = 2.0 * 27 * cin * cout * out_depth * h * w
        with torch.inference_mode():
            conv(x, wt, b, padding, relu=not add, add_to=acc)
            best = float("inf")
            for _ in range(max(1, repeat)):
                t = time.process_time()
                conv(x, wt, b, padding, relu=not add, add_to=acc)
                best = min(best, time.process_time() - t)
        return {"case": name, "shape": [cin, cout, depth, h, w], "cpu_seconds": best,
                "gflops_per_cpu_s": flops / best / 1e9}

    cases = [case("peak shape (lfbench bench peak)", PAPER_WIDTH, PAPER_WIDTH, 17, 64, 64, (1, 1, 1), False),
             case("a 3D layer of the planned tile", width, width, d, rows, cols, (1, 1, 1), False)]
    if cols < size:
        cases.append(case("a 3D layer as wide as the image", width, width, d, rows, size, (1, 1, 1), False))
    return cases + [case("a 3D layer of the planned tile, in-place add", width, width, d, rows, cols, (1, 1, 1),
                         True),
                    case("a first-convolution slab of the planned tile", channels, width, _SLAB + 2, rows, cols,
                         (0, 1, 1), False)]


def profile_table(size: int, precision: str, rows: int, params: dict) -> str:
    import torch
    from lfbench_methods.subfocal.inference import infer
    from lfbench_methods.subfocal.network import SubFocalNet
    from torch.profiler import ProfilerActivity, profile

    torch.manual_seed(0)
    net = SubFocalNet(**params).eval()
    views = torch.rand((1, net.angular ** 2, size, size), generator=torch.Generator().manual_seed(0))
    infer(net, views, precision=precision)
    with profile(activities=[ProfilerActivity.CPU], record_shapes=True) as prof:
        infer(net, views, precision=precision)
    events = sorted(prof.key_averages(group_by_input_shape=True), key=lambda e: -e.self_cpu_time_total)
    lines = ["| self ms | calls | op | input shapes |", "|---|---|---|---|"]
    for e in events[:rows]:
        shapes = str(e.input_shapes).replace("|", "/")[:120]
        lines.append(f"| {e.self_cpu_time_total / 1e3:.1f} | {e.count} | {e.key} | {shapes} |")
    return "\n".join(lines)


def table(records: list[dict]) -> str:
    out = []
    for r in records:
        out.append(f"### {r['size']}x{r['size']}, interval {r['interval']}, width {r['width']}, {r['precision']}, "
                   f"{r['threads']} thread(s), load {r['load_average']}\n")
        peaks = ", ".join(f"{k} {v:.0f}" for k, v in r["peaks_gflops_per_s"].items())
        out.append(f"{r['cpu_seconds']:.2f} CPU s ({r['seconds']:.2f} s wall) for {r['tflop']:.3f} TFLOP; peak "
                   f"{r['peak_gflops_per_s']:.0f} GFLOP/CPU s ({peaks}); "
                   f"floor {r['floor_s']:.2f} CPU s; **ratio to floor {r['ratio_to_floor']:.2f}**\n")
        out.append("| part | CPU seconds | at the peak |\n|---|---|---|")
        out.append(f"| features: convolutions | {r['features_conv_s']:.3f} | {r['features_floor_s']:.3f} (all FLOPs) |")
        out.append(f"| features: the rest | {r['features_other_s']:.3f} | |")
        out.append(f"| attention | {r['phases_s'].get('attention_s', 0):.3f} | |")
        out.append(f"| aggregation: convolutions | {r['aggregation_conv_s']:.3f} | "
                   f"{r['aggregation_floor_s']:.3f} (all FLOPs) |")
        out.append(f"| aggregation: the rest (volume, last layer, copies) | {r['aggregation_other_s']:.3f} | |\n")
        out.append("| convolution | calls | CPU seconds | GFLOP | GFLOP/CPU s | of its dtype's peak |\n"
                   "|---|---|---|---|---|---|")
        for c in r["convs"]:
            frac = "" if c["fraction_of_peak"] is None else f"{c['fraction_of_peak']:.2f}"
            out.append(f"| {c['conv']} | {c['calls']} | {c['seconds']:.3f} | {c['gflop']:.1f} | "
                       f"{c['gflops_per_s']:.0f} | {frac} |")
        if r.get("sweep"):
            out.append("\nThe convolution op alone, same process (GFLOP per CPU second):\n")
            out.append("| case | channels in, out, depth, rows, cols | GFLOP/CPU s | of the peak |\n|---|---|---|---|")
            for c in r["sweep"]:
                out.append(f"| {c['case']} | {', '.join(map(str, c['shape']))} | {c['gflops_per_cpu_s']:.0f} | "
                           f"{c['gflops_per_cpu_s'] / r['peak_gflops_per_s']:.2f} |")
        if r.get("profile"):
            out.append("\ntorch.profiler, one more run:\n\n" + r["profile"])
        out.append("")
    return "\n".join(out) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--size", type=int, default=128, help="light field size in px (size x size, 81 views)")
    p.add_argument("--interval", type=float, default=0.5)
    p.add_argument("--width", type=int, default=150, help="channels of the 3D aggregation (paper 150)")
    p.add_argument("--precision", nargs="+", default=["bf16"], choices=["fp32", "bf16"])
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--repeat", type=int, default=2, help="runs per case, the best kept (the first creates "
                                                         "oneDNN's primitives)")
    p.add_argument("--rounds", type=int, default=1, help="the precisions this many times, interleaved")
    p.add_argument("--profile", type=int, default=0, metavar="N", help="add torch.profiler's N costliest ops")
    p.add_argument("--sweep", action="store_true", help="also time the convolution op alone on the peak's shape "
                                                         "and on the network's own shapes at this size")
    p.add_argument("--json", type=Path)
    p.add_argument("--table", type=Path)
    args = p.parse_args(argv)
    if not 8 <= args.size <= 4096 or args.threads < 0:
        p.error("--size must be 8 to 4096 px and --threads >= 0")

    import torch
    from lfbench_methods.subfocal.bench import bench_peak

    from lfbench.runs.bench import machine_info
    from lfbench.utils.hardware import bf16_unavailable

    torch.set_num_threads(args.threads or os.cpu_count() or 1)
    missing = bf16_unavailable(torch.device("cpu"))
    if "bf16" in args.precision and missing is not None:
        print(f"bf16 skipped: {missing}", file=sys.stderr)
        args.precision = [x for x in args.precision if x != "bf16"]
    params = {"interval": args.interval, "width": args.width}
    records = []
    for _ in range(max(1, args.rounds)):
        for precision in args.precision:
            peaks = {q: bench_peak(q, threads=args.threads)["gflops_per_cpu_s"]
                     for q in ("fp32", "bf16") if q == "fp32" or missing is None}
            r = measure(args.size, precision, torch.get_num_threads(), args.repeat, peaks, params)
            r["load_average"] = round(os.getloadavg()[0], 2)
            r["machine"] = machine_info()
            if args.sweep:
                r["sweep"] = sweep(args.size, precision, params)
            if args.profile:
                r["profile"] = profile_table(args.size, precision, args.profile, params)
            records.append(r)
            print(f"{precision}: {r['cpu_seconds']:.2f} CPU s, floor {r['floor_s']:.2f} s, "
                  f"ratio {r['ratio_to_floor']:.2f} (features {r['phases_s']['features_s']:.2f} s, aggregation "
                  f"{r['phases_s']['aggregation_s']:.2f} s, of which convolutions {r['aggregation_conv_s']:.2f} s; "
                  f"load {r['load_average']})", flush=True)
    from lfbench.utils.atomic import write_text

    text = table(records)
    if args.json:
        write_text(args.json, json.dumps(records, indent=2) + "\n")
    if args.table:
        write_text(args.table, text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
