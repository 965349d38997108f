"""The estimator of ``planesweep`` (methods/planesweep/method.py): a training-free plane sweep over
SubFocal's disparity grid.

Pipeline, all batched torch on the chosen device (``device``: auto, cpu, cuda or cuda:K; every tensor lives
there, the outputs come back to the CPU):

1. Matching features: each gray view is contrast-normalised in a small window,
   ``(I - mean) / (std + eps)``, so faint texture (shadows, dark walls) counts as much as strong texture.
2. Plane sweep: every view is shifted onto the centre view for every candidate disparity
   ``d_min, d_min + interval, ..., d_max`` (``lfbench.data.shift`` geometry: a view at angular offset (du, dv)
   is read at ``(x - d du, y - d dv)``; edge pixels are replicated instead of zero-filled). Per view the
   cost is ``|view - centre|``.
3. Occlusion-aware matching: the per-view costs are averaged over several view subsets (all views, the
   left/right/upper/lower half of the aperture, the centre row and the centre column). A pixel next to
   an occluder is seen unoccluded by at least one subset (the half away from the occluder; the centre row
   or column between two occluders, e.g. in a thin gap), so each pixel keeps, per disparity, the smallest
   3x3-averaged subset cost.
4. Edge-aware aggregation: cross-based support regions (every pixel grows arms up to ``arm_length`` px
   while the centre view's gray level stays within ``arm_tau``; the support is the union of the horizontal
   arms along the vertical arm), computed with integral images, so support stops at intensity edges and
   grows in flat regions.
5. Winner-takes-all and sub-pixel refinement: an equiangular (V-shaped, matched to the L1 cost) or
   parabolic fit through the minimum and its two neighbours, which resolves disparities between the
   grid values.

The prediction also carries ``distribution`` (softmax over the grid of minus the aggregated cost divided
by its mean over the grid, temperature ``temperature``) and ``uncertainty`` (that distribution's standard
deviation, px). On the real scenes the error grows with it: mean |error| 0.02 px in the lower half of
the uncertainty, 0.6-0.8 px in its top 1 %.

Memory is bounded: views are shifted in chunks of disparities and bands of rows (about 32 MB per chunk);
the cost volume is (D, S, H, W) float32 (S = 7 subsets; 230 MB for 512x512 at interval 0.25).
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

VIEW_SETS = ("star", "all")
OCCLUSION_MODES = ("subsets", "none")
SUBPIXEL_FITS = ("equiangular", "parabola", "none")
_CHUNK_ELEMENTS = 8 * 1024 * 1024  # floats per shifted-view chunk (32 MB)


# --------------------------------------------------------------------------- the estimator


def estimate(views: torch.Tensor, offsets: torch.Tensor, disparities: torch.Tensor, interval: float, *,
             interpolation: str = "bilinear", view_set: str = "star",
             occlusion: str = "subsets", norm_radius: int = 2, arm_length: int = 16, arm_tau: float = 0.02,
             subpixel: str = "equiangular", temperature: float = 0.05,
             ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Disparity of the centre view from N gray views.

    views: (N, H, W) float32 gray in [0, 1], view k at angular offset ``offsets[k]`` = (u - uc, v - vc);
    disparities: (D,) ascending candidates, ``interval`` apart (px per view step).
    Returns (cost (D, H, W) aggregated matching cost, disparity (H, W) px, distribution (D, H, W),
    uncertainty (H, W) px), all on the views' device.
    """
    offsets, disparities = offsets.to(views.device), disparities.to(views.device)
    keep = select_views(offsets, view_set)
    gray, off = views[keep], offsets[keep]
    centre_index = int(torch.nonzero((off == 0).all(dim=1))[0, 0])
    guide = gray[centre_index].clone()  # raw centre view: guides the aggregation windows
    feats = normalise(gray, norm_radius) if norm_radius > 0 else gray
    weights = subset_weights(off, occlusion)  # (S, N)
    raw = sweep_costs(feats, off, disparities, weights, feats[centre_index], interpolation)  # (D, S, H, W)
    cost = best_subset(raw)  # (D, H, W)
    del raw
    if arm_length > 0:
        cost = cross_aggregate(cost, cross_arms(guide, arm_length, arm_tau))
    disp = subpixel_minimum(cost, disparities, interval, subpixel)
    relative = cost / cost.mean(dim=0, keepdim=True).clamp(min=1e-12)  # scale-free: texture-rich or not
    dist = torch.softmax(-relative / temperature, dim=0)
    mean = (dist * disparities[:, None, None]).sum(0)
    unc = ((dist * (disparities[:, None, None] - mean) ** 2).sum(0)).clamp(min=0).sqrt()
    return cost, disp, dist, unc


def select_views(offsets: torch.Tensor, views: str) -> torch.Tensor:
    """Bool (N,) of the views used: all, or the star (centre row, centre column, both diagonals)."""
    u, v = offsets[:, 0], offsets[:, 1]
    if views == "all":
        return torch.ones_like(u, dtype=torch.bool)
    return (u == 0) | (v == 0) | (u.abs() == v.abs())


def subset_weights(offsets: torch.Tensor, occlusion: str) -> torch.Tensor:
    """(S, N) float32 rows averaging the per-view costs over each view subset.

    ``none``: all views. ``subsets``: all views; u <= 0, u >= 0, v <= 0, v >= 0 (half apertures, one on
    the far side of any single occluder); v == 0 and u == 0 (centre row / column: between two occluders).
    Subsets that duplicate another one (e.g. the centre row of a 1 x U grid) are dropped.
    """
    u, v = offsets[:, 0], offsets[:, 1]
    rows = [torch.ones_like(u)]
    if occlusion == "subsets":
        rows += [(u <= 0).float(), (u >= 0).float(), (v <= 0).float(), (v >= 0).float(),
                 (v == 0).float(), (u == 0).float()]
    unique: list[torch.Tensor] = []
    for r in rows:  # a handful of masks, not a loop over views
        if r.sum() >= 2 and not any(torch.equal(r, q) for q in unique):
            unique.append(r)
    w = torch.stack(unique)
    return w / w.sum(dim=1, keepdim=True)


def box_mean(x: torch.Tensor, r: int) -> torch.Tensor:
    """Mean over the (2r+1) x (2r+1) window (replicated border) of x (..., H, W), via integral images."""
    if r <= 0:
        return x
    shape = x.shape
    h, w = shape[-2:]
    k = 2 * r + 1
    xp = F.pad(x.reshape(-1, 1, h, w), (r + 1, r, r + 1, r), mode="replicate")[:, 0]
    c = xp.cumsum(-1)
    c = c[..., k:] - c[..., :-k]
    c = c.cumsum(-2)
    c = c[..., k:, :] - c[..., :-k, :]
    return (c / (k * k)).reshape(shape)


def normalise(views: torch.Tensor, radius: int, eps: float = 0.01) -> torch.Tensor:
    """Local contrast normalisation of (N, H, W) views: (I - mean) / (std + eps) over (2r+1)^2 windows.

    In float64: the variance of a flat patch (std ~0.005) is far below float32 integral-image rounding.
    """
    x = views.double()
    mean = box_mean(x, radius)
    std = (box_mean(x * x, radius) - mean * mean).clamp(min=0).sqrt()
    return ((x - mean) / (std + eps)).to(views.dtype)


# --------------------------------------------------------------------------- the sweep


class _Shifter:
    """Shifts N views (N, H, W) by candidate disparities, band of rows by band of rows.

    ``out[k, n, y, x] = views[n, y - d_k dv_n, x - d_k du_n]`` (edge pixels replicated). bilinear and
    nearest read a replicate-padded copy through gathers of whole rows (no per-pixel grid); phase shifts
    the padded canvas in the Fourier domain (the shift never wraps: the pad exceeds the largest shift).
    """

    def __init__(self, views: torch.Tensor, offsets: torch.Tensor, disparities: torch.Tensor, mode: str) -> None:
        n, h, w = views.shape
        self.h, self.w, self.mode = h, w, mode
        self.off = offsets.to(torch.float32)
        largest = float(disparities.abs().max()) * float(self.off.abs().max())
        self.pad = int(math.ceil(largest)) + 2
        p = self.pad
        self.padded = F.pad(views[None], (p, p, p, p), mode="replicate")[0].contiguous()  # (N, H+2p, W+2p)
        if mode == "phase":
            self.spectrum = torch.fft.rfft2(self.padded)
        else:
            self.windows = self.padded.unfold(2, w, 1)  # (N, H+2p, 2p+1, W): windows[n, y, j] = row y at x+j-p
            self.wide_windows = self.padded.unfold(2, w + 1, 1)  # one px wider: both bilinear neighbours

    def shift(self, d: torch.Tensor, y0: int, rows: int) -> torch.Tensor:
        """(K, N, rows, W) views shifted by d (K,), output rows y0 .. y0 + rows - 1."""
        sx = d[:, None] * self.off[None, :, 0]  # (K, N)
        sy = d[:, None] * self.off[None, :, 1]
        p, n = self.pad, self.off.shape[0]
        if self.mode == "phase":
            return self._phase(sx, sy)[:, :, p + y0:p + y0 + rows, p:p + self.w]
        dev = self.padded.device
        idx_n = torch.arange(n, device=dev)[None, :, None]
        if self.mode == "nearest":
            ix, iy = torch.round(sx).long(), torch.round(sy).long()
            row = (y0 + p - iy)[:, :, None] + torch.arange(rows, device=dev)
            return self.windows[idx_n, row, (p - ix)[:, :, None], :]
        fx, fy = torch.floor(sx), torch.floor(sy)
        wx, wy = (sx - fx)[:, :, None, None], (sy - fy)[:, :, None, None]
        ix, iy = fx.long(), fy.long()
        row = (y0 + p - iy - 1)[:, :, None] + torch.arange(rows + 1, device=dev)  # one extra row above for the y blend
        col = (p - ix - 1)[:, :, None]
        pairs = self.wide_windows[idx_n, row, col, :]  # (K, N, rows+1, W+1): reads x - ix - 1 .. x - ix + W - 1
        across = torch.lerp(pairs[..., 1:], pairs[..., :-1], wx)  # between x - ix and x - ix - 1
        return torch.lerp(across[:, :, 1:], across[:, :, :-1], wy)

    def _phase(self, sx: torch.Tensor, sy: torch.Tensor) -> torch.Tensor:
        hp, wp = self.padded.shape[-2:]
        dev = self.padded.device
        ky = torch.fft.fftfreq(hp, device=dev)[:, None]
        kx = torch.fft.rfftfreq(wp, device=dev)[None, :]
        phase = -2 * math.pi * (ky * sy[:, :, None, None] + kx * sx[:, :, None, None])
        ramp = torch.polar(torch.ones((), device=dev), phase)
        return torch.fft.irfft2(self.spectrum[None] * ramp, s=(hp, wp))


def sweep_costs(feats: torch.Tensor, offsets: torch.Tensor, disparities: torch.Tensor, weights: torch.Tensor,
                centre: torch.Tensor, interpolation: str) -> torch.Tensor:
    """Subset-averaged L1 matching cost (D, S, H, W): ``sum_n weights[s, n] |shift_d(view_n) - centre|``.

    Views are shifted in chunks of disparities and bands of rows so that one chunk holds about 16 M floats.
    """
    n, h, w = feats.shape
    d_count, s_count = disparities.shape[0], weights.shape[0]
    shifter = _Shifter(feats, offsets, disparities, interpolation)
    if interpolation == "phase":  # the Fourier shift makes whole images: chunk disparities only
        band = h
        chunk = max(1, _CHUNK_ELEMENTS // (4 * n * shifter.padded.shape[-2] * shifter.padded.shape[-1]))
    else:
        band = min(h, max(8, _CHUNK_ELEMENTS // (n * w)))
        chunk = max(1, _CHUNK_ELEMENTS // (n * band * w))
    cost = torch.empty(d_count, s_count, h, w, dtype=torch.float32, device=feats.device)
    for k in range(0, d_count, chunk):  # chunks of disparities and bands of rows, for memory
        d = disparities[k:k + chunk]
        for y0 in range(0, h, band):
            rows = min(band, h - y0)
            diff = shifter.shift(d, y0, rows).sub_(centre[y0:y0 + rows]).abs_()  # (K, N, rows, W)
            cost[k:k + chunk, :, y0:y0 + rows] = (weights @ diff.reshape(d.shape[0], n, -1)).reshape(
                d.shape[0], s_count, rows, w)
    return cost


def best_subset(cost: torch.Tensor, radius: int = 1) -> torch.Tensor:
    """(D, S, H, W) -> (D, H, W): per disparity the smallest 3x3-averaged subset cost (chunked for memory)."""
    d_count, s_count, h, w = cost.shape
    out = torch.empty(d_count, h, w, dtype=cost.dtype, device=cost.device)
    chunk = max(1, _CHUNK_ELEMENTS // (s_count * h * w))
    for k in range(0, d_count, chunk):
        out[k:k + chunk] = box_mean(cost[k:k + chunk], radius).amin(dim=1)
    return out


# --------------------------------------------------------------------------- aggregation


def cross_arms(guide: torch.Tensor, length: int, tau: float) -> torch.Tensor:
    """(4, H, W) int64 arm lengths (left, right, up, down) of every pixel of the (H, W) guide.

    An arm grows pixel by pixel while every pixel on it differs from the anchor by less than ``tau``,
    up to ``length`` px and never past the image border.
    """
    h, w = guide.shape
    dev = guide.device
    steps = torch.arange(1, length + 1, device=dev)
    big = torch.finfo(guide.dtype).max
    padded = F.pad(guide[None, None], (length, length, length, length), value=big)[0, 0]  # border stops arms
    arms = []
    for dy, dx in ((0, -1), (0, 1), (-1, 0), (1, 0)):  # 4 directions, each vectorised over the arm length
        ys = length + dy * steps[:, None, None] + torch.arange(h, device=dev)[None, :, None]
        xs = length + dx * steps[:, None, None] + torch.arange(w, device=dev)[None, None, :]
        ok = (padded[ys, xs] - guide[None]).abs() < tau  # (length, H, W)
        arms.append(ok.to(torch.int64).cumprod(dim=0).sum(dim=0))
    return torch.stack(arms)


def cross_aggregate(cost: torch.Tensor, arms: torch.Tensor) -> torch.Tensor:
    """Mean of (D, H, W) cost over each pixel's cross-based support: horizontal arm sums, then vertical."""
    d_count, h, w = cost.shape
    left, right, up, down = arms
    xs, ys = torch.arange(w, device=cost.device), torch.arange(h, device=cost.device)[:, None]

    def horizontal(x: torch.Tensor) -> torch.Tensor:
        c = F.pad(x.cumsum(-1), (1, 0))  # c[..., j] = sum of x[..., :j]
        hi, lo = (xs + right + 1).expand(x.shape), (xs - left).expand(x.shape)
        return c.gather(-1, hi) - c.gather(-1, lo)

    def vertical(x: torch.Tensor) -> torch.Tensor:
        c = F.pad(x.cumsum(-2), (0, 0, 1, 0))
        hi, lo = (ys + down + 1).expand(x.shape), (ys - up).expand(x.shape)
        return c.gather(-2, hi) - c.gather(-2, lo)

    count = vertical(horizontal(torch.ones(1, h, w, dtype=cost.dtype, device=cost.device)))
    out = torch.empty_like(cost)
    chunk = max(1, _CHUNK_ELEMENTS // (h * w))
    for k in range(0, d_count, chunk):  # chunks of disparities, for memory
        out[k:k + chunk] = vertical(horizontal(cost[k:k + chunk])) / count
    return out


# --------------------------------------------------------------------------- sub-pixel minimum


def subpixel_minimum(cost: torch.Tensor, disparities: torch.Tensor, interval: float, fit: str) -> torch.Tensor:
    """(H, W) disparity at the minimum of the (D, H, W) cost, refined between grid values by ``fit``.

    equiangular: two lines of opposite slope through the minimum and its neighbours (exact for a V-shaped
    cost such as an L1 matching cost); parabola: a parabola through the same three samples. The offset
    stays within half an interval; the grid's end points are returned as they are.
    """
    d_count = cost.shape[0]
    best = cost.argmin(dim=0)
    disp = disparities[best]
    if fit == "none" or d_count < 3:
        return disp
    mid = best.clamp(1, d_count - 2)
    c_minus = cost.gather(0, (mid - 1)[None])[0]
    c_0 = cost.gather(0, mid[None])[0]
    c_plus = cost.gather(0, (mid + 1)[None])[0]
    if fit == "equiangular":
        denom = 2.0 * (torch.maximum(c_minus, c_plus) - c_0)
    else:
        denom = 2.0 * (c_minus - 2.0 * c_0 + c_plus)
    ok = denom > 1e-12
    offset = torch.where(ok, (c_minus - c_plus) / denom.clamp(min=1e-12), torch.zeros_like(denom)).clamp(-0.5, 0.5)
    inner = (best > 0) & (best < d_count - 1)
    return torch.where(inner, disparities[mid] + offset * interval, disp)
