"""Sub-pixel shifting of light-field views onto the centre view, for a grid of disparities.

The geometry is the benchmark's: ``centre(x, y) = view_{u,v}(x - (u - uc) d, y - (v - vc) d)``
for a pixel of disparity d (px per view step). Shifting view (u, v) by candidate d gives
``out(y, x) = F(y - d (v - vc), x - d (u - uc))``: every view lands on the centre where d is right.
Pixels sampled from outside the view are ``fill`` (0, as in the authors' code).

Interpolation modes: ``nearest`` and ``bilinear`` (each neighbour outside the image reads 0,
like TensorFlow's image translate), ``phase`` (Fourier phase shift on a zero-padded canvas).
All views and disparities are shifted in one batched call, never in Python loops over them.
"""

from __future__ import annotations

import math
from typing import Literal

import torch
import torch.nn.functional as F

Interpolation = Literal["nearest", "bilinear", "phase"]
INTERPOLATIONS: tuple[str, ...] = ("nearest", "bilinear", "phase")


MAX_ABS_DISPARITY = 64.0  # px per view step (HCI scenes: within +-4)
MAX_DISPARITIES = 1024  # candidate disparities of one grid (the paper's finest: 81)


def disparity_grid(d_min: float = -4.0, d_max: float = 4.0, interval: float = 0.5) -> torch.Tensor:
    """Candidate disparities d_min, d_min + interval, ..., d_max as float32 (D,).

    (-4, 4, 0.5) gives 17 values, 0.25 gives 33, 0.1 gives 81, 1 gives 9. The range must be a
    whole number of intervals, within +-MAX_ABS_DISPARITY px and at most MAX_DISPARITIES values
    (checked before anything is allocated).
    """
    try:
        d_min, d_max, interval = float(d_min), float(d_max), float(interval)
    except (TypeError, ValueError):
        raise ValueError(f"d_min, d_max and interval must be numbers, got {d_min!r}, {d_max!r}, {interval!r}") from None
    if not all(math.isfinite(v) for v in (d_min, d_max, interval)):
        raise ValueError(f"d_min, d_max and interval must be finite, got [{d_min}, {d_max}] step {interval}")
    if interval <= 0 or d_max <= d_min:
        raise ValueError(f"need interval > 0 and d_max > d_min, got [{d_min}, {d_max}] step {interval}")
    if max(abs(d_min), abs(d_max)) > MAX_ABS_DISPARITY:
        raise ValueError(f"disparities beyond +-{MAX_ABS_DISPARITY} px per view step are not supported, "
                         f"got [{d_min}, {d_max}]")
    steps = (d_max - d_min) / interval
    if steps + 1 > MAX_DISPARITIES:
        raise ValueError(f"[{d_min}, {d_max}] step {interval} gives {steps + 1:.3g} disparities, more than "
                         f"{MAX_DISPARITIES}: use a larger interval")
    n = int(round(steps))
    if abs(steps - n) > 1e-6 * max(1.0, steps):
        raise ValueError(f"[{d_min}, {d_max}] is not a whole number of {interval} px intervals")
    return torch.tensor([d_min + i * interval for i in range(n + 1)], dtype=torch.float64).float()


def angular_offsets(angular_rows: int = 9, angular_cols: int | None = None) -> torch.Tensor:
    """(N, 2) float32 of (u - uc, v - vc) for view k = v * U + u (N = V * U); uc = U // 2."""
    cols = angular_rows if angular_cols is None else angular_cols
    v, u = torch.meshgrid(torch.arange(angular_rows), torch.arange(cols), indexing="ij")
    return torch.stack([(u - cols // 2).flatten(), (v - angular_rows // 2).flatten()], dim=1).float()


def shift_views(views: torch.Tensor, offsets: torch.Tensor, disparities: torch.Tensor,
                mode: Interpolation = "bilinear") -> torch.Tensor:
    """Shift every view by every candidate disparity.

    views: (B, N, C, H, W) features or intensities of N views; offsets: (N, 2) (u - uc, v - vc);
    disparities: (D,) px per view step. Returns (B, D, N, C, H, W) with
    ``out[b, k, n, :, y, x] = views[b, n, :, y - d_k dv_n, x - d_k du_n]`` (0 outside the image).
    """
    if views.dim() != 5:
        raise ValueError(f"views must be (B, N, C, H, W), got {tuple(views.shape)}")
    b, n, c, h, w = views.shape
    if offsets.shape != (n, 2):
        raise ValueError(f"offsets must be ({n}, 2), got {tuple(offsets.shape)}")
    disp = disparities.to(views.device, torch.float32)
    off = offsets.to(views.device, torch.float32)
    sx = disp[:, None] * off[None, :, 0]  # (D, N) shift along x
    sy = disp[:, None] * off[None, :, 1]
    if mode == "phase":
        return _phase_shift(views, sx, sy)
    if mode not in ("nearest", "bilinear"):
        raise ValueError(f"interpolation must be one of {', '.join(INTERPOLATIONS)}, got {mode!r}")
    d = disp.shape[0]
    # Sampling positions in pixels, normalised for grid_sample with align_corners=True.
    xs = torch.arange(w, device=views.device, dtype=torch.float32)
    ys = torch.arange(h, device=views.device, dtype=torch.float32)
    gx = (xs[None, None, None, :] - sx[:, :, None, None]) * (2.0 / max(w - 1, 1)) - 1.0  # (D, N, 1, W)
    gy = (ys[None, None, :, None] - sy[:, :, None, None]) * (2.0 / max(h - 1, 1)) - 1.0  # (D, N, H, 1)
    grid = torch.stack(torch.broadcast_tensors(gx, gy), dim=-1)  # (D, N, H, W, 2)
    grid = grid.to(views.dtype).unsqueeze(0).expand(b, d, n, h, w, 2).reshape(b * d * n, h, w, 2)
    src = views.unsqueeze(1).expand(b, d, n, c, h, w).reshape(b * d * n, c, h, w)
    out = F.grid_sample(src, grid, mode=mode, padding_mode="zeros", align_corners=True)
    return out.reshape(b, d, n, c, h, w)


def _phase_shift(views: torch.Tensor, sx: torch.Tensor, sy: torch.Tensor) -> torch.Tensor:
    """Fourier shift on a canvas zero-padded by the largest shift, so nothing wraps around."""
    b, n, c, h, w = views.shape
    pad_x = int(math.ceil(float(sx.abs().max()))) + 1
    pad_y = int(math.ceil(float(sy.abs().max()))) + 1
    canvas = F.pad(views.float(), (pad_x, pad_x, pad_y, pad_y))
    hp, wp = canvas.shape[-2:]
    spec = torch.fft.rfft2(canvas)  # (B, N, C, Hp, Wp//2+1)
    ky = torch.fft.fftfreq(hp, device=views.device)[:, None]
    kx = torch.fft.rfftfreq(wp, device=views.device)[None, :]
    # shift by +s: multiply by exp(-2 pi i k s)
    phase = torch.exp(-2j * math.pi * (ky * sy[:, :, None, None] + kx * sx[:, :, None, None]))
    shifted = torch.fft.irfft2(spec.unsqueeze(1) * phase[None, :, :, None], s=(hp, wp))  # (B, D, N, C, Hp, Wp)
    return shifted[..., pad_y:pad_y + h, pad_x:pad_x + w].to(views.dtype)
