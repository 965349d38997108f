"""Speed and memory benchmarks (``lfbench bench``; not part of the tests).

Every case runs in a fresh Python subprocess (``python -m lfbench.runs.bench CASE_JSON``) so that its peak
memory is the peak resident set size (``ru_maxrss``) of a process that did only that case; the record
also gives the RSS just before the measured work (interpreter, torch, weights), so the growth is the
difference. Each record carries the machine it ran on (CPU model, cores, torch threads, torch version,
load average before and after). On a CUDA ``device`` the clocks are read after ``torch.cuda.synchronize``
and ``peak_memory_gb`` is the GPU's ``torch.cuda.max_memory_allocated`` over the case (``memory`` says
which: ``rss`` or ``cuda_max_allocated``; ``peak_rss_gb`` keeps the process's RSS), with IEEE fp32 (TF32
off). A case its device cannot run (bf16 on a CPU without bf16 instructions) is a record with ``skipped``
(the reason) instead of numbers, and no process is started for it.

Benches (each returns one record, a dict). lfbench's own time the network of any registered trainable
(``model``, default ``subfocal``; lfbench.method.trainable) through its seam:

- ``inference``: one H x W scene through ``Trainable.infer`` (random weights unless a checkpoint is given;
  SubFocal: the paper network, width 150, tiles from ``max_memory_gb``): seconds, peak memory, achieved
  GFLOP/s when the trainable counts its FLOPs (halos not counted), the phases it reports;
- ``train``: optimizer steps per second (Adam + L1 on random patches, training mode, channels-last), in the
  training variant the network's own options select (``Trainable.train_bench_options``; SubFocal: its fast
  training path or the ``reference`` one, the before/after of the speed-up);
- ``metrics``: the metric engine (``lfbench.scoring.rules.score_scene``, general metrics) over synthetic scenes
  x methods written in the HCI layout.

A trainable contributes its own benches (``Trainable.benches``); SubFocal's (lfbench_methods.subfocal.bench):

- ``peak``: a 150 -> 150 3x3x3 channels-last conv3d of the paper's shape through the op SubFocal's fast path
  uses, fp32 or bf16: the GFLOP/s the hardware reaches here, against which the network is judged;
- ``volume``: the bilinear cost volume alone (GB/s of volume written), fast gather or the reference
  grid_sample path.

:func:`attach_peaks` puts the peak measured next to each inference record beside it (fraction of peak by
wall time and per CPU second, the floor = network FLOPs / peak, and seconds / floor), and the floors of both
precisions side by side (``ratio_to_fp32_floor``, ``ratio_to_bf16_floor``: how far an fp32 or a bf16 run
is from what the same FLOPs take at the fp32 or the bf16 conv3d peak measured in the same run). On a shared
machine the wall-time numbers swing with the other processes' load; the CPU-time fraction much less.
"""

from __future__ import annotations

import contextlib
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
from typing import Any

from lfbench.method.trainable import DEFAULT_TRAINABLE, bench_options
from lfbench.utils.errors import LFBenchError, SpecError
from lfbench.utils.jsonfile import json_text
from lfbench.utils.markdown import markdown_cell
from lfbench.utils.subprocesses import safe_path_env

PRECISIONS = ("fp32", "bf16")
BENCHES = ("peak", "inference", "volume", "train", "metrics")  # the order of the tables


# --------------------------------------------------------------------------- machine and memory

def cpu_model() -> str:
    """The CPU's model name (from /proc/cpuinfo on Linux), else platform.processor()."""
    from lfbench.utils.hardware import cpuinfo_field

    model = cpuinfo_field("model name")
    return model if model is not None else platform.processor() or platform.machine()


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


def set_threads(threads: int) -> int:
    import torch

    n = threads if threads > 0 else (os.cpu_count() or 1)
    torch.set_num_threads(n)
    return n


def cpu_seconds() -> float:
    """CPU seconds (user + system) this process has used."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def sync(device) -> None:
    """Wait for the device's queued work (CUDA kernels run asynchronously); nothing on the CPU."""
    import torch

    if device is not None and torch.device(device).type == "cuda":
        torch.cuda.synchronize(device)


STATISTICS = ("best", "mean")  # what a bench's seconds are of its repeated runs


def timed(fn: Callable[[], object], repeat: int, device=None, statistic: str = "best") -> tuple[float, float]:
    """(wall time, mean CPU time) of ``repeat`` calls, s: the wall time is the best call's (``statistic``
    "best") or the mean of all (``"mean"``, as papers report a runtime, e.g. SubFocal's Table III: mean of 50
    runs; one untimed warm-up call first, so that one-off set-up is not in the mean). On CUDA each call is
    timed from a synchronized start to its synchronized end. CPU time counts the work itself and is much less
    inflated than wall time when other processes compete for the cores."""
    if statistic not in STATISTICS:
        raise ValueError(f"statistic must be one of {', '.join(STATISTICS)}, got {statistic!r}")
    n = max(1, repeat)
    if statistic == "mean":
        fn()
        sync(device)
    walls = []
    cpu0 = cpu_seconds()
    for _ in range(n):
        sync(device)
        t = time.perf_counter()
        fn()
        sync(device)
        walls.append(time.perf_counter() - t)
    wall = min(walls) if statistic == "best" else math.fsum(walls) / n
    return wall, (cpu_seconds() - cpu0) / n


def case_device(device: str = "cpu"):
    """The torch.device of a case (``auto`` resolved); on CUDA: made current, IEEE fp32 numerics, peak
    memory statistics reset."""
    import torch

    from lfbench.utils.hardware import resolve_device, set_fp32_numerics

    dev = resolve_device(device)
    if dev.type == "cuda":
        set_fp32_numerics(tf32=False)
        torch.cuda.set_device(dev)
        torch.cuda.reset_peak_memory_stats(dev)
    return dev


def memory_now_gb(device) -> float:
    """Memory in use now, GB: the process's RSS on the CPU, torch's allocated memory on CUDA."""
    import torch

    return torch.cuda.memory_allocated(device) / 1e9 if device.type == "cuda" else current_rss_gb()


def memory_fields(device, baseline_gb: float) -> dict:
    """A record's memory: peak_memory_gb (peak RSS on the CPU; torch.cuda.max_memory_allocated on CUDA since
    :func:`case_device`), baseline_memory_gb (before the measured work), memory (which), peak_rss_gb."""
    import torch

    if device.type == "cuda":
        return {"peak_memory_gb": torch.cuda.max_memory_allocated(device) / 1e9, "baseline_memory_gb": baseline_gb,
                "memory": "cuda_max_allocated", "peak_rss_gb": peak_rss_gb(), "device": str(device)}
    return {"peak_memory_gb": peak_rss_gb(), "baseline_memory_gb": baseline_gb, "memory": "rss",
            "peak_rss_gb": peak_rss_gb(), "device": str(device)}


def skip_reason(bench: str, params: dict) -> str | None:
    """Why a case cannot run on this machine (bf16 convolutions its device lacks), else None."""
    from lfbench.utils.hardware import bf16_unavailable, resolve_device

    if bench in ("peak", "inference", "train") and params.get("precision") == "bf16":
        unavailable = bf16_unavailable(resolve_device(params.get("device", "cpu")))
        if unavailable is not None:
            return f"{unavailable}; fp32 runs"
    return None


def torch_dtype(precision: str):
    import torch

    if precision not in PRECISIONS:
        raise SpecError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    return torch.float32 if precision == "fp32" else torch.bfloat16


# --------------------------------------------------------------------------- the benches

def _network(model: str, params: dict[str, Any], weights: str | None, seed: int):
    """(trainable, network in eval mode): built from ``params`` with seed ``seed`` (random weights), or
    loaded from ``weights`` with ``params`` written over the stored config."""
    import torch

    from lfbench.method.trainable import construct, get_trainable

    trainable = get_trainable(model)
    unknown = sorted(set(params) - set(trainable.parameters()))
    if unknown:
        raise SpecError(f"network {model!r} has no parameter {', '.join(unknown)} "
                        f"(parameters: {', '.join(trainable.parameters())})")
    if weights:
        return trainable, trainable.load(Path(weights), **params).eval()
    torch.manual_seed(seed)
    return trainable, construct(trainable.build, params).eval()


def _described(record: dict, net, params: dict[str, Any]) -> dict:
    """The record plus the network's config (its parameters as built) and its disparity count, if any."""
    config = getattr(net, "config", None)
    config = dict(config()) if callable(config) else dict(params)
    for key, value in config.items():
        record.setdefault(key, value)
    disparities = getattr(net, "disparities", None)
    if disparities is not None:
        record["disparities"] = int(disparities.numel())
    return record


def bench_inference(size: int = 512, precision: str = "fp32", *, model: str = DEFAULT_TRAINABLE,
                    weights: str | None = None, max_memory_gb: float | None = 4.0, tile: int = 0, threads: int = 0,
                    repeat: int = 1, seed: int = 0, device: str = "cpu", statistic: str = "best",
                    **params: Any) -> dict:
    """One size x size light field (random views, made on the CPU: the copy to ``device`` is timed) through the
    network's ``Trainable.infer`` on ``device``; best of ``repeat`` runs, or their mean (``statistic="mean"``,
    after one warm-up run: how a paper's runtime is usually measured, e.g. 9x9x256x256, mean of 50).
    ``params``: the network's parameters (e.g. SubFocal's interval, width; default: its defaults, random
    weights unless ``weights`` names a checkpoint). max_memory_gb None: the device's budget (4 GB on the CPU,
    the free memory of a GPU)."""
    import torch

    from lfbench.method.trainable import contract_problem

    set_threads(threads)
    torch_dtype(precision)
    dev = case_device(device)
    trainable, net = _network(model, params, weights, seed)
    net = net.to(dev)
    angular = int(getattr(net, "angular", 9))
    views = torch.rand((1, angular * angular, size, size), generator=torch.Generator().manual_seed(seed))
    baseline = memory_now_gb(dev)
    phases: dict = {}
    outputs: list = []

    def run() -> None:
        outputs[:] = [trainable.infer(net, views, precision=precision, max_memory_gb=max_memory_gb, tile=tile,
                                      timings=phases)]

    seconds, cpu = timed(run, repeat, dev, statistic)
    problem = contract_problem(outputs[0], (size, size), getattr(net, "disparities", None))  # the one check
    if problem:
        raise SpecError(f"network {model!r} breaks the network contract on a {size}x{size} light field: {problem}")
    record = {"bench": "inference", "model": model, "size": size, **params, "network_params": list(params),
              "precision": precision, "seconds": seconds, **memory_fields(dev, baseline),
              "cpu_seconds": cpu, "weights": weights or "random", "max_memory_gb": max_memory_gb,
              "repeat": max(1, repeat), "statistic": statistic}
    flops = trainable.flop_count(net, size, size)
    if flops:
        record.update({"gflops_per_s": flops["total"] / seconds / 1e9, "gflops_per_cpu_s": flops["total"] / cpu / 1e9,
                       "tflop": flops["total"] / 1e12,
                       **{f"tflop_{k}": v / 1e12 for k, v in flops.items() if k != "total"}})
    if "tile" in phases:
        record["tile"] = list(phases["tile"])
    if "tiles" in phases:
        record["tiles"] = phases["tiles"]
    record["phases_s"] = {k: round(v, 3) for k, v in phases.items() if k.endswith("_s")}
    if isinstance(phases.get("cpu"), dict):  # the same phases in CPU seconds, when the network reports them
        record["phases_cpu_s"] = {k: round(v, 3) for k, v in phases["cpu"].items() if k.endswith("_s")}
    return _described(record, net, params)


def bench_train(batch: int = 2, patch: int = 32, steps: int = 2, channels_last: bool = True, threads: int = 0,
                seed: int = 0, *, model: str = DEFAULT_TRAINABLE, device: str = "cpu", precision: str = "fp32",
                warmup: int = 1, **params: Any) -> dict:
    """Training steps per second: the network (``params`` over its defaults) in training mode, Adam (lr 1e-3,
    eps 1e-7) on an L1 loss of its disparity for random (batch, N, patch, patch) views against random
    disparities in [-4, 4); ``warmup`` untimed steps (at least 1), then ``steps``. ``params`` may also hold
    the options the network adds to this bench (``Trainable.train_bench_options``, e.g. SubFocal's ``path``:
    ``fast`` or ``reference``, and ``weight_grad``): the training variant ``Trainable.prepare_training``
    switches to; a variant that is not what ``lfbench train`` runs keeps glibc's default heap (the "before").
    ``precision`` bf16: the forward pass under bf16 autocast, as ``[training] precision = "bf16"`` trains."""
    import torch

    from lfbench.method.trainable import crop_margin, get_trainable, to_channels_last
    from lfbench.utils.malloc import retain_freed_memory

    set_threads(threads)
    dev = case_device(device)
    options = {o.name: o for o in bench_options(get_trainable(model).train_bench_options)}
    variant = {k: params.pop(k) for k in list(params) if k in options}
    for key, value in variant.items():  # as the flag checks it (BenchOption is a declared Flag)
        if problem := options[key].problem(value):
            raise SpecError(f"network {model!r}: {key}: {problem}")
    trainable, net = _network(model, params, None, seed)
    try:
        as_trained = trainable.prepare_training(net, **variant)
    except (TypeError, ValueError) as exc:
        raise SpecError(f"network {model!r}: {exc}") from None
    if as_trained:
        retain_freed_memory()  # as lfbench train does
    net = net.to(dev).train()
    if channels_last:
        to_channels_last(net)
    opt = torch.optim.Adam(net.parameters(), lr=1e-3, eps=1e-7)
    g = torch.Generator().manual_seed(seed)
    angular = int(getattr(net, "angular", 9))
    views = torch.rand((batch, angular * angular, patch, patch), generator=g).to(dev)
    target = (torch.rand((batch, patch, patch), generator=g) * 8 - 4).to(dev)

    dtype = torch_dtype(precision)
    autocast = (lambda: torch.autocast(dev.type, dtype=dtype)) if dtype != torch.float32 else contextlib.nullcontext
    margin = trainable.output_margin(net)  # the border the network fills: lfbench train's loss leaves it out
    if patch <= 2 * margin:
        raise SpecError(f"network {model!r}: --patch {patch} leaves nothing to train on (its output loses {margin} px "
                        f"per side); use --patch {2 * margin + 1} or more")

    def step() -> None:
        opt.zero_grad(set_to_none=True)
        with autocast():
            disp, _ = trainable.training_forward(net, views, target)
        inner, _, label = crop_margin(disp, None, target, margin)
        torch.nn.functional.l1_loss(inner.float(), label).backward()
        opt.step()

    baseline = memory_now_gb(dev)
    for _ in range(max(1, warmup)):
        step()
    sync(dev)
    t, cpu0 = time.perf_counter(), cpu_seconds()
    for _ in range(max(1, steps)):
        step()
    sync(dev)
    seconds = (time.perf_counter() - t) / max(1, steps)
    cpu = (cpu_seconds() - cpu0) / max(1, steps)
    record = {"bench": "train", "model": model, **params, "network_params": list(params), "batch": batch,
              "patch": patch, **variant, "variant": list(variant), "channels_last": channels_last,
              "steps": max(1, steps), "warmup": max(1, warmup), "seconds": seconds, "seconds_per_step": seconds,
              "steps_per_s": 1.0 / seconds, "cpu_seconds": cpu, **memory_fields(dev, baseline),
              "precision": precision}
    flops = trainable.flop_count(net, patch, patch)
    if flops:
        forward = flops["total"] * batch
        record.update({"gflops_per_s": 3 * forward / seconds / 1e9, "gflops_per_cpu_s": 3 * forward / cpu / 1e9})
    return _described(record, net, params)


def _write_synthetic_scene(folder: Path, size: int, seed: int):
    """A scene folder in the generator's layout (lfbench.data.synth.SYNTH_LAYOUT, written by its adapter) with
    its camera and a smooth random ground-truth disparity (size x size px) and no views, returned."""
    import types

    import numpy as np

    from lfbench.data.camera import Camera
    from lfbench.data.synth import write_scene

    params = Camera(focal_length_mm=100.0, image_resolution_x_px=size, image_resolution_y_px=size,
                    sensor_size_mm=35.0, num_cams_x=9, num_cams_y=9, baseline_mm=90.0,
                    focus_distance_m=8.0, disp_min=-2.0, disp_max=2.0, name=folder.name,
                    category="synthetic")
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] / size
    gt = (1.5 * np.sin(2 * np.pi * (x * rng.uniform(0.5, 2) + rng.uniform())) * np.cos(2 * np.pi * y)).astype(
        np.float32)
    write_scene(types.SimpleNamespace(params=params, views=None, disparity=gt, depth=None, masks={}), folder)
    return gt


def bench_metrics(scenes: int = 12, methods: int = 5, size: int = 512, repeat: int = 1) -> dict:
    """The metric engine: ``score_scene`` with the general metrics (BadPix 0.01/0.03/0.07, MSE x100, Q25)
    for ``methods`` predictions (ground truth + noise of growing size) on each of ``scenes`` synthetic
    size x size scenes (HCI layout in a temporary folder; reading the ground truth is part of the time)."""
    import numpy as np

    from lfbench.data.dataset import DATASETS
    from lfbench.data.synth import SYNTH_LAYOUT
    from lfbench.scoring.metrics import GENERAL_METRICS
    from lfbench.scoring.score import score_scene

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
            opened = {scene.name: scene for scene in DATASETS.get(SYNTH_LAYOUT).open(Path(tmp))}
            for folder, per_scene in zip(folders, preds, strict=True):
                scene = opened[folder.name]
                for pred in per_scene:
                    score_scene(scene, pred, GENERAL_METRICS)

        seconds, cpu = timed(run, repeat)
    pairs = scenes * methods
    return {"bench": "metrics", "scenes": scenes, "methods": methods, "size": size, "metrics": len(GENERAL_METRICS),
            "seconds": seconds, "cpu_seconds": cpu, "scores_per_s": pairs / seconds,
            "mpixels_per_s": pairs * size * size / seconds / 1e6,
            "peak_memory_gb": peak_rss_gb(), "baseline_memory_gb": baseline}


_FUNCTIONS = {"inference": bench_inference, "train": bench_train, "metrics": bench_metrics}


# --------------------------------------------------------------------------- running cases

def bench_function(bench: str, model: str = DEFAULT_TRAINABLE) -> Callable[..., dict]:
    """The function of a bench: lfbench's own (inference, train, metrics) or one the network ``model``
    contributes (``Trainable.benches``, e.g. SubFocal's peak and volume)."""
    if bench in _FUNCTIONS:
        return _FUNCTIONS[bench]
    from lfbench.method.trainable import get_trainable

    extra = get_trainable(model).benches
    if bench not in extra:
        raise SpecError(f"unknown bench {bench!r} (one of {', '.join([*_FUNCTIONS, *extra])}; "
                        f"network {model!r})")
    return extra[bench]


def run_case(bench: str, params: dict) -> dict:
    """Run one case in this process: the bench's record plus ``machine`` (load average before and after).
    A bench contributed by a network takes the network's name as ``model`` in ``params``."""
    params = dict(params)
    if bench in _FUNCTIONS:
        fn = _FUNCTIONS[bench]
    else:
        fn = bench_function(bench, params.pop("model", DEFAULT_TRAINABLE))
    load_before = _load()
    record = fn(**params)
    machine = machine_info()
    machine["load_average_before"] = load_before
    record["machine"] = machine
    return record


def run_isolated(bench: str, params: dict, timeout_s: float | None = None) -> dict:
    """Run one case in a fresh Python process (its own peak RSS); a failed case gives a record with ``error``,
    one its device cannot run a record with ``skipped`` (decided here, no process started)."""
    reason = skip_reason(bench, params)
    if reason is not None:
        return {"bench": bench, **params, "skipped": reason}
    cmd = [sys.executable, "-m", "lfbench.runs.bench", json.dumps({"bench": bench, "params": params})]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, check=False,
                              env=safe_path_env())  # lfbench and plugins as installed, not from the current folder
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
    ratio_to_floor (seconds / floor_s) of its own precision, and for every precision P whose peak was
    measured in the run, P_floor_s and ratio_to_P_floor (fp32 and bf16 side by side, whatever precision
    the case ran in; ratio_to_P_floor_cpu: the same by CPU seconds, inference and peak alike, which other
    processes on the cores inflate far less); where the peak of P was skipped (bf16 on a CPU without it),
    P_floor_skipped says why."""
    out = [dict(r) for r in records]
    ok = [i for i, r in enumerate(out) if r.get("bench") == "peak" and "error" not in r and "skipped" not in r]
    skipped = {r.get("precision"): r["skipped"] for r in out if r.get("bench") == "peak" and "skipped" in r}

    def near(i: int, precision: str, key: str = "gflops_per_s") -> float | None:
        """Mean ``key`` of the peaks of ``precision`` next to record i (else the best of all of them)."""
        same = [j for j in ok if out[j].get("precision") == precision and key in out[j]]
        if not same:
            return None
        before = [j for j in same if j < i][-1:]
        after = [j for j in same if j > i][:1]
        chosen = before + after or [max(same, key=lambda j: out[j][key])]
        return sum(out[j][key] for j in chosen) / len(chosen)

    for i, r in enumerate(out):
        if r.get("bench") not in ("inference", "train") or "error" in r or "skipped" in r:
            continue
        if r["bench"] == "inference" and "tflop" in r:
            for precision in PRECISIONS:
                other = near(i, precision)
                if other is not None:
                    r[f"{precision}_floor_s"] = r["tflop"] * 1e3 / other
                    r[f"ratio_to_{precision}_floor"] = r["seconds"] / r[f"{precision}_floor_s"]
                    other_cpu = near(i, precision, "gflops_per_cpu_s")
                    if other_cpu is not None and "cpu_seconds" in r:  # the same in CPU seconds (less load-bound)
                        r[f"ratio_to_{precision}_floor_cpu"] = r["cpu_seconds"] * other_cpu / (r["tflop"] * 1e3)
                elif precision in skipped:
                    r[f"{precision}_floor_skipped"] = skipped[precision]
        peak = near(i, r.get("precision"))
        if peak is None or "gflops_per_s" not in r:  # no peak of its precision, or a network without FLOPs
            continue
        r["peak_gflops_per_s"] = peak
        r["fraction_of_peak"] = r["gflops_per_s"] / peak
        cpu_peak = near(i, r.get("precision"), "gflops_per_cpu_s")
        if cpu_peak is not None and "gflops_per_cpu_s" in r:
            r["fraction_of_peak_cpu"] = r["gflops_per_cpu_s"] / cpu_peak
        if r["bench"] == "inference":
            r["floor_s"] = r["tflop"] * 1e3 / peak
            r["ratio_to_floor"] = r["seconds"] / r["floor_s"]
    return out


def attach_ratios(records: Sequence[dict], reference: str) -> list[dict]:
    """Add to each inference record of a run that timed several networks ``ratio_to_reference``: its seconds over
    those of the record of network ``reference`` (its ``model_spec``) at the same size, precision and device,
    and ``reference`` (as papers compare runtimes: SubFocal's Table III, LFattNet 0.743 s / SubFocal 1.839 s =
    0.40). A record without such a reference (it failed, or was skipped) gets none."""
    out = [dict(r) for r in records]

    def timed(r: dict) -> bool:
        return r.get("bench") == "inference" and "error" not in r and "skipped" not in r and r.get("seconds")

    def key(r: dict) -> tuple:
        return r.get("size"), r.get("precision"), r.get("device")

    refs: dict[tuple, dict] = {}
    for r in out:
        if timed(r) and r.get("model_spec") == reference:
            refs.setdefault(key(r), r)
    for r in out:
        ref = refs.get(key(r))
        if timed(r) and ref is not None:
            r["reference"] = reference
            r["ratio_to_reference"] = r["seconds"] / ref["seconds"]
    return out


_COLUMNS = {
    "peak": ["precision", "shape", "seconds", "gflops_per_s", "gflops_per_cpu_s"],
    "inference": ["model_spec", "size", "<network>", "precision", "seconds", "ratio_to_reference", "peak_memory_gb",
                  "gflops_per_s", "fraction_of_peak",
                  "fraction_of_peak_cpu", "fp32_floor_s", "ratio_to_fp32_floor", "ratio_to_fp32_floor_cpu",
                  "bf16_floor_s", "ratio_to_bf16_floor", "ratio_to_bf16_floor_cpu", "tile", "tiles", "phases_s"],
    "volume": ["size", "interval", "precision", "method", "seconds", "volume_gb", "gb_per_s", "peak_memory_gb"],
    "train": ["<network>", "batch", "patch", "<variant>", "precision", "seconds_per_step", "steps_per_s",
              "cpu_seconds", "gflops_per_s", "fraction_of_peak", "fraction_of_peak_cpu", "peak_memory_gb"],
    "metrics": ["scenes", "methods", "size", "seconds", "scores_per_s", "mpixels_per_s", "peak_memory_gb"],
}


_ONLY_WHEN_SET = ("model_spec", "ratio_to_reference")  # columns of a run that timed several networks


def format_value(value: object) -> str:
    """A bench record's value as table text: 3 significant digits, phases as "name seconds", shapes as AxB."""
    if isinstance(value, float):
        return f"{value:.3g}" if abs(value) < 1000 else f"{value:.0f}"
    if isinstance(value, dict):
        return " ".join(f"{k.removesuffix('_s')} {format_value(v)}" for k, v in value.items())
    if isinstance(value, list):
        return "x".join(str(v) for v in value)
    return "" if value is None else str(value)


def _cell(record: dict, column: str) -> str:
    """A table cell: the formatted value; ``skipped`` for the ratio to a floor whose peak this machine could not
    measure (the reason is the peak's own row)."""
    if column.startswith("ratio_to_") and column.endswith(("_floor", "_floor_cpu")) and column not in record:
        precision = column.removeprefix("ratio_to_").removesuffix("_cpu").removesuffix("_floor")
        if f"{precision}_floor_skipped" in record:
            return "skipped"
    return format_value(record.get(column))


def _columns(bench: str, rows: Sequence[dict]) -> list[str]:
    """A bench's table columns: ``<network>`` stands for the network parameters the cases set (e.g. SubFocal's
    interval, a plugin's channels), ``<variant>`` for the training options they chose (SubFocal's path)."""
    cols: list[str] = []
    for col in _COLUMNS[bench]:
        if col in _ONLY_WHEN_SET and not any(col in r for r in rows):
            continue  # a run of one network: no network and ratio columns
        if col in ("<network>", "<variant>"):
            key = "network_params" if col == "<network>" else "variant"
            cols += [k for k in dict.fromkeys(k for r in rows for k in r.get(key, [])) if k not in cols]
        else:
            cols.append(col)
    return cols


def table(records: Sequence[dict]) -> str:
    """Markdown tables, one per bench, plus the machine line(s) and the load average of every row."""
    from tabulate import tabulate

    parts = []
    for bench in BENCHES:
        rows = [r for r in records if r.get("bench") == bench]
        if not rows:
            continue
        cols = _columns(bench, rows)
        body = [[_cell(r, c) for c in cols] + [format_value((r.get("machine") or {}).get("load_average")),
                                                  r.get("error", "") or (f"skipped: {r['skipped']}" if "skipped" in r
                                                                         else "")] for r in rows]
        models = ", ".join(dict.fromkeys(str(r["model"]) for r in rows if r.get("model")))
        parts.append(f"## {bench}{f' ({models})' if models and bench in ('inference', 'train') else ''}\n\n"
                     + tabulate([[markdown_cell(c) for c in row] for row in body],  # an error's line breaks, a "|"
                                headers=[*cols, "load", "error"], tablefmt="github", disable_numparse=True))
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

    write_text(Path(path), json_text(list(records), indent=2, sort_keys=True) + "\n")


def _main(argv: Sequence[str]) -> int:
    """Child entry: one JSON argument {"bench", "params"}; prints the record as one JSON line."""
    spec = json.loads(argv[0])
    try:
        record = run_case(spec["bench"], spec.get("params", {}))
    except LFBenchError as exc:  # one line (the case's error record), e.g. a plugin's flops() of the wrong kind
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code
    print(json.dumps(record), flush=True)
    return 0


if __name__ == "__main__":  # pragma: no cover - exercised through run_isolated
    sys.exit(_main(sys.argv[1:]))
