"""The GPU check: what lfbench does on a CUDA device, in one run of a few minutes, written as JSON.

    python benchmarks/gpu_check.py --json gpu_check.json                 # the GPU (cuda), < 8 min on an H100
    python benchmarks/gpu_check.py --device cpu --quick --json quick.json  # small sizes, seconds (the test)

Sections (each a dict in ``sections``; one that fails holds ``error``, one the machine cannot run ``skipped``):

- ``inference``: the paper network (width 150, random weights) on one 512x512 light field at intervals 0.5
  and 0.1, fp32 and bf16: seconds (after a warm-up at 64x64; synchronized clocks) and GB (CUDA:
  torch.cuda.max_memory_allocated; CPU: the process's peak RSS);
- ``gpu_vs_cpu``: the shipped weights (methods/weights/subfocal_small.pt) on a synthetic 128x128 scene, the
  device against the CPU, both IEEE fp32 (TF32 off): max |diff| of the disparity, px;
- ``tiled_vs_whole``: on the device, the exact tiling against whole-image inference: max |diff| px;
- ``phase``: Fourier (phase) sub-pixel shifts on the device against the CPU, forward and backward (the
  gradient of a weighted sum with respect to the views): max |diff|;
- ``training``: configs/subfocal_paper.toml (its network, batch 32, patch, Adam) for 50 steps of stage 1 on
  synthetic scenes (or the HCI data with --hci): an uninterrupted run (steps/s, the median of the per-step
  rates after 5 warm-up steps), and a run killed with SIGKILL after its checkpoint at step 25 and resumed by
  the same command (the resumed run's final weights against the uninterrupted run's: max |diff|);
- ``ddp``: with 2 or more GPUs, the same training on 2 GPUs through torchrun (steps/s; both ranks end with
  bit-identical parameters); otherwise skipped.

``targets`` compares the CUDA numbers with the issue's targets (interval 0.5: bf16 < 1 s, fp32 < 2 s;
interval 0.1 < 5 s; training >= 5 steps/s); ``--quick`` (for the tests) shrinks every size and step count.
Exit code 1 when a section failed.
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PAPER_CONFIG = ROOT / "configs" / "subfocal_paper.toml"
SHIPPED = ROOT / "methods" / "weights" / "subfocal_small.pt"
TARGETS = {"interval_0.5_bf16_s": 1.0, "interval_0.5_fp32_s": 2.0, "interval_0.1_s": 5.0, "train_steps_per_s": 5.0}


def _sizes(quick: bool) -> dict:
    if quick:
        return {"size": 24, "width": 4, "intervals": [1.0, 0.5], "compare_size": 24, "steps": 4, "kill_after": 2,
                "batch": 2, "patch": 16, "model_width": 4, "synthetic_size": 48, "warmup": 16}
    return {"size": 512, "width": 150, "intervals": [0.5, 0.1], "compare_size": 128, "steps": 50, "kill_after": 25,
            "batch": 32, "patch": None, "model_width": None, "synthetic_size": 256, "warmup": 64}


def _memory_gb(device) -> float:
    import torch

    from lfbench.runs.bench import peak_rss_gb

    return torch.cuda.max_memory_allocated(device) / 1e9 if device.type == "cuda" else peak_rss_gb()


def section_inference(device, sizes: dict) -> dict:
    import torch
    from lfbench_methods.subfocal.inference import infer
    from lfbench_methods.subfocal.network import SubFocalNet

    from lfbench.runs.bench import sync
    from lfbench.utils.hardware import bf16_unavailable

    out: dict = {"size": sizes["size"], "width": sizes["width"], "cases": []}
    views = torch.rand((1, 81, sizes["size"], sizes["size"]), generator=torch.Generator().manual_seed(0))
    warm = views[..., :sizes["warmup"], :sizes["warmup"]]
    for interval in sizes["intervals"]:
        torch.manual_seed(0)
        net = SubFocalNet(interval=interval, width=sizes["width"]).eval().to(device)
        for precision in ("fp32", "bf16"):
            case = {"interval": interval, "precision": precision}
            missing = bf16_unavailable(device) if precision == "bf16" else None
            if missing is not None:
                out["cases"].append({**case, "skipped": missing})
                continue
            infer(net, warm, precision=precision, max_memory_gb=None)  # cuDNN / oneDNN set-up, lazy init
            if device.type == "cuda":
                torch.cuda.reset_peak_memory_stats(device)
            sync(device)
            start = time.perf_counter()
            res = infer(net, views, precision=precision, max_memory_gb=None)
            sync(device)
            case.update(seconds=time.perf_counter() - start, memory_gb=_memory_gb(device),
                        memory="cuda_max_allocated" if device.type == "cuda" else "peak_rss",
                        finite=bool(torch.isfinite(res.disparity).all()))
            out["cases"].append(case)
        del net
    return out


def _scene_views(size: int):
    """(1, 81, size, size) gray views of a synthetic scene (lfbench.data.synth), float32 in [0, 1]."""
    import torch

    from lfbench.data.scene import rgb_to_gray
    from lfbench.data.synth import generate_scene

    scene = generate_scene(seed=7, size=size)
    gray = rgb_to_gray(scene.views)  # (9, 9, H, W)
    return torch.from_numpy(gray.reshape(1, 81, size, size).copy())


def section_gpu_vs_cpu(device, sizes: dict) -> dict:
    from lfbench_methods.subfocal.inference import infer
    from lfbench_methods.subfocal.keras_import import build_from_checkpoint

    views = _scene_views(sizes["compare_size"])
    cpu = infer(build_from_checkpoint(SHIPPED).eval(), views, precision="fp32")
    dev = infer(build_from_checkpoint(SHIPPED).eval().to(device), views, precision="fp32")
    return {"weights": SHIPPED.name, "size": sizes["compare_size"], "device": str(device),
            "max_abs_diff_px": float((dev.disparity - cpu.disparity).abs().max()),
            "mean_abs_diff_px": float((dev.disparity - cpu.disparity).abs().mean())}


def section_tiled_vs_whole(device, sizes: dict) -> dict:
    from lfbench_methods.subfocal.inference import infer
    from lfbench_methods.subfocal.keras_import import build_from_checkpoint

    size = sizes["compare_size"]
    views = _scene_views(size)
    net = build_from_checkpoint(SHIPPED).eval().to(device)
    whole = infer(net, views, tile=size)
    tile = max(8, size // 3)
    tiled = infer(net, views, tile=tile)
    return {"size": size, "tile": tile, "tiles": (-(-size // tile)) ** 2,
            "max_abs_diff_px": float((tiled.disparity - whole.disparity).abs().max())}


def section_phase(device, sizes: dict) -> dict:
    import torch

    from lfbench.data.shift import angular_offsets, disparity_grid, shift_views

    g = torch.Generator().manual_seed(0)
    size = sizes["compare_size"]
    x = torch.rand((1, 81, 4, size, size), generator=g)
    weight = torch.rand((1, 9, 81, 4, size, size), generator=g)
    offsets, grid = angular_offsets(9), disparity_grid(-2.0, 2.0, 0.5)

    def run(dev):
        xd = x.to(dev, copy=True).requires_grad_(True)  # a leaf on each device (x itself stays grad-free)
        y = shift_views(xd, offsets.to(dev), grid.to(dev), "phase")
        (y * weight.to(dev)).sum().backward()
        return y.detach().cpu(), xd.grad.cpu()

    y_cpu, g_cpu = run(torch.device("cpu"))
    y_dev, g_dev = run(device)
    return {"size": size, "forward_max_abs_diff": float((y_dev - y_cpu).abs().max()),
            "backward_max_abs_diff": float((g_dev - g_cpu).abs().max()),
            "finite": bool(torch.isfinite(y_dev).all() and torch.isfinite(g_dev).all())}


def _train_config(folder: Path, device, sizes: dict, hci: Path | None) -> Path:
    """configs/subfocal_paper.toml with stage 1 only, ``steps`` steps, checkpoints every ``kill_after``,
    no validation, on ``device``; synthetic scenes unless ``hci`` has the paper's training scenes."""
    from lfbench.training.config import TrainConfig
    from lfbench.utils.tomlfile import toml_text

    cfg = TrainConfig.from_toml(PAPER_CONFIG).to_dict() if hci else None
    if cfg is None:
        os.environ.setdefault("LFBENCH_HCI_ROOT", str(folder))  # the paper config names it; unused here
        cfg = TrainConfig.from_toml(PAPER_CONFIG).to_dict()
        cfg["data"] = {**cfg["data"], "roots": [], "train": ["synthetic"], "validation": [], "invalid_area": None,
                       "scene_weights": {}, "default_scene_weight": 1,
                       "synthetic": [{"category": "synthetic", "seed": 1, "size": sizes["synthetic_size"],
                                      "scenes": 2}]}
        cfg["data"] = {k: v for k, v in cfg["data"].items() if v is not None}
    if sizes["patch"]:
        cfg["data"]["patch"] = sizes["patch"]
    if sizes["model_width"]:
        cfg["model"]["width"] = sizes["model_width"]
    cfg["training"] = {**cfg["training"], "batch_size": sizes["batch"], "device": str(device),
                       "checkpoint_every": sizes["kill_after"], "log_every": 1, "threads": 0}
    cfg["validation"] = {**cfg["validation"], "every": 0}
    cfg["stages"] = [{**cfg["stages"][0], "steps": sizes["steps"]}]
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "train.toml"
    path.write_text(toml_text(cfg, "configs/subfocal_paper.toml as benchmarks/gpu_check.py runs it"), encoding="utf-8")
    return path


def _lfbench(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lfbench", *args], capture_output=True, text=True, check=False)


def _final_state(out: Path) -> dict:
    import torch

    return torch.load(out / "final.pt", map_location="cpu", weights_only=True)["state_dict"]


def _rates(out: Path, skip: int = 5) -> list[float]:
    entries = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines() if line.strip()]
    rates = [e["steps_per_s"] for e in entries if e.get("event") == "train"]
    return rates[skip:] or rates


def section_training(device, sizes: dict, hci: Path | None, work: Path) -> dict:
    config = _train_config(work, device, sizes, hci)
    plain, killed = work / "plain", work / "killed"
    proc = _lfbench("train", str(config), "--out", str(plain), "--no-progress")
    if proc.returncode != 0:
        raise RuntimeError(f"lfbench train exited {proc.returncode}: {proc.stderr.strip()[-500:]}")
    # The kill: a run of the same config that SIGKILLs itself once the checkpoint at kill_after is written.
    leg = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--_kill-leg", str(config), str(killed),
                          str(sizes["kill_after"])], capture_output=True, text=True, check=False)
    was_killed = leg.returncode == -signal.SIGKILL
    resumed = _lfbench("train", str(config), "--out", str(killed), "--no-progress")
    if resumed.returncode != 0:
        raise RuntimeError(f"resuming exited {resumed.returncode}: {resumed.stderr.strip()[-500:]}")
    a, b = _final_state(plain), _final_state(killed)
    diff = max(float((a[k].float() - b[k].float()).abs().max()) for k in a if a[k].is_floating_point())
    summary = json.loads((killed / "summary.json").read_text())
    rates = _rates(plain)
    return {"config": str(PAPER_CONFIG.relative_to(ROOT)), "data": "hci" if hci else "synthetic",
            "batch": sizes["batch"], "steps": sizes["steps"], "steps_per_s": statistics.median(rates),
            "killed_at_step": sizes["kill_after"] + 1 if was_killed else None, "kill_exit": leg.returncode,
            "resumed": "resuming from" in resumed.stderr, "resumed_steps": summary["steps"],
            "resumed_vs_uninterrupted_max_abs_diff": diff}


def section_ddp(device, sizes: dict, hci: Path | None, work: Path) -> dict:
    import torch

    if device.type != "cuda" or torch.cuda.device_count() < 2:
        return {"skipped": "needs 2 CUDA GPUs"}
    config = _train_config(work, torch.device("cuda"), sizes, hci)
    out = work / "ddp"
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
                           "-m", "lfbench", "train", str(config), "--out", str(out), "--no-progress"],
                          capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        raise RuntimeError(f"torchrun exited {proc.returncode}: {proc.stderr.strip()[-500:]}")
    final = torch.load(out / "final.pt", map_location="cpu", weights_only=True)
    digests = final["training"]["rank_parameters_sha256"]
    return {"gpus": 2, "batch": sizes["batch"], "steps_per_s": statistics.median(_rates(out)),
            "ranks_identical": len(set(digests)) == 1}


def _kill_leg(config: str, out: str, after: int) -> None:
    """Train ``config`` into ``out`` and SIGKILL this process at step ``after`` + 1 (the checkpoint of step
    ``after`` is on disk by then: the loop logs a step before it checkpoints it)."""
    from lfbench.training.config import TrainConfig
    from lfbench.training.loop import train

    class Kill:
        def record(self, entry: dict) -> None:
            if entry.get("event") == "train" and entry.get("global_step", 0) > after:
                os.kill(os.getpid(), signal.SIGKILL)

        def close(self) -> None:
            pass

    train(TrainConfig.from_toml(config), out, progress=False, loggers=[Kill()])


def _targets(sections: dict, device) -> dict:
    if device.type != "cuda":
        return {"note": "targets apply to a CUDA GPU"}
    cases = {(c["interval"], c["precision"]): c.get("seconds") for c in sections["inference"].get("cases", [])}
    got = {"interval_0.5_bf16_s": cases.get((0.5, "bf16")), "interval_0.5_fp32_s": cases.get((0.5, "fp32")),
           "interval_0.1_s": min([s for (i, _), s in cases.items() if i == 0.1 and s is not None], default=None),
           "train_steps_per_s": sections["training"].get("steps_per_s")}
    out = {}
    for key, limit in TARGETS.items():
        value = got[key]
        met = None if value is None else (value >= limit if key == "train_steps_per_s" else value < limit)
        out[key] = {"value": value, "target": limit, "met": met}
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--device", default="cuda", help="cuda, cuda:K or cpu (default cuda)")
    p.add_argument("--quick", action="store_true", help="small sizes and few steps (seconds; what the test runs)")
    p.add_argument("--json", type=Path, default=Path("gpu_check.json"), help="output JSON (default gpu_check.json)")
    p.add_argument("--hci", type=Path, default=None, help="HCI data root: train on its scenes instead of synthetic")
    p.add_argument("--only", nargs="+", default=None,
                   choices=["inference", "gpu_vs_cpu", "tiled_vs_whole", "phase", "training", "ddp"])
    p.add_argument("--_kill-leg", nargs=3, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args._kill_leg:
        _kill_leg(args._kill_leg[0], args._kill_leg[1], int(args._kill_leg[2]))
        return 0
    import torch

    from lfbench.runs.bench import machine_info
    from lfbench.utils.errors import LFBenchError
    from lfbench.utils.hardware import fp32_numerics, resolve_device, set_fp32_numerics

    try:
        device = resolve_device(args.device)
    except LFBenchError as exc:
        print(f"gpu_check: error: {exc}", file=sys.stderr)
        return 2
    if args.hci is not None:
        os.environ["LFBENCH_HCI_ROOT"] = str(args.hci.resolve())
    set_fp32_numerics(tf32=False)
    if device.type == "cuda":
        torch.cuda.set_device(device)
    sizes = _sizes(args.quick)
    report: dict = {"device": str(device), "gpu": torch.cuda.get_device_name(device) if device.type == "cuda" else None,
                    "quick": args.quick, "fp32": fp32_numerics(), "machine": machine_info(), "sections": {}}
    clock = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="lfbench-gpu-check-") as tmp:
        work = Path(tmp)
        plan = [("inference", lambda: section_inference(device, sizes)),
                ("gpu_vs_cpu", lambda: section_gpu_vs_cpu(device, sizes)),
                ("tiled_vs_whole", lambda: section_tiled_vs_whole(device, sizes)),
                ("phase", lambda: section_phase(device, sizes)),
                ("training", lambda: section_training(device, sizes, args.hci, work / "train")),
                ("ddp", lambda: section_ddp(device, sizes, args.hci, work / "ddp"))]
        for name, fn in plan:
            if args.only and name not in args.only:
                continue
            start = time.perf_counter()
            try:
                result = fn()
            except Exception as exc:  # noqa: BLE001 - a failed section is recorded, the others still run
                result = {"error": f"{type(exc).__name__}: {exc}", "traceback": traceback.format_exc()[-2000:]}
            result["section_s"] = round(time.perf_counter() - start, 2)
            report["sections"][name] = result
            print(f"[{name}] {json.dumps({k: v for k, v in result.items() if k != 'traceback'})}", flush=True)
            args.json.write_text(json.dumps(report, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    report["total_s"] = round(time.perf_counter() - clock, 1)
    if "inference" in report["sections"] and "training" in report["sections"]:
        report["targets"] = _targets(report["sections"], device)
    args.json.write_text(json.dumps(report, indent=2, sort_keys=True) + "\n", encoding="utf-8")
    print(f"wrote {args.json} ({report['total_s']} s)")
    return 1 if any("error" in s for s in report["sections"].values()) else 0


if __name__ == "__main__":
    sys.exit(main())
