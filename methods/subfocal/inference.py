"""SubFocal inference on whole images or in exact tiles, in bounded memory.

Two parts of the network see the whole image: the SPP upsampling of the feature extractor and the
channel attention (a mean over the whole cost volume). Exact tiling therefore works in three steps:

1. features of the whole image (B, N, 4, H, W), extracted a few views at a time (cheap: 4 ch/view);
2. the attention mean of the cost volume, accumulated over all tiles before any tile is aggregated;
3. per tile, the cost volume of the tile plus a halo (sampled from the whole-image feature map, so
   shifts reach across tile borders exactly as in one pass) and the 3D aggregation; only the tile's
   core is kept. The aggregation is nine 3x3x3 convolutions, so a halo of >= 9 px makes the result
   identical to whole-image inference (up to float rounding).

``tile=0`` picks the tile size from a memory budget (``max_memory_gb``): the whole image in one
piece when it fits. The output uncertainty is the standard deviation of the predicted distribution
in px: sqrt(sum_k p_k (d_k - d_hat)^2).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import nullcontext
from dataclasses import dataclass

import torch
import torch.nn.functional as F
from lfbench_methods.subfocal.network import FEATURES, SubFocalNet
from tqdm import tqdm

from lfbench.shift import shift_views

EXACT_HALO = 9  # receptive radius of the 3D aggregation in px
PRECISIONS = ("fp32", "bf16")
_FEATURE_BYTES_PER_PX_VIEW = 4 * 160  # extractor working set per view pixel (fp32, measured order)
_VOLUME_FACTOR = 1.3  # cost volume + one disparity chunk of sampling grid and samples
_RUNTIME_BYTES = 0.3e9  # the interpreter, torch and the weights


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


def estimate_tile_bytes(net: SubFocalNet, rows: int, cols: int, precision: str = "fp32") -> int:
    """Peak working set of one tile's cost volume and 3D aggregation (rows x cols incl. halo), bytes.

    Per voxel (disparity x pixel): the fp32 volume plus a chunk of sampling grid (1.3 x 4 bytes per
    channel), about five live aggregation activations of ``width`` channels (fp32 accounted for bf16
    too: autocast keeps some in fp32), and for bf16 the converted channels-last copy of the volume.
    Calibrated against peak RSS of the paper network on this CPU (fp32 ~4.3 kB, bf16 ~4.4 kB per voxel).
    """
    d = net.disparities.numel()
    channels = FEATURES * net.angular ** 2
    width = net.config()["width"]
    per_voxel = 4 * channels * _VOLUME_FACTOR + 20 * width + (2 * channels if precision == "bf16" else 0)
    return int(d * rows * cols * per_voxel)


def plan_tile(net: SubFocalNet, height: int, width: int, halo: int = EXACT_HALO, max_memory_gb: float = 4.0,
              precision: str = "fp32") -> int:
    """The core tile size (px) for ``max_memory_gb``: the whole image when it fits, else the fewest tiles
    per side k whose largest tile (ceil(size / k) + 2 halo) fits beside the whole-image buffers.
    Balanced tiles keep the halo overhead small (512 px in 3 x 3 tiles of 171 px: +15 % pixels)."""
    budget = max_memory_gb * 1e9 - _fixed_bytes(net, height, width) - _RUNTIME_BYTES
    for k in range(1, max(height, width) + 1):
        th, tw = math.ceil(height / k), math.ceil(width / k)
        rows, cols = min(th + 2 * halo, height) if k > 1 else height, min(tw + 2 * halo, width) if k > 1 else width
        if estimate_tile_bytes(net, rows, cols, precision) <= budget or max(th, tw) <= 8:
            return max(th, tw)
    return 8


def _fixed_bytes(net: SubFocalNet, height: int, width: int) -> int:
    """Whole-image buffers: features (N x 4 ch), cost, probability and outputs."""
    d = net.disparities.numel()
    return 4 * height * width * (FEATURES * net.angular ** 2 + 3 * d + 4)


def _tiles(height: int, width: int, tile: int) -> Iterator[tuple[int, int, int, int]]:
    for y0 in range(0, height, tile):
        for x0 in range(0, width, tile):
            yield y0, min(y0 + tile, height), x0, min(x0 + tile, width)


def region_volume(net: SubFocalNet, features: torch.Tensor, y0: int, y1: int, x0: int, x1: int,
                  chunk_bytes: float = 256e6) -> torch.Tensor:
    """The cost volume restricted to rows y0:y1, cols x0:x1: equal to
    ``net.cost_volume(features)[..., y0:y1, x0:x1]`` without building the whole volume.

    features (B, N, 4, H, W) of the whole image -> (B, 4N, D, y1 - y0, x1 - x0) float32.
    nearest/bilinear sample the whole-image map at the region's pixels with the same arithmetic as
    lfbench.shift.shift_views; phase shifts the whole map (a global operation) and crops.
    """
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
    """The canvas padding lfbench.shift uses for phase shifts of these amounts (px)."""
    return int(math.ceil(float(shifts.abs().max()))) + 1


def _autocast(precision: str, device: torch.device):
    if precision == "fp32":
        return nullcontext()
    return torch.autocast(device.type, dtype=torch.bfloat16)


def infer(net: SubFocalNet, views: torch.Tensor, *, tile: int = 0, halo: int = EXACT_HALO,
          max_memory_gb: float = 4.0, precision: str = "fp32", progress: bool = False) -> InferenceOutput:
    """Run ``net`` (switched to eval mode) on views (B, N, H, W) or (N, H, W) float32 in [0, 1].

    tile: core tile size in px (0 = from ``max_memory_gb``; >= the image size = one piece);
    halo: px of context around each tile (>= 9 is exact); precision: fp32, or bf16 autocast for
    the 3D aggregation (features, shifts, attention and softmax stay in fp32).
    """
    if precision not in PRECISIONS:
        raise ValueError(f"precision must be one of {', '.join(PRECISIONS)}, got {precision!r}")
    if tile < 0 or halo < 0:
        raise ValueError(f"tile and halo must be >= 0, got tile={tile}, halo={halo}")
    if views.dim() == 3:
        views = views.unsqueeze(0)
    net.eval()
    device = net.disparities.device
    views = views.to(device, torch.float32)
    b, n, h, w = views.shape
    if tile == 0:
        tile = plan_tile(net, h, w, halo, max_memory_gb, precision)
    tiles = list(_tiles(h, w, tile))
    with torch.inference_mode():
        per_view = h * w * b * _FEATURE_BYTES_PER_PX_VIEW
        feats = net.features(views, view_chunk=max(1, int(max_memory_gb * 1e9 * 0.5 // per_view)))
        d = net.disparities.numel()
        weights = None
        if net.attention is not None:
            total = torch.zeros((b, FEATURES * n), dtype=torch.float64, device=device)
            for y0, y1, x0, x1 in tiles:
                total += region_volume(net, feats, y0, y1, x0, x1).sum(dim=(2, 3, 4), dtype=torch.float64)
            weights = net.attention_weights((total / (d * h * w)).float())
        cost = torch.empty((b, d, h, w), dtype=torch.float32, device=device)
        bar = tqdm(tiles, desc="subfocal tiles", unit="tile", disable=not progress or len(tiles) == 1)
        for y0, y1, x0, x1 in bar:
            ry0, ry1, rx0, rx1 = max(y0 - halo, 0), min(y1 + halo, h), max(x0 - halo, 0), min(x1 + halo, w)
            vol = region_volume(net, feats, ry0, ry1, rx0, rx1)
            if weights is not None:
                vol.mul_(weights[:, :, None, None, None])
            if precision == "bf16":
                vol = vol.to(torch.bfloat16).contiguous(memory_format=torch.channels_last_3d)
            with _autocast(precision, device):
                out = net.aggregation(vol)
            cost[:, :, y0:y1, x0:x1] = out[:, :, y0 - ry0:y1 - ry0, x0 - rx0:x1 - rx0].float()
            del vol, out
        disparity, probability = net.regress(cost)
        uncertainty = distribution_std(probability, net.disparities, disparity)
    return InferenceOutput(disparity.cpu(), probability.cpu(), uncertainty.cpu(), net.disparities.cpu().clone())


def tile_count(height: int, width: int, tile: int) -> int:
    """Number of tiles ``infer`` uses for a given core tile size."""
    return math.ceil(height / tile) * math.ceil(width / tile)


__all__ = ["infer", "InferenceOutput", "plan_tile", "estimate_tile_bytes", "region_volume", "distribution_std",
           "tile_count", "EXACT_HALO", "PRECISIONS"]
