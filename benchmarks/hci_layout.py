"""A synthetic benchmark in the full HCI layout for scoring benchmarks (generated, no data needed).

Every scene of the benchmark's four categories (stratified: backgammon, dots, pyramids, stripes;
training: boxes, cotton, dino, sideboard; test: bedroom, bicycle, herbs, origami, ground truth hidden as
in the benchmark; additional: the 16 scenes), each with parameters.cfg, ``gt_disp_lowres.pfm`` and
every evaluation mask the toolkit reads for it: the stratified scenes' own masks (label masks of the
dots included), the region masks of the photorealistic scenes (discontinuities, planes, smooth surfaces,
fine, fine surrounding). ``gt_disp_highres.pfm`` (``scale`` x the size per side) and the masks of the
high-resolution metrics at that size are written where the benchmark has them. No views: scoring reads
none (the maps of :func:`write_submissions` stand for the methods).

Ground truth and masks come from one analytic layout per scene evaluated at each resolution's pixel
centres, so the high-resolution files agree with the low-resolution ones. ``scene_set``: ``"issue"`` is
the 9-scene set of the scoring issue (the 4 stratified scenes with high-resolution ground truth, the 4
training scenes and antinous with every region mask at low resolution); ``"full"`` is every scene of the
4 categories, high-resolution ground truth and masks for the stratified and training scenes.
"""

from __future__ import annotations

import zlib
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from PIL import Image

from lfbench.data.hci.params import SceneParameters
from lfbench.data.hci.scene import PARAMETERS_FILE, gt_file_name, mask_file_name
from lfbench.data.pfm import write_pfm
from lfbench.data.submission import write_submission_map

__all__ = ["CATEGORIES", "SCENE_SETS", "write_benchmark", "write_submissions"]

CATEGORIES: dict[str, tuple[str, ...]] = {
    "stratified": ("backgammon", "dots", "pyramids", "stripes"),
    "training": ("boxes", "cotton", "dino", "sideboard"),
    "test": ("bedroom", "bicycle", "herbs", "origami"),
    "additional": ("antinous", "boardgames", "dishes", "greek", "kitchen", "medieval2", "museum", "pens", "pillows",
                   "platonic", "rosemary", "table", "tomb", "tower", "town", "vinyl"),
}
_ISSUE = {"stratified": CATEGORIES["stratified"], "training": CATEGORIES["training"], "additional": ("antinous",)}
SCENE_SETS = ("issue", "full")

# masks of the metrics scored at high resolution (lfbench.scoring.region_metrics): written at both resolutions
_HIGHRES_MASKS = {"mask_discontinuities", "mask_fine", "mask_fine_surrounding", "mask_foreground_fattening",
                  "mask_foreground_thinning", "mask_background", "mask_boxes", "mask_dots_by_size",
                  "mask_low_texture", "mask_high_contrast", "mask_low_contrast"}


def _axes(size: int, scale: int) -> tuple[np.ndarray, np.ndarray]:
    """Pixel centres in low-resolution px of a (size scale)^2 grid: (y column, x row) for broadcasting."""
    c = (np.arange(size * scale, dtype=np.float64) + 0.5) / scale - 0.5
    return c[:, None], c[None, :]


def _photoreal(size: int, scale: int, seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A background plane, a smooth bump, a box in front and thin bars: gt (px) and the region masks."""
    rng = np.random.default_rng(seed)
    y, x = _axes(size, scale)
    s = float(size)
    a, b = rng.uniform(-0.8, 0.8, 2)
    gt = -0.6 + a * x / s + 0.5 * b * y / s
    cy, cx, r = s * rng.uniform(0.55, 0.7), s * rng.uniform(0.25, 0.35), s * 0.16
    rho = np.hypot(y - cy, x - cx) / r
    sphere = rho < 1
    gt = np.where(sphere, gt + 0.9 * np.sqrt(np.clip(1 - rho**2, 0, None)), gt)
    box = (x > 0.55 * s) & (x < 0.85 * s) & (y > 0.12 * s) & (y < 0.42 * s)
    gt = np.where(box, 1.3 + 0.2 * (x - 0.7 * s) / s, gt)
    width = max(1.5, s / 200)
    bar_x = 0.6 * s + np.arange(4)[:, None, None] * 0.06 * s
    bars_each = (np.abs(x[None] - bar_x) < width) & (y[None] > 0.55 * s) & (y[None] < 0.9 * s)
    bars = bars_each.any(axis=0)
    gt = np.where(bars, 1.8, gt)
    edge = 1.0 + s / 256  # px, the width of the discontinuity band
    near_box = (x > 0.55 * s - edge) & (x < 0.85 * s + edge) & (y > 0.12 * s - edge) & (y < 0.42 * s + edge)
    inner_box = (x > 0.55 * s + edge) & (x < 0.85 * s - edge) & (y > 0.12 * s + edge) & (y < 0.42 * s - edge)
    near_bars = ((np.abs(x[None] - bar_x) < width + edge) & (y[None] > 0.55 * s - edge)
                 & (y[None] < 0.9 * s + edge)).any(axis=0)
    surround = ((np.abs(x[None] - bar_x) < width + 3 * edge) & (y[None] > 0.55 * s - 3 * edge)
                & (y[None] < 0.9 * s + 3 * edge)).any(axis=0)
    disc = (near_box & ~inner_box) | (np.abs(rho - 1) * r < edge) | near_bars
    masks = {"mask_discontinuities": disc, "mask_planes": ~sphere & ~bars & ~disc,
             "mask_smooth_surfaces": sphere & ~box & ~bars & ~disc, "mask_fine": bars,
             "mask_fine_surrounding": surround & ~bars}
    return gt, masks


def _backgammon(size: int, scale: int, seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Vertical foreground bars (the first 20 % of each row is foreground, the last 10 % background) with
    gaps that narrow along x; fattening: background between the bars, thinning: the bars."""
    y, x = _axes(size, scale)
    s = float(size)
    fg, bg = 1.2, -0.4 + 0.2 * y / s + 0 * x
    period = 0.04 * s + 0.06 * s * (1 - x / s)
    inside = (x > 0.2 * s) & (x < 0.9 * s)
    bar = ((x % period) < 0.5 * period) & inside | (x <= 0.2 * s)
    gt = np.where(bar, fg, bg)
    rows = (y > 0.1 * s) & (y < 0.9 * s)
    return gt, {"mask_foreground_fattening": ~bar & inside & rows, "mask_foreground_thinning": bar & inside & rows}


def _dots(size: int, scale: int, seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A noisy background plane in a 4 x 4 grid of boxes, each holding 9 dots of falling size (labels
    1..9 by size; the toolkit scores 1..8)."""
    rng = np.random.default_rng(seed)
    y, x = _axes(size, scale)
    s = float(size)
    noise_f = rng.uniform(0.7, 1.3, 2)
    gt = 0.3 + 0.02 * np.sin(x * noise_f[0]) * np.cos(y * noise_f[1])
    cell = s / 4
    box = (np.floor(y / cell).clip(0, 3) * 4 + np.floor(x / cell).clip(0, 3) + 1).astype(np.int32)
    boxes = np.where((x >= 0) & (y >= 0), box, 0)
    dots = np.zeros(np.broadcast_shapes(y.shape, x.shape), np.int32)
    fy, fx = (y % cell) / cell, (x % cell) / cell
    for k in range(9):
        radius = 0.08 * (1 - k / 10)
        cy, cx = 0.2 + 0.3 * (k // 3), 0.2 + 0.3 * (k % 3)
        dot = np.hypot(fy - cy, fx - cx) < radius
        dots[dot] = k + 1
    gt = np.where(dots > 0, 1.0, gt)
    return gt, {"mask_boxes": boxes, "mask_dots_by_size": dots, "mask_background": dots == 0}


def _pyramids(size: int, scale: int, seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A fronto-parallel plane, a sphere out, a sphere in and a pyramid."""
    y, x = _axes(size, scale)
    s = float(size)
    gt = np.full(np.broadcast_shapes(y.shape, x.shape), -0.3)
    r = 0.15 * s
    rho_out, rho_in = np.hypot(y - 0.3 * s, x - 0.3 * s) / r, np.hypot(y - 0.3 * s, x - 0.7 * s) / r
    out, inn = rho_out < 1, rho_in < 1
    gt = np.where(out, -0.3 + 0.8 * np.sqrt(np.clip(1 - rho_out**2, 0, None)), gt)
    gt = np.where(inn, -0.3 - 0.8 * np.sqrt(np.clip(1 - rho_in**2, 0, None)), gt)
    cheb = np.maximum(np.abs(y - 0.72 * s), np.abs(x - 0.5 * s)) / (0.18 * s)
    pyr = cheb < 1
    gt = np.where(pyr, -0.3 + 0.9 * (1 - cheb), gt)
    return gt, {"mask_sphere_out": out, "mask_sphere_in": inn, "mask_pyramids": pyr,
                "mask_plane": ~out & ~inn & ~pyr}


def _stripes(size: int, scale: int, seed: int) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A slanted plane; the low-texture region above, dark and bright stripes below."""
    y, x = _axes(size, scale)
    s = float(size)
    gt = 0.5 + 0.3 * x / s - 0.2 * y / s
    top = y < 0.45 * s
    stripe = (np.floor(x / (0.05 * s)) % 2 == 0) & ~top & (y < 0.95 * s)
    gap = ~stripe & ~top & (y < 0.95 * s)
    return gt, {"mask_low_texture": top & (x > 0.05 * s), "mask_high_contrast": stripe, "mask_low_contrast": gap}


_LAYOUTS = {"backgammon": _backgammon, "dots": _dots, "pyramids": _pyramids, "stripes": _stripes}


def _params(name: str, category: str, size: int, scale: int) -> SceneParameters:
    return SceneParameters(focal_length_mm=100.0, image_resolution_x_px=size, image_resolution_y_px=size,
                           sensor_size_mm=35.0, num_cams_x=9, num_cams_y=9, baseline_mm=100.0 * 512.0 / size,
                           focus_distance_m=7.0, disp_min=-2.0, disp_max=2.0, depth_map_scale=float(scale),
                           name=name, category=category)


def _write_png(path: Path, mask: np.ndarray) -> None:
    arr = np.asarray(mask)
    img = np.where(arr, 255, 0).astype(np.uint8) if arr.dtype == bool else arr.astype(np.uint8)
    Image.fromarray(img).save(path, compress_level=1)


def _write_scene(folder: Path, name: str, category: str, size: int, scale: int, highres: bool, seed: int) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / PARAMETERS_FILE).write_text(_params(name, category, size, scale).to_cfg(), encoding="utf-8")
    if category == "test":  # the benchmark hides the test scenes' ground truth
        return
    layout = _LAYOUTS.get(name, _photoreal)
    for res, factor in (("lowres", 1), *((("highres", scale),) if highres else ())):
        gt, masks = layout(size, factor, seed)
        write_pfm(folder / gt_file_name(res), np.broadcast_to(gt, (size * factor,) * 2).astype(np.float32))
        for mask_name, mask in masks.items():
            if res == "lowres" or mask_name in _HIGHRES_MASKS:
                _write_png(folder / mask_file_name(mask_name, res), np.broadcast_to(mask, (size * factor,) * 2))
        del gt, masks


def write_benchmark(root: str | Path, scene_set: str = "issue", size: int = 512, scale: int = 10) -> list[Path]:
    """Write the scenes of ``scene_set`` ('issue' or 'full') as ROOT/<category>/<scene>/, ``size`` px square
    at low resolution and ``scale`` x that at high resolution; returns the scene folders."""
    if scene_set not in SCENE_SETS:
        raise ValueError(f"scene_set must be one of {SCENE_SETS}, got {scene_set!r}")
    chosen = _ISSUE if scene_set == "issue" else CATEGORIES
    highres_categories = ("stratified",) if scene_set == "issue" else ("stratified", "training")
    folders = []
    for category, names in chosen.items():
        for name in names:  # a scene is the same in every set (its seed is its name's)
            folder = Path(root) / category / name
            _write_scene(folder, name, category, size, scale, category in highres_categories,
                         seed=zlib.crc32(name.encode()))
            folders.append(folder)
    return folders


def write_submissions(root: str | Path, scenes: Sequence[tuple[str, np.ndarray]], n_methods: int,
                      seed: int = 0) -> list[Path]:
    """``n_methods`` submission folders ROOT/m<k>/ (disp_maps/<scene>.pfm, runtimes/<scene>.txt): each
    scene's low-resolution ground truth (name, (H, W)) plus method k's noise (Gaussian, 0.01-0.05 px, with
    1 % outliers; one method in ten also leaves 0.1 % of its pixels NaN)."""
    folders = []
    for k in range(n_methods):
        rng = np.random.default_rng([seed, k])
        folder = Path(root) / f"m{k:03d}"
        for name, gt in scenes:
            pred = gt + rng.normal(0, 0.01 + 0.01 * (k % 5), gt.shape)
            outliers = rng.random(gt.shape) < 0.01
            pred[outliers] += rng.uniform(-1, 1, int(outliers.sum()))
            if k % 10 == 9:
                pred[rng.random(gt.shape) < 0.001] = np.nan
            write_submission_map(folder, name, pred.astype(np.float32), 0.5 + k / 100)
        folders.append(folder)
    return folders
