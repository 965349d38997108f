"""Speed and memory benchmarks (``lfbench bench``; not part of the tests).

Every case runs in a fresh Python subprocess (``python -m lfbench.runs.bench CASE_JSON``) so that its peak
memory is the peak resident set size (``ru_maxrss``) of a process that did only that case; the record
also gives the RSS just before the measured work (interpreter, torch, weights), so the growth is the
difference. Each record carries the machine it ran on (CPU model, cores, torch threads, torch version,
load average before and after).

Benches (functions ``bench_<name>``, each returning one record, a dict):

- ``peak``: a 150 -> 150 3x3x3 channels-last conv3d of the paper's shape through the op SubFocal's fast path
  uses, fp32 or bf16: the GFLOP/s the hardware reaches here, against which the network is judged;
- ``inference``: one H x W scene through ``lfbench_methods.subfocal.inference.infer`` (paper network, width
  150, random weights unless a checkpoint is given; tiles from ``max_memory_gb``): seconds, peak memory,
  achieved GFLOP/s (the network's FLOPs on the image, halos not counted), the phases;
- ``volume``: the bilinear cost volume alone (GB/s of volume written), fast gather or the reference
  grid_sample path;
- ``train``: optimizer steps per second (Adam + L1 on random patches, training mode, channels-last);
- ``metrics``: the metric engine (``lfbench.scoring.rules.score_scene``, general metrics) over synthetic scenes
  x methods written in the HCI layout.

:func:`attach_peaks` puts the peak measured next to each inference record beside it (fraction of peak by
wall time and per CPU second, the floor = network FLOPs / peak, and seconds / floor). On a shared machine
the wall-time numbers swing with the other processes' load; the CPU-time fraction much less.
"""

from __future__ import annotations

import json
import math
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from lfbench.utils.errors import SpecError

PRECISIONS = ("fp32", "bf16")
BENCHES = ("peak", "inference", "volume", "train", "metrics")
PAPER_WIDTH = 150


# --------------------------------------------------------------------------- machine and memory

def cpu_model() -> str:
    """The CPU's model name (from /proc/cpuinfo on Linux), else platform.processor()."""
    try:
        for line in Path("/proc/cpuinfo").read_text(encoding="utf-8", errors="replace").splitlines():
            if line.lower().startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine_info() -> dict:
    """CPU model, logical cores, torch threads and version, CPU capability, GPU if any, load average."""
    import torch

    info = {"cpu": cpu_model(), "cores": os.cpu_count(), "threads": torch.get_num_threads(),
            "torch": str(torch.__version__), "python": platform.python_version(),
            "cpu_capability": _cpu_capability(), "onednn": bool(torch.backends.mkldnn.is_available()),
            "gpu": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None}
    info["load_average"] = _load()
    return info


def _cpu_capability() -> str | None:
    import torch

    try:
        return str(torch.backends.cpu.get_cpu_capability())
    except AttributeError:  # older torch
        return None


def _load() -> float | None:
    try:
        return round(os.getloadavg()[0], 2)
    except OSError:
        return None


def peak_rss_gb() -> float:
    """Peak resident set size of this process so far, GB (ru_maxrss: KiB on Linux, bytes on macOS)."""
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return rss / 1e9 if sys.platform == "darwin" else rss * 1024 / 1e9


def current_rss_gb() -> float:
    """Resident set size now, GB (/proc/self/statm; the peak where that is absent)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
        return pages * os.sysconf("SC_PAGE_SIZE") / 1e9
    except (OSError, ValueError, IndexError):
        return peak_rss_gb()


def _set_threads(threads: int) -> int:
    import torch

    n = threads if threads > 0 else (os.cpu_count() or 1)
    torch.set_num_threads(n)
    return n


def _cpu_s() -> float:
    """CPU seconds (user + system) this process has used."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _timed(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """(best wall time, mean CPU time) of ``repeat`` calls, s. CPU time counts the work itself and is
    much less inflated than wall time when other processes compete for the cores."""
    best = math.inf
    cpu0 = _cpu_s()
    for _ in range(max(1, repeat)):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best, (_cpu_s() - cpu0) / max(1, repeat)


def _dtype(precision: str):
    import torch

    if precision not in PRECISIONS:
        raise SpecError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    return torch.float32 if precision == "fp32" else torch.bfloat16


# --------------------------------------------------------------------------- the benches

def bench_peak(precision: str = "fp32", depth: int = 17, size: int = 64, width: int = PAPER_WIDTH,
               repeat: int = 3, threads: int = 0) -> dict:
    """GFLOP/s of a width -> width 3x3x3 conv3d (+ bias, ReLU) on (1, width, depth, size, size) channels-last,
    through the fused op of SubFocal's fast path; best of ``repeat`` after one warm-up."""
    import torch
    from lfbench_methods.subfocal.fast import conv

    _set_threads(threads)
    dtype = _dtype(precision)
    g = torch.Generator().manual_seed(0)
    x = torch.rand((1, width, depth, size, size), generator=g).to(dtype).contiguous(
        memory_format=torch.channels_last_3d)
    w = (torch.randn((width, width, 3, 3, 3), generator=g) * 0.01).to(dtype).contiguous(
        memory_format=torch.channels_last_3d)
    b = torch.zeros(width)
    flops = 2.0 * 27 * width * width * depth * size * size
    with torch.inference_mode():
        conv(x, w, b, (1, 1, 1), relu=True)
        seconds, cpu = _timed(lambda: conv(x, w, b, (1, 1, 1), relu=True), repeat)
    return {"bench": "peak", "precision": precision, "shape": [width, depth, size, size], "seconds": seconds,
            "cpu_seconds": cpu, "gflops_per_s": flops / seconds / 1e9, "gflops_per_cpu_s": flops / cpu / 1e9}


def _paper_net(interval: float, width: int, weights: str | None, seed: int = 0):
    import torch
    from lfbench_methods.subfocal.network import SubFocalNet

    if weights:
        from lfbench_methods.subfocal.keras_import import build_from_checkpoint

        net = build_from_checkpoint(Path(weights))
        if abs(net.config()["interval"] - interval) > 1e-9:
            cfg = {**net.config(), "interval": interval}
            state = net.state_dict()
            net = SubFocalNet(**cfg)
            net.load_state_dict(state)
        return net.eval()
    torch.manual_seed(seed)
    return SubFocalNet(interval=interval, width=width).eval()


def bench_inference(size: int = 512, interval: float = 0.5, precision: str = "fp32", width: int = PAPER_WIDTH,
                    weights: str | None = None, max_memory_gb: float = 4.0, tile: int = 0, threads: int = 0,
                    repeat: int = 1, seed: int = 0) -> dict:
    """One size x size light field (81 random views) through ``infer``; best of ``repeat`` runs."""
    import torch
    from lfbench_methods.subfocal.inference import infer, plan_tiles

    _set_threads(threads)
    _dtype(precision)
    net = _paper_net(interval, width, weights, seed)
    views = torch.rand((1, 81, size, size), generator=torch.Generator().manual_seed(seed))
    flops = net.flops(size, size)
    tiles = plan_tiles(net, size, size, max_memory_gb=max_memory_gb, precision=precision) if tile == 0 else (tile,
                                                                                                               tile)
    baseline = current_rss_gb()
    phases: dict = {}
    seconds, cpu = _timed(lambda: infer(net, views, tile=tile, max_memory_gb=max_memory_gb, precision=precision,
                                        timings=phases), repeat)
    return {"bench": "inference", "size": size, "interval": interval, "precision": precision, "seconds": seconds,
            "peak_memory_gb": peak_rss_gb(), "baseline_memory_gb": baseline,
            "gflops_per_s": flops["total"] / seconds / 1e9, "cpu_seconds": cpu,
            "gflops_per_cpu_s": flops["total"] / cpu / 1e9, "width": net.config()["width"],
            "disparities": net.disparities.numel(), "weights": weights or "random", "max_memory_gb": max_memory_gb,
            "tile": list(phases.get("tile", tiles)), "tiles": phases.get("tiles"),
            "tflop": flops["total"] / 1e12, "tflop_aggregation": flops["aggregation"] / 1e12,
            "tflop_extractor": flops["extractor"] / 1e12,
            "phases_s": {k: round(v, 3) for k, v in phases.items() if k.endswith("_s")}}


def bench_volume(size: int = 512, interval: float = 0.5, precision: str = "fp32", method: str = "gather",
                 threads: int = 0, repeat: int = 1, chunk_disparities: int = 2) -> dict:
    """The whole bilinear cost volume (1, 4N, D, size, size) of random features, built ``chunk_disparities``
    planes at a time into one reused buffer: GB/s = volume bytes / seconds. method: ``gather`` (the fast
    path, channels-last in ``precision``) or ``grid_sample`` (lfbench.data.shift.shift_views, fp32)."""
    import torch
    from lfbench_methods.subfocal.fast import VolumeGather, pad_features, shift_plan
    from lfbench_methods.subfocal.network import FEATURES

    from lfbench.data.shift import angular_offsets, disparity_grid, shift_views

    _set_threads(threads)
    dtype = _dtype(precision) if method == "gather" else torch.float32
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
        seconds, cpu = _timed(run_gather if method == "gather" else run_grid, repeat)
    item = torch.empty((), dtype=dtype).element_size()
    gb = d * size * size * n * FEATURES * item / 1e9
    return {"bench": "volume", "size": size, "interval": interval, "precision": precision if method == "gather"
            else "fp32", "method": method, "seconds": seconds, "cpu_seconds": cpu, "volume_gb": gb,
            "gb_per_s": gb / seconds, "peak_memory_gb": peak_rss_gb(), "baseline_memory_gb": baseline}


def bench_train(width: int = PAPER_WIDTH, batch: int = 2, patch: int = 32, steps: int = 2, interval: float = 0.5,
                channels_last: bool = True, threads: int = 0, seed: int = 0) -> dict:
    """Training steps per second: SubFocalNet(width) in training mode, Adam (lr 1e-3, eps 1e-7) on an L1 loss
    of random (batch, 81, patch, patch) views against random disparities; one warm-up step, then ``steps``."""
    import torch
    from lfbench_methods.subfocal.network import SubFocalNet

    _set_threads(threads)
    torch.manual_seed(seed)
    net = SubFocalNet(width=width, interval=interval).train()
    if channels_last:
        for m in net.modules():
            if isinstance(m, torch.nn.Conv2d):
                m.to(memory_format=torch.channels_last)
            elif isinstance(m, torch.nn.Conv3d):
                m.to(memory_format=torch.channels_last_3d)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, eps=1e-7)
    g = torch.Generator().manual_seed(seed)
    views = torch.rand((batch, 81, patch, patch), generator=g)
    target = torch.rand((batch, patch, patch), generator=g) * 8 - 4

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        disp, _ = net(views)
        torch.nn.functional.l1_loss(disp, target).backward()
        opt.step()

    baseline = current_rss_gb()
    step()
    t, cpu0 = time.perf_counter(), _cpu_s()
    for _ in range(max(1, steps)):
        step()
    seconds = (time.perf_counter() - t) / max(1, steps)
    cpu = (_cpu_s() - cpu0) / max(1, steps)
    forward = net.flops(patch, patch)["total"] * batch
    return {"bench": "train", "width": width, "batch": batch, "patch": patch, "interval": interval,
            "channels_last": channels_last, "steps": max(1, steps), "seconds": seconds, "seconds_per_step": seconds,
            "steps_per_s": 1.0 / seconds, "gflops_per_s": 3 * forward / seconds / 1e9, "cpu_seconds": cpu,
            "gflops_per_cpu_s": 3 * forward / cpu / 1e9,
            "peak_memory_gb": peak_rss_gb(), "baseline_memory_gb": baseline, "precision": "fp32"}


def _write_synthetic_scene(folder: Path, size: int, seed: int):
    """An HCI-layout scene folder with parameters.cfg and gt_disp_lowres.pfm (smooth random disparity)."""
    import numpy as np

    from lfbench.data.params import SceneParameters
    from lfbench.data.pfm import write_pfm

    folder.mkdir(parents=True, exist_ok=True)
    params = SceneParameters(focal_length_mm=100.0, image_resolution_x_px=size, image_resolution_y_px=size,
                             sensor_size_mm=35.0, num_cams_x=9, num_cams_y=9, baseline_mm=90.0,
                             focus_distance_m=8.0, disp_min=-2.0, disp_max=2.0, name=folder.name,
                             category="synthetic")
    (folder / "parameters.cfg").write_text(params.to_cfg(), encoding="utf-8")
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    gt = (1.5 * np.sin(2 * np.pi * (x * rng.uniform(0.5, 2) + rng.uniform())) * np.cos(2 * np.pi * y)).astype(
        np.float32)
    write_pfm(folder / "gt_disp_lowres.pfm", gt)
    return gt


def bench_metrics(scenes: int = 12, methods: int = 5, size: int = 512, repeat: int = 1) -> dict:
    """The metric engine: ``score_scene`` with the general metrics (BadPix 0.01/0.03/0.07, MSE x100, Q25)
    for ``methods`` predictions (ground truth + noise of growing size) on each of ``scenes`` synthetic
    size x size scenes (HCI layout in a temporary folder; reading the ground truth is part of the time)."""
    import numpy as np

    from lfbench.data.scene import Scene
    from lfbench.scoring.metrics import GENERAL_METRICS
    from lfbench.scoring.rules import score_scene

    rng = np.random.default_rng(0)
    with tempfile.TemporaryDirectory(prefix="lfbench-bench-") as tmp:
        preds = []
        folders = []
        for i in range(scenes):
            folder = Path(tmp) / "synthetic" / f"scene_{i:02d}"
            gt = _write_synthetic_scene(folder, size, i)
            folders.append(folder)
            preds.append([gt + rng.normal(0, 0.02 * (m + 1), gt.shape).astype(np.float32) for m in range(methods)])
        baseline = current_rss_gb()

        def run() -> None:
            for folder, per_scene in zip(folders, preds, strict=True):
                scene = Scene(folder)
                for pred in per_scene:
                    score_scene(scene, pred, GENERAL_METRICS)

        seconds, cpu = _timed(run, repeat)
    pairs = scenes * methods
    return {"bench": "metrics", "scenes": scenes, "methods": methods, "size": size, "metrics": len(GENERAL_METRICS),
            "seconds": seconds, "cpu_seconds": cpu, "scores_per_s": pairs / seconds,
            "mpixels_per_s": pairs * size * size / seconds / 1e6,
            "peak_memory_gb": peak_rss_gb(), "baseline_memory_gb": baseline}


_FUNCTIONS = {"peak": bench_peak, "inference": bench_inference, "volume": bench_volume, "train": bench_train,
              "metrics": bench_metrics}


# --------------------------------------------------------------------------- running cases

def run_case(bench: str, params: dict) -> dict:
    """Run one case in this process: the bench's record plus ``machine`` (load average before and after)."""
    if bench not in _FUNCTIONS:
        raise SpecError(f"unknown bench {bench!r} (one of {', '.join(BENCHES)})")
    load_before = _load()
    record = _FUNCTIONS[bench](**params)
    machine = machine_info()
    machine["load_average_before"] = load_before
    record["machine"] = machine
    return record


def run_isolated(bench: str, params: dict, timeout_s: float | None = None) -> dict:
    """Run one case in a fresh Python process (its own peak RSS); a failed case gives a record with ``error``."""
    cmd = [sys.executable, "-m", "lfbench.runs.bench", json.dumps({"bench": bench, "params": params})]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=False)
    except subprocess.TimeoutExpired:
        return {"bench": bench, **params, "error": f"timed out after {timeout_s} s"}
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        return {"bench": bench, **params, "error": f"exit {proc.returncode}: {tail}"}
    return json.loads(lines[-1])


def attach_peaks(records: Sequence[dict]) -> list[dict]:
    """Add to each inference/train record the conv3d peak of its precision: the mean of the ``peak`` records
    measured next to it (the last one before it and the first one after it, when present; else the best of
    all). Adds peak_gflops_per_s, fraction_of_peak (wall time), fraction_of_peak_cpu (per CPU second, far
    less sensitive to other processes on the cores); for inference also floor_s (network FLOPs / peak) and
    ratio_to_floor (seconds / floor_s)."""
    out = [dict(r) for r in records]
    ok = [i for i, r in enumerate(out) if r.get("bench") == "peak" and "error" not in r]
    for i, r in enumerate(out):
        if r.get("bench") not in ("inference", "train") or "error" in r:
            continue
        same = [j for j in ok if out[j]["precision"] == r.get("precision")]
        if not same:
            continue
        before = [j for j in same if j < i][-1:]
        after = [j for j in same if j > i][:1]
        near = before + after or [max(same, key=lambda j: out[j]["gflops_per_s"])]
        peak = sum(out[j]["gflops_per_s"] for j in near) / len(near)
        r["peak_gflops_per_s"] = peak
        r["fraction_of_peak"] = r["gflops_per_s"] / peak
        cpu_peaks = [out[j]["gflops_per_cpu_s"] for j in near if "gflops_per_cpu_s" in out[j]]
        if cpu_peaks and "gflops_per_cpu_s" in r:
            r["fraction_of_peak_cpu"] = r["gflops_per_cpu_s"] / (sum(cpu_peaks) / len(cpu_peaks))
        if r["bench"] == "inference":
            r["floor_s"] = r["tflop"] * 1e3 / peak
            r["ratio_to_floor"] = r["seconds"] / r["floor_s"]
    return out


_COLUMNS = {
    "peak": ["precision", "shape", "seconds", "gflops_per_s", "gflops_per_cpu_s"],
    "inference": ["size", "interval", "precision", "seconds", "peak_memory_gb", "gflops_per_s", "fraction_of_peak",
                  "fraction_of_peak_cpu", "floor_s", "ratio_to_floor", "tile", "tiles", "phases_s"],
    "volume": ["size", "interval", "precision", "method", "seconds", "volume_gb", "gb_per_s", "peak_memory_gb"],
    "train": ["width", "batch", "patch", "seconds_per_step", "steps_per_s", "gflops_per_s", "fraction_of_peak",
              "fraction_of_peak_cpu", "peak_memory_gb"],
    "metrics": ["scenes", "methods", "size", "seconds", "scores_per_s", "mpixels_per_s", "peak_memory_gb"],
}


def _fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}"
    if isinstance(value, dict):
        return " ".join(f"{k.removesuffix('_s')} {_fmt(v)}" for k, v in value.items())
    if isinstance(value, list):
        return "x".join(str(v) for v in value)
    return "" if value is None else str(value)


def table(records: Sequence[dict]) -> str:
    """Markdown tables, one per bench, plus the machine line(s) and the load average of every row."""
    from tabulate import tabulate

    parts = []
    for bench in BENCHES:
        rows = [r for r in records if r.get("bench") == bench]
        if not rows:
            continue
        cols = _COLUMNS[bench]
        body = [[_fmt(r.get(c)) for c in cols] + [_fmt((r.get("machine") or {}).get("load_average")),
                                                  r.get("error", "")] for r in rows]
        parts.append(f"## {bench}\n\n" + tabulate(body, headers=[*cols, "load", "error"], tablefmt="github",
                                                  disable_numparse=True))
    machines = {json.dumps({k: v for k, v in (r.get("machine") or {}).items() if "load" not in k}, sort_keys=True)
                for r in records if r.get("machine")}
    for m in sorted(machines):
        d = json.loads(m)
        parts.append(f"machine: {d.get('cpu')}, {d.get('cores')} cores, {d.get('threads')} torch threads, "
                     f"torch {d.get('torch')} ({d.get('cpu_capability')}), gpu {d.get('gpu')}")
    return "\n\n".join(parts) + "\n"


def write_json(path: str | Path, records: Sequence[dict]) -> None:
    """The records as a JSON list, written atomically."""
    from lfbench.utils.atomic import write_text

    write_text(Path(path), json.dumps(list(records), indent=2, sort_keys=True) + "\n")


def _main(argv: Sequence[str]) -> int:
    """Child entry: one JSON argument {"bench", "params"}; prints the record as one JSON line."""
    spec = json.loads(argv[0])
    print(json.dumps(run_case(spec["bench"], spec.get("params", {}))), flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover - exercised through run_isolated
    sys.exit(_main(sys.argv[1:]))
