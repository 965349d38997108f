"""Where SubFocal's time goes on a device: training-step rates by width and batch, a torch.profiler table of one
training configuration, and inference seconds by width and image size, written as JSON (+ the profile table).

    python benchmarks/gpu_profile.py --out OUT                      # CUDA, ~1.5 min on an H200
    python benchmarks/gpu_profile.py --device cpu --quick --out OUT  # toy sizes, seconds (the test)

Training cases (random views, 32x32 patches, L1 on the disparity, Adam; 5 warm-up steps, then N timed steps
between synchronizations): width 16 at batch 32 (profiled: OUT/profile_w16_b32.txt), 4 and 128, and the
paper's width 150 at batch 32. Inference cases: the shipped width-16 weights on a 512x512 light field and the
paper network (random weights) at 128, 256 and 512 px, interval 0.5, fp32 and bf16, each after a warm-up at
64x64 (cuDNN's algorithm search for the full size, if cudnn.benchmark is on, falls inside the timed call:
``--cudnn-benchmark`` turns it on, as training does with ``training.cudnn_benchmark``). fp32 here is PyTorch's
default numerics on that device (on CUDA, cuDNN convolutions may use TF32) unless ``--ieee``. Cases stop
being started once ``--budget`` seconds are spent; the JSON is rewritten after each.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "methods" / "weights" / "subfocal_small.pt"


def _cases(quick: bool) -> tuple[list, list]:
    if quick:
        return [(4, 2, True, 2), (4, 1, False, 2)], [(16, 32), (4, 32)]
    return ([(16, 32, True, 20), (16, 4, False, 20), (16, 128, False, 20), (150, 32, False, 5)],
            [(16, 512), (150, 128), (150, 256), (150, 512)])


def train_rate(device, width: int, batch: int, steps: int, profile_to: Path | None, *, warmup: int = 5,
               profiled_steps: int = 3) -> float:
    """Training steps per second of SubFocal (interval 0.5) on random (batch, 81, 32, 32) views, after
    ``warmup`` untimed steps; ``profile_to``: a profiler table of ``profiled_steps`` more steps."""
    import torch
    from lfbench_methods.subfocal.network import SubFocalNet

    from lfbench.runs.bench import sync

    torch.manual_seed(0)
    net = SubFocalNet(interval=0.5, width=width).to(device).train()
    opt = torch.optim.Adam(net.parameters(), 1e-4)
    views = torch.rand(batch, 81, 32, 32, device=device)

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        disparity, _ = net(views)
        disparity.abs().mean().backward()
        opt.step()

    for _ in range(warmup):
        step()
    sync(device)
    start = time.perf_counter()
    for _ in range(steps):
        step()
    sync(device)
    rate = steps / (time.perf_counter() - start)
    if profile_to is not None:
        from torch.profiler import ProfilerActivity, profile

        activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda" else [])
        with profile(activities=activities) as prof:
            for _ in range(profiled_steps):
                step()
            sync(device)
        key = "cuda_time_total" if device.type == "cuda" else "cpu_time_total"
        profile_to.write_text(f"{profiled_steps} training steps, width {width}, batch {batch}, sorted by {key}\n"
                              + prof.key_averages().table(sort_by=key, row_limit=30) + "\n\nsorted by cpu_time_total\n"
                              + prof.key_averages().table(sort_by="cpu_time_total", row_limit=15), encoding="utf-8")
    return rate


def infer_seconds(device, width: int, size: int, precision: str) -> float:
    """Seconds of one interval-0.5 inference of a (1, 81, size, size) light field, after a 64x64 warm-up."""
    import torch
    from lfbench_methods.subfocal.inference import infer
    from lfbench_methods.subfocal.keras_import import build_from_checkpoint
    from lfbench_methods.subfocal.network import SubFocalNet

    from lfbench.runs.bench import sync

    torch.manual_seed(0)
    net = build_from_checkpoint(SHIPPED) if width == 16 else SubFocalNet(interval=0.5, width=width)
    net = net.eval().to(device)
    views = torch.rand((1, 81, size, size), generator=torch.Generator().manual_seed(0))
    warm = min(64, size)
    infer(net, views[..., :warm, :warm], precision=precision, max_memory_gb=None)
    sync(device)
    start = time.perf_counter()
    infer(net, views, precision=precision, max_memory_gb=None)
    sync(device)
    return time.perf_counter() - start


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cuda", help="cuda, cuda:K or cpu (default cuda)")
    p.add_argument("--out", type=Path, required=True, help="folder for gpu_profile.json and the profile table")
    p.add_argument("--budget", type=float, default=150.0, help="no new case starts after this many seconds")
    p.add_argument("--quick", action="store_true", help="toy sizes (seconds; what the test runs)")
    p.add_argument("--cudnn-benchmark", action="store_true", help="let cuDNN time its algorithms per shape")
    p.add_argument("--ieee", action="store_true", help="IEEE fp32 on CUDA (TF32 off)")
    args = p.parse_args(argv)
    import torch

    from lfbench.runs.bench import machine_info
    from lfbench.utils.errors import LFBenchError
    from lfbench.utils.hardware import bf16_unavailable, fp32_numerics, resolve_device, set_fp32_numerics

    try:
        device = resolve_device(args.device)
    except LFBenchError as exc:
        print(f"gpu_profile: error: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    if args.ieee:
        set_fp32_numerics(tf32=False)
    torch.backends.cudnn.benchmark = args.cudnn_benchmark
    report: dict = {"device": str(device), "quick": args.quick, "fp32": fp32_numerics(),
                    "cudnn_benchmark": args.cudnn_benchmark, "machine": machine_info(), "train": [], "inference": []}
    path = args.out / "gpu_profile.json"
    clock = time.perf_counter()
    train_cases, infer_cases = _cases(args.quick)
    for width, batch, profiled, steps in train_cases:
        if time.perf_counter() - clock > args.budget / 2:
            break
        case: dict = {"width": width, "batch": batch, "steps": steps}
        try:
            table = args.out / f"profile_w{width}_b{batch}.txt" if profiled else None
            # quick: one warm-up and one profiled step (the profiler's table costs ~6 s per profiled step on a CPU)
            case["steps_per_s"] = train_rate(device, width, batch, steps, table,
                                             **({"warmup": 1, "profiled_steps": 1} if args.quick else {}))
        except Exception as exc:  # noqa: BLE001 - a failed case is recorded, the others still run
            case["error"] = f"{type(exc).__name__}: {exc}"[:300]
        report["train"].append(case)
        print(f"[train] {json.dumps(case)}", flush=True)
        path.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    for width, size in infer_cases:
        for precision in ("fp32", "bf16"):
            if time.perf_counter() - clock > args.budget:
                break
            case = {"width": width, "size": size, "interval": 0.5, "precision": precision}
            missing = bf16_unavailable(device) if precision == "bf16" else None
            try:
                if missing is not None:
                    case["skipped"] = missing
                else:
                    case["seconds"] = infer_seconds(device, width, size, precision)
            except Exception as exc:  # noqa: BLE001
                case["error"] = f"{type(exc).__name__}: {exc}"[:300]
            report["inference"].append(case)
            print(f"[inference] {json.dumps(case)}", flush=True)
            path.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    report["total_s"] = round(time.perf_counter() - clock, 1)
    path.write_text(json.dumps(report, indent=2) + "\n", encoding="utf-8")
    print(f"wrote {path} ({report['total_s']} s)")
    return 1 if any("error" in c for c in report["train"] + report["inference"]) else 0


if __name__ == "__main__":
    raise SystemExit(main())
