"""SubFocal inference on whole images or in exact tiles, in bounded memory, on the eval fast path.

Two parts of the network see the whole image: the SPP upsampling of the feature extractor and the
channel attention (a mean over the whole cost volume). Exact tiling therefore works in three steps:

1. features of the whole image, extracted a few views at a time and kept zero-padded channels-last
   (B, H + 2P, W + 2P, N, 4) (cheap: 4 ch/view);
2. the attention mean of the cost volume: for bilinear shifts computed analytically from the features
   (methods/subfocal/fast.py, no volume is built), otherwise accumulated over all tiles first;
3. per tile, the cost volume of the tile plus a halo (gathered from the whole-image feature map, so
   shifts reach across tile borders exactly as in one pass) and the 3D aggregation; only the tile's
   core is kept. The aggregation is eight 3x3x3 convolutions in a row, so a halo of >= 8 px makes the
   result identical to whole-image inference (up to float rounding).

``tile=0`` picks the tiling from a memory budget (``max_memory_gb``): the whole image in one piece when
it fits, else the tiles (strips or a grid) that compute the fewest voxels; in bf16 on a CPU with AMX, tiles
at most :data:`AMX_MAX_CONV_WIDTH` px wide (oneDNN's fast AMX kernels stop at 256 px). The output uncertainty is the
standard deviation of the predicted distribution in px: sqrt(sum_k p_k (d_k - d_hat)^2).
"""

from __future__ import annotations

import ctypes
import math
import time
from collections.abc import Iterator
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from lfbench_methods.subfocal.network import FEATURES, Aggregation, SubFocalNet
from tqdm import tqdm

from lfbench.data.shift import shift_views
from lfbench.utils.hardware import require_bf16

EXACT_HALO = Aggregation.RECEPTIVE_RADIUS  # px: eight 3x3x3 convolutions in a row
PRECISIONS = ("fp32", "bf16")
DTYPES = {"fp32": torch.float32, "bf16": torch.bfloat16}
_FEATURE_BYTES_PER_PX_VIEW = 4 * 150  # fast extractor working set per view pixel (fp32; measured 480-580 B)
_RUNTIME_BYTES = 0.35e9  # the interpreter, torch, oneDNN and the weights (measured ~0.26 GB)
_CUDA_RUNTIME_BYTES = 0.5e9  # on a GPU: cuDNN workspaces and the caching allocator's slack beside planned tensors
CPU_BUDGET_GB = 4.0  # the default budget on the CPU (on CUDA: the GPU's available memory)
_SLAB = 2  # disparities per slab of the first 3D convolution
# oneDNN runs a bf16 convolution with AMX through its fast micro-kernel path (brgemm "uker", with spatial
# blocking across rows) only when the output is less than 256 px wide (a heuristic in
# src/cpu/x64/jit_brgemm_conv_utils.cpp); wider, it takes a slower AMX path. On an AMX Xeon the paper network
# at 256x256 in bf16 (one 256 px wide tile) ran 4.9x off the floor of a 64 px wide conv3d. So on a CPU with
# AMX, bf16 tiles are at most this wide, halo included (exact tiling; at 256x256: two strips, 6 % more voxels).
AMX_MAX_CONV_WIDTH = 255


@dataclass
class InferenceOutput:
    """disparity (B, H, W) px per view step; probability (B, D, H, W) softmax over ``disparities`` (D,);
    uncertainty (B, H, W): standard deviation of the distribution in px. All float32 on the CPU."""

    disparity: torch.Tensor
    probability: torch.Tensor
    uncertainty: torch.Tensor
    disparities: torch.Tensor


def distribution_std(probability: torch.Tensor, disparities: torch.Tensor, mean: torch.Tensor) -> torch.Tensor:
    """(B, D, H, W), (D,), (B, H, W) -> (B, H, W): sqrt(sum_k p_k (d_k - mean)^2) in px."""
    dev = disparities[None, :, None, None] - mean[:, None]
    return (probability * dev * dev).sum(dim=1).clamp_min(0).sqrt()


def estimate_tile_bytes(net: SubFocalNet, rows: int, cols: int, precision: str = "fp32", device=None) -> int:
    """Peak working set of one tile's 3D aggregation that scales with its voxels (rows x cols incl. halo,
    times D disparities), bytes: the larger of (a) the first convolution's phase: its output, a slab of
    the volume (``_SLAB`` + 2 planes of 4N channels), the slab's output and gather indices, and (b) two live
    ``width``-channel activations (three without oneDNN's in-place add), or the last activation and its
    27 float32 taps. The interpolated maps the volume is gathered from are :func:`gather_bytes`. ``device``
    (default: the CPU) decides whether oneDNN's in-place add runs."""
    from lfbench_methods.subfocal.fast import LAST_BLOCK, fused_ops_work

    d = net.disparities.numel()
    n = net.angular ** 2
    channels, width = FEATURES * n, net.config()["width"]
    item = 2 if precision == "bf16" else 4
    plane = rows * cols
    act = width * item
    first = d * plane * act + (_SLAB + 2) * plane * channels * item + _SLAB * plane * act + (_SLAB + 1) * plane * n * 4
    live = 2 if _is_cpu(device) and fused_ops_work() else 3
    rest = d * plane * max(live * act, act + 27 * 4) + LAST_BLOCK * width * 4
    return int(1.1 * max(first, rest))


def gather_bytes(net: SubFocalNet, rows: int, cols: int, precision: str = "fp32", plan=None) -> int:
    """Bytes a tile's volume source holds during the first 3D convolution: the interpolated feature maps
    of the bilinear gather (one per view and distinct sub-pixel fraction, over the tile plus the shift
    range) and its index base; other interpolations hold the tile's whole fp32 volume instead."""
    d = net.disparities.numel()
    n = net.angular ** 2
    item = 2 if precision == "bf16" else 4
    if net.interpolation != "bilinear":
        return d * rows * cols * FEATURES * n * 4
    plan = net._shift_plan() if plan is None else plan
    return _map_area(plan, rows, cols) * n * FEATURES * plan.slots * item + rows * cols * n * 4


def _map_area(plan, rows: int, cols: int) -> int:
    """Pixels of one interpolated map of a rows x cols tile (plus the range of integer shifts)."""
    return (rows + int(plan.oy.max() - plan.oy.min()) + 1) * (cols + int(plan.ox.max() - plan.ox.min()) + 1)


def _is_cpu(device) -> bool:
    return device is None or torch.device(device).type == "cpu"


def _runtime_bytes(device) -> float:
    """Bytes of the budget the planned tensors cannot use: on the CPU the process itself (interpreter, torch,
    weights); on CUDA cuDNN workspaces and allocator slack (the weights are already allocated there)."""
    return _RUNTIME_BYTES if _is_cpu(device) else _CUDA_RUNTIME_BYTES


def memory_budget_gb(device, max_memory_gb: float | None = None) -> float:
    """The inference budget in GB. CPU: ``max_memory_gb`` (default 4). CUDA: what this process can still
    allocate on the device (``torch.cuda.mem_get_info`` free memory plus torch's cached, unused blocks),
    capped by ``max_memory_gb`` when given. Call it with the views and weights already on the device: those
    live tensors are then not counted again."""
    if _is_cpu(device):
        return CPU_BUDGET_GB if max_memory_gb is None else float(max_memory_gb)
    device = torch.device(device)
    free, _ = torch.cuda.mem_get_info(device)
    cached = torch.cuda.memory_reserved(device) - torch.cuda.memory_allocated(device)
    available = (free + max(cached, 0)) / 1e9
    return available if max_memory_gb is None else min(float(max_memory_gb), available)


def _tile_need(net: SubFocalNet, rows: int, cols: int, precision: str, plan=None, device=None) -> int:
    """Peak bytes of one tile: the aggregation beside what its volume source holds, or the source while it
    builds its maps (two float32 map-sized temporaries)."""
    held = gather_bytes(net, rows, cols, precision, plan)
    build = 2 * _map_area(plan, rows, cols) * net.angular ** 2 * FEATURES * 4 if plan is not None else 0
    return max(estimate_tile_bytes(net, rows, cols, precision, device) + held, held + build)


def _fixed_bytes(net: SubFocalNet, height: int, width: int) -> int:
    """Whole-image buffers: zero-padded features (N x 4 ch, fp32), cost, probability and the outputs."""
    d = net.disparities.numel()
    pad = net._shift_plan().pad if net.interpolation == "bilinear" else 0
    feats = (height + 2 * pad) * (width + 2 * pad) * FEATURES * net.angular ** 2 * 4
    return feats + 4 * height * width * (5 * d + 4)


def _budget(net: SubFocalNet, height: int, width: int, max_memory_gb: float, device=None) -> float:
    return max_memory_gb * 1e9 - _fixed_bytes(net, height, width) - _runtime_bytes(device)


def _spans(size: int, tile: int, halo: int) -> list[tuple[int, int, int, int]]:
    """(start, stop, region start, region stop) of the tiles along one axis."""
    return [(a, min(a + tile, size), max(a - halo, 0), min(a + tile + halo, size)) for a in range(0, size, tile)]


def cpu_has_amx_bf16() -> bool:
    """True when this CPU has AMX for bf16 (oneDNN then runs bf16 convolutions on its tiles)."""
    try:
        return bool(torch.cpu.get_capabilities().get("amx_bf16", False))
    except (AttributeError, RuntimeError):  # an older torch
        from lfbench.utils.hardware import cpu_flags

        return "amx_bf16" in cpu_flags()


def conv_width_limit(precision: str = "fp32", device=None) -> int | None:
    """The widest tile (px, halo included) the 3D aggregation should run on: :data:`AMX_MAX_CONV_WIDTH` for
    bf16 on a CPU with AMX, else None (no limit)."""
    if precision == "bf16" and _is_cpu(device) and cpu_has_amx_bf16():
        return AMX_MAX_CONV_WIDTH
    return None


def _tile_fits(net: SubFocalNet, rows: int, cols: int, budget: float, precision: str, plan=None,
               device=None) -> bool:
    return _tile_need(net, rows, cols, precision, plan, device) <= budget


def plan_tile(net: SubFocalNet, height: int, width: int, halo: int = EXACT_HALO, max_memory_gb: float = 4.0,
              precision: str = "fp32") -> int:
    """The square core tile size (px) for ``max_memory_gb``: the whole image when it fits, else the fewest tiles
    per side k whose largest tile (ceil(size / k) + 2 halo) fits beside the whole-image buffers."""
    budget = _budget(net, height, width, max_memory_gb)
    plan = net._shift_plan() if net.interpolation == "bilinear" else None
    for k in range(1, max(height, width) + 1):
        th, tw = math.ceil(height / k), math.ceil(width / k)
        rows, cols = min(th + 2 * halo, height) if k > 1 else height, min(tw + 2 * halo, width) if k > 1 else width
        if _tile_fits(net, rows, cols, budget, precision, plan) or max(th, tw) <= 8:
            return max(th, tw)
    return 8


def plan_tiles(net: SubFocalNet, height: int, width: int, halo: int = EXACT_HALO, max_memory_gb: float = 4.0,
               precision: str = "fp32", device=None) -> tuple[int, int]:
    """Core tile (rows, cols) for ``max_memory_gb`` that computes the fewest voxels (tiles plus halos): the
    whole image when it fits, else e.g. full-width strips or a grid; ties go to fewer tiles. Tiles of
    at least 8 px are used even when the budget is smaller than that. ``device`` (default CPU): where it runs
    (see :func:`memory_budget_gb` for the budget of a GPU). Tiles are at most :func:`conv_width_limit` px
    wide, halo included (bf16 on a CPU with AMX)."""
    budget = _budget(net, height, width, max_memory_gb, device)
    plan = net._shift_plan() if net.interpolation == "bilinear" else None
    max_cols = conv_width_limit(precision, device) or width
    best = None
    for ky in range(1, math.ceil(height / 8) + 1):
        th = math.ceil(height / ky)
        ys = _spans(height, th, halo)
        rows = max(r1 - r0 for _, _, r0, r1 in ys)
        for kx in range(1, math.ceil(width / 8) + 1):
            tw = math.ceil(width / kx)
            xs = _spans(width, tw, halo)
            cols = max(c1 - c0 for _, _, c0, c1 in xs)
            if cols > max_cols or not _tile_fits(net, rows, cols, budget, precision, plan, device):
                continue
            work = sum(r1 - r0 for *_, r0, r1 in ys) * sum(c1 - c0 for *_, c0, c1 in xs)
            key = (work, len(ys) * len(xs))
            if best is None or key < best[0]:
                best = (key, (th, tw))
            break  # more columns only add halo work
    if best is None:
        return min(8, height), min(8, width)
    return best[1]


def view_chunk(height: int, width: int, batch: int, max_memory_gb: float, fixed: float = 0.0, device=None) -> int:
    """Views the feature extractor takes at once within the budget (at least 1)."""
    per_view = height * width * batch * _FEATURE_BYTES_PER_PX_VIEW
    return max(1, int((max_memory_gb * 1e9 - fixed - _runtime_bytes(device)) // per_view))


def _tiles(height: int, width: int, tile_h: int, tile_w: int | None = None) -> Iterator[tuple[int, int, int, int]]:
    tile_w = tile_h if tile_w is None else tile_w
    for y0 in range(0, height, tile_h):
        for x0 in range(0, width, tile_w):
            yield y0, min(y0 + tile_h, height), x0, min(x0 + tile_w, width)


def region_volume(net: SubFocalNet, features: torch.Tensor, y0: int, y1: int, x0: int, x1: int,
                  chunk_bytes: float = 256e6) -> torch.Tensor:
    """The cost volume restricted to rows y0:y1, cols x0:x1: equal to
    ``net.cost_volume(features)[..., y0:y1, x0:x1]`` without building the whole volume.

    features (B, N, 4, H, W) of the whole image -> (B, 4N, D, y1 - y0, x1 - x0) float32 (channels-last
    memory on the fast path). Bilinear on the eval fast path: gathered from interpolated maps
    (methods/subfocal/fast.py); otherwise sampled like lfbench.data.shift.shift_views.
    """
    if net.interpolation != "bilinear" or not net.uses_fast_path():
        return _grid_region_volume(net, features, y0, y1, x0, x1, chunk_bytes)
    from lfbench_methods.subfocal.fast import VolumeGather, pad_features

    b, n, c, h, w = features.shape
    plan = net._shift_plan()
    gather = VolumeGather(plan, pad_features(features, plan.pad), y0, y1, x0, x1)
    d, rh, rw = plan.disparities, y1 - y0, x1 - x0
    out = torch.empty((b, d, rh, rw, n * c), dtype=torch.float32, device=features.device)
    step = max(1, int(chunk_bytes // (b * rh * rw * n * (4 * c + 8))))
    for k in range(0, d, step):  # disparity chunks bound the gather indices
        gather.fill(out[:, k:k + step], k, min(k + step, d))
    return out.permute(0, 4, 1, 2, 3)


def _grid_region_volume(net: SubFocalNet, features: torch.Tensor, y0: int, y1: int, x0: int, x1: int,
                  chunk_bytes: float = 256e6) -> torch.Tensor:
    """:func:`region_volume` with the arithmetic of lfbench.data.shift.shift_views (grid_sample; phase shifts
    the whole map, a global operation, and crops): the reference path, and nearest / phase."""
    b, n, c, h, w = features.shape
    disp = net.disparities
    d, rh, rw = disp.numel(), y1 - y0, x1 - x0
    vol = torch.empty((b, n * c, d, rh, rw), dtype=torch.float32, device=features.device)
    off = net.offsets.to(features.device, torch.float32)
    disp = disp.to(features.device, torch.float32)
    sx = disp[:, None] * off[None, :, 0]  # (D, N), as in shift_views
    sy = disp[:, None] * off[None, :, 1]
    if net.interpolation == "phase":
        # shift_views pads its FFT canvas by _phase_pad(shifts); the result depends on the canvas size,
        # so a chunk of disparities is pre-padded to give the canvas of the whole grid.
        full_x, full_y = _phase_pad(sx), _phase_pad(sy)
        per_d = b * n * c * (h + 2 * full_y) * (w + 2 * full_x) * 4 * 8  # canvas, spectrum, products
        step = max(1, int(chunk_bytes // per_d))
        for k in range(0, d, step):
            ex, ey = full_x - _phase_pad(sx[k:k + step]), full_y - _phase_pad(sy[k:k + step])
            padded = F.pad(features.float(), (ex, ex, ey, ey))
            sh = shift_views(padded, net.offsets, disp[k:k + step], "phase")[..., y0 + ey:y1 + ey, x0 + ex:x1 + ex]
            vol[:, :, k:k + step] = sh.reshape(b, -1, n * c, rh, rw).transpose(1, 2)
        return vol
    xs = torch.arange(w, device=features.device, dtype=torch.float32)[x0:x1]
    ys = torch.arange(h, device=features.device, dtype=torch.float32)[y0:y1]
    src = features.reshape(b * n, c, h, w).float()
    step = max(1, int(chunk_bytes // (b * n * rh * rw * 4 * (2 + c))))
    for k in range(0, d, step):
        gx = (xs[None, None, None, :] - sx[k:k + step, :, None, None]) * (2.0 / max(w - 1, 1)) - 1.0
        gy = (ys[None, None, :, None] - sy[k:k + step, :, None, None]) * (2.0 / max(h - 1, 1)) - 1.0
        grid = torch.stack(torch.broadcast_tensors(gx, gy), dim=-1)  # (dk, N, rh, rw, 2)
        dk = grid.shape[0]
        grid = grid.transpose(0, 1).reshape(1, n, dk * rh, rw, 2).expand(b, n, dk * rh, rw, 2)
        out = F.grid_sample(src, grid.reshape(b * n, dk * rh, rw, 2), mode=net.interpolation,
                            padding_mode="zeros", align_corners=True)  # (B*N, C, dk*rh, rw)
        vol[:, :, k:k + dk] = out.reshape(b, n * c, dk, rh, rw)
    return vol


def _phase_pad(shifts: torch.Tensor) -> int:
    """The canvas padding lfbench.data.shift uses for phase shifts of these amounts (px)."""
    return int(math.ceil(float(shifts.abs().max()))) + 1


class _VolumeSlices:
    """A tile's prebuilt fp32 volume (B, 4N, D, rows, cols) as a slab source for the fast aggregation."""

    def __init__(self, volume: torch.Tensor, dtype: torch.dtype) -> None:
        self.volume, self.dtype = volume, dtype

    def fill(self, out: torch.Tensor, d0: int, d1: int) -> None:
        out.copy_(self.volume[:, :, d0:d1].permute(0, 2, 3, 4, 1))

    def release(self) -> None:
        self.volume = None


def release_memory() -> None:
    """Give freed heap memory back to the OS (glibc ``malloc_trim``; a no-op elsewhere): freed activations
    of one phase would otherwise stay in the process's resident set beside the next phase's."""
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def padded_features(net: SubFocalNet, views: torch.Tensor, pad: int, chunk: int = 0) -> torch.Tensor:
    """Eval-mode features of views (B, N, H, W), ``chunk`` views at a time (0 = all), zero-padded by ``pad``
    px: (B, H + 2 pad, W + 2 pad, N, 4) float32 channels-last (what the cost volume is gathered from)."""
    from lfbench_methods.subfocal.fast import FastExtractor

    b, n, h, w = views.shape
    if n != net.angular ** 2:
        raise ValueError(f"expected {net.angular ** 2} views, got {n}")
    out = views.new_zeros((b, h + 2 * pad, w + 2 * pad, n, FEATURES))
    extractor = FastExtractor(net.extractor)
    x = views.transpose(0, 1).reshape(n * b, 1, h, w)  # view-major
    chunk = n if chunk <= 0 else chunk
    for i in range(0, n, chunk):  # chunks of views bound the extractor's memory
        f = extractor(x[i * b:(i + chunk) * b])  # (m * B, 4, H, W) channels-last
        m = f.shape[0] // b
        out[:, pad:pad + h, pad:pad + w, i:i + m] = f.reshape(m, b, FEATURES, h, w).permute(1, 3, 4, 0, 2)
    return out


def eval_cost(net: SubFocalNet, views: torch.Tensor, tile_h: int, tile_w: int, *, halo: int = EXACT_HALO,
              precision: str = "fp32", max_memory_gb: float = 4.0, progress: bool = False,
              timings: dict | None = None) -> torch.Tensor:
    """The raw cost (B, D, H, W) float32 of the eval-mode network on views (B, N, H, W), in tiles of
    tile_h x tile_w px (each computed with ``halo`` px of context), on the fast path. Call under
    torch.inference_mode() with ``net`` in eval mode. ``timings`` (a dict) receives the seconds of the
    phases (features_s, attention_s, aggregation_s), the same in CPU seconds of this process (``cpu``: a
    dict with the same keys; far less inflated than wall time by other processes on the cores) and the
    tiling (tiles, tile)."""
    clock, cpu_clock = time.perf_counter(), time.process_time()
    from lfbench_methods.subfocal.fast import FastAggregation, VolumeGather, attention_sum

    b, n, h, w = views.shape
    device = views.device
    dtype = DTYPES[precision]
    bilinear = net.interpolation == "bilinear"
    plan = net._shift_plan() if bilinear else None
    pad = plan.pad if bilinear else 0
    chunk = view_chunk(h, w, b, max_memory_gb, fixed=_fixed_bytes(net, h, w), device=device)
    padded = padded_features(net, views, pad, chunk)
    feats = padded[:, pad:pad + h, pad:pad + w].permute(0, 3, 4, 1, 2)  # (B, N, 4, H, W) view
    release_memory()
    times = {"features_s": time.perf_counter() - clock}
    cpu = {"features_s": time.process_time() - cpu_clock}
    clock, cpu_clock = time.perf_counter(), time.process_time()
    d = net.disparities.numel()
    tiles = list(_tiles(h, w, tile_h, tile_w))
    weights = None
    if net.attention is not None:
        if bilinear:
            total = attention_sum(plan, padded, h, w)
        else:
            total = torch.zeros((b, FEATURES * n), dtype=torch.float64, device=device)
            for y0, y1, x0, x1 in tiles:
                total += _grid_region_volume(net, feats, y0, y1, x0, x1).sum(dim=(2, 3, 4), dtype=torch.float64)
        weights = net.attention_weights((total / (d * h * w)).float().to(device))
    times["attention_s"] = time.perf_counter() - clock
    cpu["attention_s"] = time.process_time() - cpu_clock
    clock, cpu_clock = time.perf_counter(), time.process_time()
    aggregate = FastAggregation(net.aggregation, dtype)
    cost = torch.empty((b, d, h, w), dtype=torch.float32, device=device)
    bar = tqdm(tiles, desc="subfocal tiles", unit="tile", disable=not progress or len(tiles) == 1)
    for y0, y1, x0, x1 in bar:
        ry0, ry1, rx0, rx1 = max(y0 - halo, 0), min(y1 + halo, h), max(x0 - halo, 0), min(x1 + halo, w)
        if bilinear:
            source = VolumeGather(plan, padded, ry0, ry1, rx0, rx1, dtype)
        else:
            source = _VolumeSlices(_grid_region_volume(net, feats, ry0, ry1, rx0, rx1), dtype)
        core = (y0 - ry0, y1 - ry0, x0 - rx0, x1 - rx0)
        cost[:, :, y0:y1, x0:x1] = aggregate(source, b, d, ry1 - ry0, rx1 - rx0, weights, core, slab=_SLAB,
                                             device=device)
        del source
        release_memory()
    times["aggregation_s"] = time.perf_counter() - clock
    cpu["aggregation_s"] = time.process_time() - cpu_clock
    if timings is not None:
        timings.update(times, cpu=cpu, tiles=len(tiles), tile=[min(tile_h, h), min(tile_w, w)])
    return cost


def infer(net: SubFocalNet, views: torch.Tensor, *, tile: int = 0, halo: int = EXACT_HALO,
          max_memory_gb: float | None = CPU_BUDGET_GB, precision: str = "fp32", progress: bool = False,
          timings: dict | None = None) -> InferenceOutput:
    """Run ``net`` (switched to eval mode) on views (B, N, H, W) or (N, H, W) float32 in [0, 1], on the
    device of the network's weights (the views are moved there; the outputs come back to the CPU).

    max_memory_gb: the memory budget (None: 4 GB on the CPU, the GPU's available memory on CUDA, see
    :func:`memory_budget_gb`; on CUDA a given budget is capped by what is available).

    tile: core tile size in px (0 = the tiling that computes least within ``max_memory_gb``; >= the image
    size = one piece); halo: px of context around each tile (>= 8 is exact); precision: fp32, or bf16
    for the 3D aggregation (features, shifts, attention, the last layer and the softmax stay in fp32);
    timings: a dict that receives the seconds of the phases (see :func:`eval_cost`).
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    if tile < 0 or halo < 0:
        raise ValueError(f"tile and halo must be >= 0, got tile={tile}, halo={halo}")
    if views.dim() == 3:
        views = views.unsqueeze(0)
    net.eval()
    device = net.disparities.device
    if precision == "bf16":
        require_bf16(device)  # one line instead of oneDNN's error on a CPU without bf16 instructions
    views = views.to(device, torch.float32)
    b, n, h, w = views.shape
    max_memory_gb = memory_budget_gb(device, max_memory_gb)  # after the views are on the device
    tile_h, tile_w = plan_tiles(net, h, w, halo, max_memory_gb, precision, device) if tile == 0 else (tile, tile)
    with torch.inference_mode():
        cost = eval_cost(net, views, tile_h, tile_w, halo=halo, precision=precision, max_memory_gb=max_memory_gb,
                         progress=progress, timings=timings)
        disparity, probability = net.regress(cost)
        del cost
        uncertainty = distribution_std(probability, net.disparities, disparity)
    return InferenceOutput(disparity.cpu(), probability.cpu(), uncertainty.cpu(), net.disparities.cpu().clone())


def tile_count(height: int, width: int, tile: int) -> int:
    """Number of tiles ``infer`` uses for a given core tile size."""
    return math.ceil(height / tile) * math.ceil(width / tile)


__all__ = ["infer", "InferenceOutput", "plan_tile", "plan_tiles", "memory_budget_gb", "CPU_BUDGET_GB",
           "conv_width_limit", "cpu_has_amx_bf16", "AMX_MAX_CONV_WIDTH",
           "estimate_tile_bytes", "gather_bytes",
           "region_volume", "distribution_std", "eval_cost", "padded_features", "tile_count", "EXACT_HALO",
           "PRECISIONS"]
