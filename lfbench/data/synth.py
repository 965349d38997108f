"""Synthetic light fields with exact ground truth (the embedded default benchmark), written in the layout
:data:`SYNTH_LAYOUT` (HCI's) by that dataset adapter's writer (:meth:`lfbench.data.dataset.Dataset.write_scene`;
:func:`write_scene`, :func:`write_benchmark`).

Geometry is the benchmark's (docs/benchmark-rules.md, Geometry): a surface point with disparity
d (px per view step) seen at centre-view pixel p = (x, y) appears in view (u, v) at ``p - s d`` with
``s = (u - c, v - c)``, ``c = A // 2`` (A x A views, view k at row v = k // A, column u = k % A), so
``centre(x, y) = view_{u,v}(x - s_u d, y - s_v d)`` wherever the point is visible in both.

A scene is a stack of opaque, Lambertian layers. Each layer has
- a surface: disparity as a function of the centre-view position p, either affine
  (fronto-parallel or slanted plane) or quadric (a spherical-cap-like bump/dent or a cylinder),
- a support: where in p the layer exists (whole plane, rotated rectangle, ellipse, thin bar),
- a texture defined on the surface (a band-limited atlas indexed by p), so a point looks the same
  from every view.
A view is rendered by inverse mapping: for every sample x' of view s and every layer, solve
``p - s d(p) = x'`` (closed form for planes, Newton's fixed-point iteration for quadrics), keep the
hit with the largest disparity (z-buffer: closer wins), then look up the winner's texture. The
z-buffer is supersampled 2 x 2 per pixel: a pixel inside one surface takes the texture at its
samples' mean surface point, a pixel across an occlusion edge averages its samples' colours, so
edges and thin structures are anti-aliased. Textures are filtered noise, stripes or checkers
band-limited at sigma >= 1.3 px, so the 8-bit views are smooth enough for sub-pixel matching
(warping a view by the ground truth reproduces the centre view to a median gray error of about
0.003-0.008, as on the real HCI scenes).
Every surface keeps ``|s| |grad d| <= 0.6`` for all views, so the map p -> p - s d(p) is one-to-one
(no surface occludes itself) and the inverse is unique.

The centre-view ground truth is the winner's disparity at each pixel centre: exact, not rendered.
"""

from __future__ import annotations

import math
import os
import shutil
import stat
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage

from lfbench.data.camera import MAX_CAMS, Camera
from lfbench.data.dataset import DATASETS
from lfbench.data.scene import MAX_VIEW_PIXELS, ArrayLightField, rgb_to_gray
from lfbench.utils.atomic import check_replaceable, fresh_dir, replace_dir
from lfbench.utils.errors import DataError, SpecError
from lfbench.utils.flags import SCENE_COUNT, SEED, section_flags
from lfbench.utils.options import Param, option

GENERATOR_VERSION = "1"
SUPERSAMPLE = 2  # samples per pixel along each axis
TEXTURE_STEP = 0.5  # px between texture atlas samples
TEXTURE_BLUR = 1.3  # scale of every texture's Gaussian band limit (1.3 px for sigma = 1)
MAX_SLOPE_SHIFT = 0.6  # bound on |s| * |grad d| over every view s and surface point
_MAX_SAMPLES_PER_CHUNK = 1 << 22  # rendering works on groups of views of at most this many samples
_NEWTON_STEPS = 6
_HIT_TOL = 1e-3  # px: residual of the inverse map accepted as a hit
#: Bounds of the generator's own disparities, px per view step (observed on 320 scenes: [-2.05, 2.27]; by
#: construction the background reaches at most 0.7 / sqrt 2 px below its -1.6, a thin bar 0.2 px above its 2.1).
GENERATOR_DISPARITY_RANGE = (-2.1, 2.31)
MAX_SYNTH_DISPARITY = 3.5  # |d| px: the layers' extent covers every view's border up to this disparity
MASK_NAMES = ("mask_discontinuities", "mask_planes", "mask_smooth_surfaces", "mask_fine", "mask_fine_surrounding",
              "mask_low_texture")


# --------------------------------------------------------------------------- surfaces


@dataclass(frozen=True)
class Affine:
    """Planar surface: d(p) = d0 + gx (x - cx) + gy (y - cy), disparity in px per view step."""

    d0: float
    gx: float
    gy: float
    cx: float
    cy: float

    kind = "plane"

    def disparity(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self.d0 + self.gx * (x - self.cx) + self.gy * (y - self.cy)

    def max_slope(self) -> float:
        """Largest |grad d| (px of disparity per px)."""
        return math.hypot(self.gx, self.gy)

    def remapped(self, scale: float, offset: float) -> Affine:
        """The surface of disparity ``scale * d + offset`` (same position, slope times ``scale``)."""
        return Affine(scale * self.d0 + offset, scale * self.gx, scale * self.gy, self.cx, self.cy)

    def solve(self, x, y, su, sv) -> tuple[np.ndarray, np.ndarray]:
        """p with p - s d(p) = (x, y) (closed form; all arguments broadcast)."""
        # q = p - c; q - s (d0 + g.q) = y0 with y0 = x' - c  ->  q = w + s (g.w) / (1 - g.s), w = y0 + s d0
        wx = x - self.cx + su * self.d0
        wy = y - self.cy + sv * self.d0
        t = (self.gx * wx + self.gy * wy) / (1.0 - (self.gx * su + self.gy * sv))
        return wx + su * t + self.cx, wy + sv * t + self.cy


@dataclass(frozen=True)
class Quadric:
    """Curved surface: d(p) = d0 + h (1 - rho^2 / R^2) for rho <= R, continued as a cone (C1) beyond.

    rho = |p - c| (a paraboloid bump/dent: a sphere-like cap, ``axis`` None) or rho = |n . (p - c)|
    (a cylinder across the unit vector n = ``axis``). h > 0 bulges towards the camera. The linear
    continuation keeps |grad d| <= 2 |h| / R everywhere, so the inverse map has one solution.
    """

    d0: float
    h: float
    radius: float
    cx: float
    cy: float
    axis: tuple[float, float] | None = None

    kind = "smooth"

    def _rho_dir(self, qx, qy):
        if self.axis is None:
            rho = np.sqrt(qx * qx + qy * qy)
            return rho, qx, qy  # grad d = k * (qx, qy) with k below
        nx, ny = self.axis
        w = nx * qx + ny * qy
        return np.abs(w), w * nx, w * ny

    def _eval(self, qx, qy):
        """(d, grad d) at q = p - c."""
        r2 = self.radius * self.radius
        rho, ex, ey = self._rho_dir(qx, qy)
        inside = rho <= self.radius
        d = np.where(inside, self.d0 + self.h * (1.0 - rho * rho / r2),
                     self.d0 - 2.0 * self.h * (rho - self.radius) / self.radius)
        k = (-2.0 * self.h / r2) * np.where(inside, 1.0, self.radius / np.maximum(rho, 1e-12))
        return d, k * ex, k * ey

    def disparity(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        return self._eval(x - self.cx, y - self.cy)[0]

    def remapped(self, scale: float, offset: float) -> Quadric:
        """The surface of disparity ``scale * d + offset`` (same footprint, height times ``scale``)."""
        return Quadric(scale * self.d0 + offset, scale * self.h, self.radius, self.cx, self.cy, self.axis)

    def max_slope(self) -> float:
        return 2.0 * abs(self.h) / self.radius

    def solve(self, x, y, su, sv) -> tuple[np.ndarray, np.ndarray]:
        """p with p - s d(p) = (x, y) by Newton iteration (Sherman-Morrison inverse of I - s grad d^T)."""
        y0x, y0y = x - self.cx, y - self.cy
        d, _, _ = self._eval(y0x, y0y)
        qx, qy = y0x + su * d, y0y + sv * d  # one fixed-point step as the start
        for _ in range(_NEWTON_STEPS):
            d, gx, gy = self._eval(qx, qy)
            rx, ry = qx - su * d - y0x, qy - sv * d - y0y
            den = np.maximum(1.0 - (gx * su + gy * sv), 0.2)
            t = (gx * rx + gy * ry) / den
            qx, qy = qx - rx - su * t, qy - ry - sv * t
        return qx + self.cx, qy + self.cy


Surface = Affine | Quadric


# --------------------------------------------------------------------------- supports


@dataclass(frozen=True)
class Shape:
    """Where a layer exists in centre-view coordinates: 'all', a rotated 'rect' or an 'ellipse'.

    (cx, cy) centre, (a, b) half sizes along the rotated axes, ``angle`` in radians; px.
    """

    kind: str
    cx: float = 0.0
    cy: float = 0.0
    a: float = 0.0
    b: float = 0.0
    angle: float = 0.0

    def contains(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        if self.kind == "all":
            return np.ones(np.broadcast_shapes(np.shape(x), np.shape(y)), dtype=bool)
        c, s = math.cos(self.angle), math.sin(self.angle)
        dx, dy = x - self.cx, y - self.cy
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        if self.kind == "rect":
            return (np.abs(lx) <= self.a) & (np.abs(ly) <= self.b)
        return (lx / self.a) ** 2 + (ly / self.b) ** 2 <= 1.0

    def bbox(self, extent: tuple[float, float, float, float]) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) bounding the support; ``extent`` for the unbounded 'all'."""
        if self.kind == "all":
            return extent
        c, s = abs(math.cos(self.angle)), abs(math.sin(self.angle))
        if self.kind == "rect":
            hx, hy = self.a * c + self.b * s, self.a * s + self.b * c
        else:
            hx = math.hypot(self.a * c, self.b * s)
            hy = math.hypot(self.a * s, self.b * c)
        return self.cx - hx, self.cy - hy, self.cx + hx, self.cy + hy


# --------------------------------------------------------------------------- textures


@dataclass(frozen=True, eq=False)
class Texture:
    """RGB albedo on a surface: bilinear interpolation of ``atlas`` (h, w, 3) float32 in [0, 1] whose
    sample [i, j] sits at centre-view position (x0 + j step, y0 + i step) px. Band-limited by
    construction (filtered well below the pixel Nyquist rate; the atlas is 1 / step times finer)."""

    atlas: np.ndarray
    x0: float
    y0: float
    contrast: float
    step: float = 1.0

    def sample(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(N,) positions in px -> (N, 3) float32 colours (positions outside the atlas are clamped)."""
        h, w, _ = self.atlas.shape
        planes = np.ascontiguousarray(np.moveaxis(self.atlas, -1, 0)).reshape(3, -1)
        n = np.shape(x)[0]
        inv = np.float32(1.0 / self.step)
        return _bilinear(planes, w, (np.asarray(x, np.float32) - np.float32(self.x0)) * inv,
                         (np.asarray(y, np.float32) - np.float32(self.y0)) * inv, np.full(n, w - 1.001, np.float32),
                         np.full(n, h - 1.001, np.float32)).T


def _bilinear(planes: np.ndarray, width: int, fx: np.ndarray, fy: np.ndarray, xmax, ymax) -> np.ndarray:
    """Bilinear lookup in ``planes`` (C, rows * width) at (fx, fy) (N,) clamped to [0, xmax] x [0, ymax].

    Returns (C, N) float32. One np.take per channel and corner: much faster than row gathers.
    """
    fx = np.clip(fx, 0, xmax)
    fy = np.clip(fy, 0, ymax)
    ix, iy = fx.astype(np.int32), fy.astype(np.int32)
    ax, ay = fx - ix, fy - iy
    i00 = iy * width + ix
    i10, i01, i11 = i00 + 1, i00 + width, i00 + width + 1
    out = np.empty((planes.shape[0], fx.shape[0]), dtype=np.float32)
    for c, plane in enumerate(planes):  # 3 colour channels
        top = np.take(plane, i00) * (1 - ax) + np.take(plane, i10) * ax
        bottom = np.take(plane, i01) * (1 - ax) + np.take(plane, i11) * ax
        out[c] = top * (1 - ay) + bottom * ay
    return out


class _PackedAtlas:
    """The texture atlases of all layers stacked into one planar array, so that colouring every
    sample is a single bilinear lookup indexed by the sample's layer (no per-layer masking)."""

    def __init__(self, textures: Sequence[Texture]) -> None:
        steps = {t.step for t in textures}
        if len(steps) != 1:
            raise ValueError("all textures of a scene must share one atlas step")
        self.inv_step = np.float32(1.0 / steps.pop())
        width = max(t.atlas.shape[1] for t in textures)
        rows = np.cumsum([0] + [t.atlas.shape[0] for t in textures])
        canvas = np.zeros((3, int(rows[-1]), width), dtype=np.float32)
        for t, r in zip(textures, rows[:-1], strict=False):
            canvas[:, r:r + t.atlas.shape[0], :t.atlas.shape[1]] = np.moveaxis(t.atlas, -1, 0)
        self.width = width
        self.planes = canvas.reshape(3, -1)
        self.x0 = np.array([t.x0 for t in textures], dtype=np.float32)
        self.y0 = np.array([t.y0 for t in textures], dtype=np.float32)
        self.xmax = np.array([t.atlas.shape[1] - 1.001 for t in textures], dtype=np.float32)
        self.row0 = rows[:-1].astype(np.float32)
        self.ymax = np.array([r + t.atlas.shape[0] - 1.001 for t, r in zip(textures, rows[:-1], strict=False)],
                             dtype=np.float32)

    def sample(self, layer: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Colours (3, N) float32 of layer indices ``layer`` (N,) at surface positions (x, y) (N,) px."""
        fx = (x - np.take(self.x0, layer)) * self.inv_step
        fy = (y - np.take(self.y0, layer)) * self.inv_step + np.take(self.row0, layer)
        fy = np.maximum(fy, np.take(self.row0, layer))
        return _bilinear(self.planes, self.width, fx, fy, np.take(self.xmax, layer), np.take(self.ymax, layer))


def _unit_noise(rng: np.random.Generator, shape: tuple[int, int], sigma: float) -> np.ndarray:
    """Gaussian-filtered white noise (h, w) normalised to zero mean, unit standard deviation."""
    n = ndimage.gaussian_filter(rng.standard_normal(shape), sigma, mode="wrap")
    return (n - n.mean()) / max(float(n.std()), 1e-12)


def make_texture(rng: np.random.Generator, bbox: tuple[float, float, float, float], kind: str, contrast: float,
                 sigma: float = 1.0, shading=None, step: float = TEXTURE_STEP) -> Texture:
    """A band-limited texture atlas covering ``bbox`` (px) with 2 px of margin, sampled every ``step`` px.

    kind: 'noise' (two octaves of filtered noise), 'stripes' (smooth sinusoidal stripes), 'checker'
    (a rotated, smoothed checkerboard), 'flat' (nearly uniform: low texture). ``contrast`` is the
    amplitude of the luminance pattern around a random base colour; ``sigma`` (px) the band limit.
    ``shading(x, y) -> (h, w)`` optionally multiplies the albedo (view-independent, baked in).
    """
    x0, y0 = math.floor(bbox[0]) - 2, math.floor(bbox[1]) - 2
    w = int(math.ceil((math.ceil(bbox[2]) + 2 - x0) / step)) + 1
    h = int(math.ceil((math.ceil(bbox[3]) + 2 - y0) / step)) + 1
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) * step
    xx += x0
    yy += y0
    sigma = sigma * TEXTURE_BLUR / step  # in atlas samples from here on
    theta = rng.uniform(0, np.pi)
    along = xx * math.cos(theta) + yy * math.sin(theta)
    across = -xx * math.sin(theta) + yy * math.cos(theta)
    fine = _unit_noise(rng, (h, w), sigma)
    coarse = _unit_noise(rng, (h, w), 4 * sigma)
    if kind == "noise":
        pattern = 0.75 * fine + 0.65 * coarse
    elif kind == "stripes":
        freq = rng.uniform(0.04, 0.11)  # cycles per px
        pattern = 1.2 * np.sin(2 * np.pi * freq * along + rng.uniform(0, 2 * np.pi)) + 0.3 * fine
    elif kind == "checker":
        period = rng.uniform(5.0, 10.0)
        sq = np.sign(np.sin(np.pi * along / period) * np.sin(np.pi * across / period))
        pattern = ndimage.gaussian_filter(sq, sigma) + 0.25 * fine
    elif kind == "flat":
        pattern = 0.5 * coarse + 0.5 * fine
    else:
        raise ValueError(f"unknown texture kind {kind!r}")
    base = rng.uniform(0.3, 0.7, size=3)
    tint = 1.0 + 0.35 * rng.uniform(-1, 1, size=3)  # the pattern's colour
    chroma = _unit_noise(rng, (h, w), 3 * sigma)[..., None] * rng.uniform(-1, 1, size=3) * 0.25
    rgb = base + contrast * (pattern[..., None] * tint + chroma)
    if shading is not None:
        rgb = rgb * shading(xx, yy)[..., None]
    return Texture(np.clip(rgb, 0.0, 1.0).astype(np.float32), float(x0), float(y0), float(contrast), float(step))


# --------------------------------------------------------------------------- layers


@dataclass(frozen=True, eq=False)
class Layer:
    """One opaque surface patch: surface (disparity), support, texture and its evaluation region.

    region: 'plane' (fronto-parallel or slanted), 'smooth' (curved) or 'fine' (thin structure).
    """

    name: str
    surface: Surface
    shape: Shape
    texture: Texture
    region: str
    bbox: tuple[float, float, float, float]
    disparity_range: tuple[float, float]
    low_texture: bool = False

    def solve(self, x, y, su, sv) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Inverse map at view positions (x, y) of views with offsets (su, sv) (broadcasting).

        Returns (px, py, d, hit): the surface point in centre-view px, its disparity, and whether
        the layer covers that point.
        """
        px, py = self.surface.solve(x, y, su, sv)
        d = self.surface.disparity(px, py)
        hit = self.shape.contains(px, py)
        if isinstance(self.surface, Quadric):  # Newton converged (always, for |s grad d| < 1)
            hit &= (np.abs(px - su * d - x) < _HIT_TOL) & (np.abs(py - sv * d - y) < _HIT_TOL)
        return px, py, d, hit


def _make_layer(name: str, surface: Surface, shape: Shape, texture: Texture, region: str,
                extent: tuple[float, float, float, float], low_texture: bool = False) -> Layer:
    bbox = shape.bbox(extent)
    gx, gy = np.meshgrid(np.linspace(bbox[0], bbox[2], 33), np.linspace(bbox[1], bbox[3], 33))
    inside = shape.contains(gx, gy)
    d = surface.disparity(gx[inside], gy[inside]) if inside.any() else surface.disparity(gx, gy)
    # a layer's disparity range is only used to bound where it can appear: pad it generously
    lo, hi = float(d.min()), float(d.max())
    spacing = max(bbox[2] - bbox[0], bbox[3] - bbox[1]) / 32.0
    pad = 0.05 + surface.max_slope() * 2.0 * spacing  # extremes between grid samples
    return Layer(name, surface, shape, texture, region, bbox, (lo - pad, hi + pad), low_texture)


# --------------------------------------------------------------------------- scene layout


def _slope_cap(c: int) -> float:
    """Largest |grad d| such that |s| |grad d| <= MAX_SLOPE_SHIFT for every view (|s| <= c sqrt 2)."""
    return MAX_SLOPE_SHIFT / (max(c, 1) * math.sqrt(2.0))


def _dome_shading(surface: Quadric, scale: float, light: np.ndarray):
    """Lambertian shading of the disparity relief (height = scale * d), baked into the albedo."""

    def shade(x, y):
        _, gx, gy = surface._eval(x - surface.cx, y - surface.cy)
        n = np.stack([-scale * gx, -scale * gy, np.ones_like(gx)], axis=-1)
        n /= np.linalg.norm(n, axis=-1, keepdims=True)
        return 0.55 + 0.45 * np.clip(n @ light, 0.0, 1.0)

    return shade


def disparity_map(disparity_range: tuple[float, float] | None) -> tuple[float, float] | None:
    """(scale, offset) of the map d -> scale * d + offset taking :data:`GENERATOR_DISPARITY_RANGE` onto
    ``disparity_range`` (min, max) px, or None for None (the generator's own disparities). SpecError for a
    range that is not finite, min >= max, wider than the generator's own (its slopes would fold a surface
    over itself) or beyond +-:data:`MAX_SYNTH_DISPARITY` (views would show past the background)."""
    if disparity_range is None:
        return None
    lo, hi = (float(v) for v in disparity_range)
    g_lo, g_hi = GENERATOR_DISPARITY_RANGE
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise SpecError(f"disparity range must be finite LOW < HIGH px, got [{lo:g}, {hi:g}]")
    if hi - lo > g_hi - g_lo + 1e-9 or max(abs(lo), abs(hi)) > MAX_SYNTH_DISPARITY:
        raise SpecError(f"disparity range [{lo:g}, {hi:g}] px: the generator writes spans of at most "
                        f"{g_hi - g_lo:g} px within [-{MAX_SYNTH_DISPARITY:g}, {MAX_SYNTH_DISPARITY:g}]")
    scale = (hi - lo) / (g_hi - g_lo)
    return scale, lo - scale * g_lo


def layout_scene(rng: np.random.Generator, size: int, angular: int,
                 remap: tuple[float, float] | None = None) -> list[Layer]:
    """The layers of one random scene (positions in px of a size x size centre view).

    Far to near: a gently slanted background plane, a large fronto-parallel textured wall, then a
    low-texture panel, a slanted plane, a bump (sphere-like cap), a dent or a cylinder and a front
    block, each in its own cell of a jittered 3 x 3 grid (neighbours may overlap: occlusions), and
    2-3 thin bars across the image (nearest). Disparities stay within :data:`GENERATOR_DISPARITY_RANGE`;
    ``remap`` (scale, offset) (:func:`disparity_map`) moves every surface to ``scale * d + offset`` (the
    same layout, textures and random draws; a scale <= 1 keeps every surface one-to-one).
    """
    s = float(size)
    c = angular // 2
    cap = _slope_cap(c)
    margin = c * 3.5 + 4.0
    extent = (-margin, -margin, s - 1 + margin, s - 1 + margin)
    mid = (s - 1) / 2
    cells = iter(rng.permutation(9)[:5])
    layers: list[Layer] = []

    def cell_pos() -> tuple[float, float]:
        k = int(next(cells))
        jitter = rng.uniform(-0.05, 0.05, size=2)
        return float((0.2 + 0.3 * (k % 3) + jitter[0]) * s), float((0.2 + 0.3 * (k // 3) + jitter[1]) * s)

    def slope(variation: float, extent_px: float) -> tuple[float, float]:
        """A gradient of random direction changing d by ``variation`` px over ``extent_px`` (capped)."""
        mag = min(variation / max(extent_px, 1.0), 0.9 * cap)
        phi = rng.uniform(0, 2 * np.pi)
        return mag * math.cos(phi), mag * math.sin(phi)

    def add(name, surface, shape, kind, contrast, region="plane", sigma=1.0, shading=None, low=False):
        tex = make_texture(rng, shape.bbox(extent), kind, contrast, sigma=sigma, shading=shading)
        if remap is not None:
            surface = surface.remapped(*remap)
        layers.append(_make_layer(name, surface, shape, tex, region, extent, low_texture=low))

    # background: a gently slanted far plane covering every view
    gx, gy = slope(rng.uniform(0.3, 0.7), s)
    add("background", Affine(rng.uniform(-1.6, -1.3), gx, gy, mid, mid), Shape("all"),
        str(rng.choice(["noise", "checker"])), rng.uniform(0.12, 0.22), sigma=1.1)

    # fronto-parallel wall, well textured (high contrast)
    cx, cy = (float(v) for v in rng.uniform(0.35, 0.65, size=2) * s)
    add("wall", Affine(rng.uniform(-0.9, -0.6), 0.0, 0.0, cx, cy),
        Shape("rect", cx, cy, rng.uniform(0.2, 0.3) * s, rng.uniform(0.2, 0.3) * s, rng.uniform(-0.4, 0.4)),
        str(rng.choice(["checker", "stripes", "noise"])), rng.uniform(0.3, 0.45))

    # low-texture fronto-parallel panel
    cx, cy = cell_pos()
    add("low_texture_panel", Affine(rng.uniform(-0.4, 0.0), 0.0, 0.0, cx, cy),
        Shape("ellipse", cx, cy, rng.uniform(0.11, 0.16) * s, rng.uniform(0.09, 0.14) * s, rng.uniform(0, np.pi)),
        "flat", rng.uniform(0.008, 0.015), sigma=1.5, low=True)

    # slanted plane
    cx, cy = cell_pos()
    a, b = rng.uniform(0.1, 0.16) * s, rng.uniform(0.08, 0.13) * s
    gx, gy = slope(rng.uniform(0.8, 1.4), 2 * max(a, b))
    add("slanted_plane", Affine(rng.uniform(0.1, 0.6), gx, gy, cx, cy),
        Shape("rect", cx, cy, a, b, rng.uniform(0, np.pi)), str(rng.choice(["noise", "stripes"])),
        rng.uniform(0.15, 0.3))

    light = np.array([-0.4, -0.5, 0.77])
    light /= np.linalg.norm(light)

    def quadric(name: str, h_sign: float, axis) -> None:
        cx, cy = cell_pos()
        radius = rng.uniform(0.1, 0.15) * s
        h = h_sign * rng.uniform(0.6, 1.0) * min(1.2, radius * cap / 2.0)  # 2 |h| / R <= cap
        surf = Quadric(rng.uniform(0.2, 0.8), h, radius, cx, cy, axis)
        if axis is None:
            shape = Shape("ellipse", cx, cy, radius, radius)
        else:
            shape = Shape("rect", cx, cy, radius, rng.uniform(0.1, 0.16) * s, math.atan2(axis[1], axis[0]))
        add(name, surf, shape, str(rng.choice(["noise", "checker"])), rng.uniform(0.12, 0.3), region="smooth",
            shading=_dome_shading(surf, s / 6.0, light))

    quadric("bump", 1.0, None)
    if rng.uniform() < 0.5:
        quadric("dent", -1.0, None)
    else:
        phi = rng.uniform(0, np.pi)
        quadric("cylinder", 1.0, (math.cos(phi), math.sin(phi)))

    # a front block: a large near occluder
    cx, cy = cell_pos()
    add("front_block", Affine(rng.uniform(1.2, 1.6), 0.0, 0.0, cx, cy),
        Shape("rect", cx, cy, rng.uniform(0.05, 0.09) * s, rng.uniform(0.05, 0.09) * s, rng.uniform(0, np.pi)),
        str(rng.choice(["checker", "noise"])), rng.uniform(0.25, 0.4))

    # thin bars (fine structures, 1-2 px wide), nearest
    for i in range(int(rng.integers(2, 4))):
        cx, cy = (float(v) for v in rng.uniform(0.3, 0.7, size=2) * s)
        half_len = rng.uniform(0.25, 0.45) * s
        gx, gy = slope(rng.uniform(0.0, 0.4), 2 * half_len)
        add(f"bar{i}", Affine(rng.uniform(1.7, 2.1), gx, gy, cx, cy),
            Shape("rect", cx, cy, half_len, rng.uniform(0.5, 0.9), rng.uniform(0, np.pi)),
            "noise", rng.uniform(0.08, 0.15), region="fine", sigma=1.5)
    return layers


# --------------------------------------------------------------------------- rendering


def view_offsets(angular: int) -> tuple[np.ndarray, np.ndarray]:
    """(su, sv) float32 (A*A,): offsets (u - c, v - c) of view k = v * A + u."""
    c = angular // 2
    k = np.arange(angular * angular)
    return (k % angular - c).astype(np.float32), (k // angular - c).astype(np.float32)


def trace_points(layers: Sequence[Layer], x: np.ndarray, y: np.ndarray, su: np.ndarray, sv: np.ndarray):
    """Z-buffer at arbitrary points: (x, y) positions in views with offsets (su, sv), all (N,).

    Returns (layer index int16 (N,), -1 where nothing is hit; disparity, px, py float (N,)).
    """
    n = x.shape[0]
    lid = np.full(n, -1, dtype=np.int16)
    zbuf = np.full(n, -np.inf, dtype=np.float64)
    px = np.full(n, np.nan)
    py = np.full(n, np.nan)
    for i, layer in enumerate(layers):
        lo, hi = layer.disparity_range
        x0, y0, x1, y1 = layer.bbox
        # the layer can only be hit where p = x' + s d lands in its bbox for some d in [lo, hi]
        ax, bx = su * lo, su * hi
        ay, by = sv * lo, sv * hi
        cand = ((x + np.minimum(ax, bx) <= x1) & (x + np.maximum(ax, bx) >= x0)
                & (y + np.minimum(ay, by) <= y1) & (y + np.maximum(ay, by) >= y0))
        idx = np.flatnonzero(cand)
        if idx.size == 0:
            continue
        qx, qy, d, hit = layer.solve(x[idx].astype(np.float64), y[idx].astype(np.float64),
                                     su[idx].astype(np.float64), sv[idx].astype(np.float64))
        win = hit & (d > zbuf[idx])
        sel = idx[win]
        lid[sel] = i
        zbuf[sel] = d[win]
        px[sel] = qx[win]
        py[sel] = qy[win]
    return lid, zbuf, px, py


def _axis_slice(coords: np.ndarray, lo: float, hi: float) -> slice:
    return slice(int(np.searchsorted(coords, lo, "left")), int(np.searchsorted(coords, hi, "right")))


def _shade_pixels(atlas: _PackedAtlas, lid: np.ndarray, px: np.ndarray, py: np.ndarray, size: int,
                  ss: int) -> np.ndarray:
    """Pixel colours (M, H, W, 3) from the z-buffer samples (M, H*ss, W*ss) of M views.

    A pixel whose ss x ss samples all hit one layer takes the texture at the mean of their surface
    points (the surface point of the pixel centre); a pixel straddling an occlusion edge averages
    the colours of its samples (area coverage: anti-aliased edges and thin structures).
    """
    m = lid.shape[0]
    blocks = (m, size, ss, size, ss)
    lid5, px5, py5 = lid.reshape(blocks), px.reshape(blocks), py.reshape(blocks)
    first = lid5[:, :, 0, :, 0]
    mixed = np.zeros(first.shape, dtype=bool)
    sx = np.zeros(first.shape, dtype=np.float32)
    sy = np.zeros(first.shape, dtype=np.float32)
    for j in range(ss):  # ss x ss strided views, not a per-pixel loop
        for i in range(ss):
            mixed |= lid5[:, :, j, :, i] != first
            sx += px5[:, :, j, :, i]
            sy += py5[:, :, j, :, i]
    scale = np.float32(1.0 / (ss * ss))
    rgb = atlas.sample(first.ravel(), sx.ravel() * scale, sy.ravel() * scale)  # (3, M*H*W)
    where = np.flatnonzero(mixed.ravel())
    if where.size:
        pm, ym, xm = np.unravel_index(where, first.shape)
        sub_l = lid5[pm, ym, :, xm, :].ravel()  # (n, ss, ss) -> samples of the mixed pixels
        sub_x = px5[pm, ym, :, xm, :].ravel()
        sub_y = py5[pm, ym, :, xm, :].ravel()
        rgb[:, where] = atlas.sample(sub_l, sub_x, sub_y).reshape(3, where.size, ss * ss).mean(axis=2)
    return np.moveaxis(rgb.reshape(3, m, size, size), 0, -1)


def render_views(layers: Sequence[Layer], size: int, angular: int, supersample: int = SUPERSAMPLE) -> np.ndarray:
    """All views (A*A, H, W, 3) float32 RGB in [0, 1], H = W = size, by inverse mapping per layer.

    Each pixel is the mean of ``supersample``^2 point samples. Views are processed in groups that
    keep at most 2^22 samples in memory at once.
    """
    ss = supersample
    hs = size * ss
    coords = ((np.arange(hs, dtype=np.float32) + 0.5) / ss - 0.5).astype(np.float32)
    su_all, sv_all = view_offsets(angular)
    nv = su_all.size
    per_chunk = max(1, _MAX_SAMPLES_PER_CHUNK // (hs * hs))
    out = np.empty((nv, size, size, 3), dtype=np.float32)
    atlas = _PackedAtlas([layer.texture for layer in layers])
    for start in range(0, nv, per_chunk):
        su = su_all[start:start + per_chunk, None, None]
        sv = sv_all[start:start + per_chunk, None, None]
        m = su.shape[0]
        zbuf = np.full((m, hs, hs), -np.inf, dtype=np.float32)
        lid = np.full((m, hs, hs), -1, dtype=np.int16)
        pxb = np.zeros((m, hs, hs), dtype=np.float32)
        pyb = np.zeros((m, hs, hs), dtype=np.float32)
        shift = float(max(np.abs(su).max(), np.abs(sv).max()))
        for i, layer in enumerate(layers):
            lo, hi = layer.disparity_range
            reach = shift * max(abs(lo), abs(hi))
            x0, y0, x1, y1 = layer.bbox
            cx, cy = _axis_slice(coords, x0 - reach, x1 + reach), _axis_slice(coords, y0 - reach, y1 + reach)
            if cx.stop <= cx.start or cy.stop <= cy.start:
                continue
            px, py, d, hit = layer.solve(coords[None, None, cx], coords[None, cy, None], su, sv)
            z = zbuf[:, cy, cx]
            win = hit & (d > z)
            np.copyto(z, d, where=win, casting="same_kind")
            np.copyto(lid[:, cy, cx], np.int16(i), where=win)
            np.copyto(pxb[:, cy, cx], px, where=win, casting="same_kind")
            np.copyto(pyb[:, cy, cx], py, where=win, casting="same_kind")
        if (lid < 0).any():  # the background covers every view by construction
            raise RuntimeError("synthetic renderer: a sample hit no layer")
        out[start:start + m] = _shade_pixels(atlas, lid, pxb, pyb, size, ss)
    return out


# --------------------------------------------------------------------------- masks


def _disk(radius: int) -> np.ndarray:
    r = np.arange(-radius, radius + 1)
    return (r[:, None] ** 2 + r[None, :] ** 2) <= radius * radius


def evaluation_masks(layers: Sequence[Layer], layer_id: np.ndarray, disparity: np.ndarray,
                     jump: float = 0.02) -> dict[str, np.ndarray]:
    """Region masks (H, W) bool of the centre view, named like the benchmark's mask files.

    mask_discontinuities: pixels within r px (r = max(1, round(size / 64))) of an occlusion edge,
    i.e. 8-neighbours on different layers whose disparities differ by more than ``jump`` px;
    mask_planes / mask_smooth_surfaces: planar / curved layers away from discontinuities;
    mask_fine: thin-bar pixels; mask_fine_surrounding: pixels within 2 r px of a thin bar, not on one;
    mask_low_texture: the low-texture layer away from discontinuities.
    """
    h, w = disparity.shape
    r = max(1, round(max(h, w) / 64))
    edge = np.zeros((h, w), dtype=bool)
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        a = (slice(0, h - dy), slice(max(0, -dx), w - max(0, dx)))
        b = (slice(dy, h), slice(max(0, dx), w - max(0, -dx)))
        e = (layer_id[a] != layer_id[b]) & (np.abs(disparity[a] - disparity[b]) > jump)
        edge[a] |= e
        edge[b] |= e
    disc = ndimage.binary_dilation(edge, _disk(r))
    region = np.array([layer.region for layer in layers])[layer_id]
    low = np.array([layer.low_texture for layer in layers])[layer_id]
    fine = region == "fine"
    return {
        "mask_discontinuities": disc,
        "mask_planes": (region == "plane") & ~disc,
        "mask_smooth_surfaces": (region == "smooth") & ~disc,
        "mask_fine": fine,
        "mask_fine_surrounding": ndimage.binary_dilation(fine, _disk(2 * r)) & ~fine,
        "mask_low_texture": low & ~disc,
    }


# --------------------------------------------------------------------------- scenes


def scene_parameters(size: int, angular: int, disparity: np.ndarray, name: str, category: str,
                     seed: int) -> Camera:
    """A camera consistent with the HCI scenes: f = 100 mm, sensor 35 mm, focus at 7 m, and a baseline
    scaled so that b f N / s (the disparity factor) equals the 512 px HCI cameras' at any size N."""
    lo, hi = float(np.min(disparity)), float(np.max(disparity))
    return Camera(
        focal_length_mm=100.0, image_resolution_x_px=size, image_resolution_y_px=size, sensor_size_mm=35.0,
        num_cams_x=angular, num_cams_y=angular, baseline_mm=100.0 * 512.0 / size, focus_distance_m=7.0,
        disp_min=math.floor(lo * 10) / 10, disp_max=math.ceil(hi * 10) / 10, depth_map_scale=10.0,
        name=name, category=category,
        extra={"meta": {"generator": f"lfbench.data.synth v{GENERATOR_VERSION}", "synth_seed": str(seed)}},
    )


@dataclass
class SyntheticScene:
    """A generated light field with exact ground truth.

    views: (V, U, H, W, 3) float32 RGB in [0, 1] (views[v, u] = view k = v * U + u);
    disparity: (H, W) float32 centre-view disparity in px per view step; depth: (H, W) float32 in m
    (from ``params``); layer_id: (H, W) int16 index into ``layers`` at each pixel centre;
    masks: name -> (H, W) bool (the scene's evaluation masks). ``visibility()`` (computed on first use):
    (V, U, H, W) bool, True where the centre pixel's surface point is seen in view (u, v).
    """

    name: str
    category: str
    seed: int
    views: np.ndarray
    disparity: np.ndarray
    depth: np.ndarray
    layer_id: np.ndarray
    masks: dict[str, np.ndarray]
    params: Camera
    layers: list[Layer] = field(repr=False)
    #: where the views lie in the square frame the scene was rendered in: (y0, x0, side) of a crop (:meth:`crop`;
    #: side 0: the views are the frame)
    window: tuple[int, int, int] = (0, 0, 0)
    _visibility: np.ndarray | None = field(default=None, init=False, repr=False, compare=False)

    def visibility(self) -> np.ndarray:
        """(V, U, H, W) bool: the centre pixel's surface point is seen in view (u, v) (not occluded by a
        nearer layer, inside the image); traced through the same z-buffer as the renderer."""
        if self._visibility is None:
            v, u, h, w = self.views.shape[:4]
            y0, x0, side = self.window
            yy, xx = np.mgrid[y0:y0 + h, x0:x0 + w]
            vis = _visibility(self.layers, xx.ravel().astype(np.float64), yy.ravel().astype(np.float64),
                              self.layer_id.ravel(), self.disparity.ravel().astype(np.float64), u, side or max(h, w))
            self._visibility = vis.reshape(v, u, h, w)
        return self._visibility

    def crop(self, width: int, height: int) -> SyntheticScene:
        """The centre ``height`` x ``width`` px of this (square) scene: the same window of every view, so the
        disparity between views is unchanged and the ground truth stays exact. Its camera has the window's
        resolution and the same pixel pitch (the sensor spans the larger side, which a crop to the frame's side
        along one axis keeps). The scene itself when the window is the whole frame."""
        side = self.disparity.shape[0]
        if (width, height) == (side, side):
            return self
        if not (0 < width <= side and 0 < height <= side and max(width, height) == side):
            raise SpecError(f"cannot crop a {side} px square scene to {width}x{height} px: one side must be {side}")
        y0, x0 = (side - height) // 2, (side - width) // 2
        win = (slice(y0, y0 + height), slice(x0, x0 + width))
        return replace(self, views=self.views[:, :, win[0], win[1]], disparity=self.disparity[win],
                       depth=self.depth[win], layer_id=self.layer_id[win],
                       masks={name: mask[win] for name, mask in self.masks.items()},
                       params=replace(self.params, image_resolution_x_px=width, image_resolution_y_px=height),
                       window=(y0, x0, side))

    def gray_views(self) -> np.ndarray:
        """(V, U, H, W) float32 gray (the benchmark's weights)."""
        return rgb_to_gray(self.views)

    def to_light_field(self) -> ArrayLightField:
        """In-memory light field (gray views, ground truth) for methods."""
        return ArrayLightField(views=self.gray_views(), name=self.name, gt=self.disparity)


def plane_views(disparity: float, size: int, angular: int = 9, seed: int = 0) -> np.ndarray:
    """(A, A, size, size) float32 gray views in [0, 1] of one textured fronto-parallel plane at ``disparity``
    px per view step covering every view, rendered as every scene is (a point of the centre view at (x, y)
    appears in view (u, v) at (x - (u - c) d, y - (v - c) d)): a scene whose ground truth is ``disparity``
    everywhere (``lfbench check-plugin`` checks a network's sign on two of them)."""
    check_args(size, angular)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(size), int(angular), 7]))
    margin = (angular // 2) * (abs(float(disparity)) + 1.0) + 4.0
    extent = (-margin, -margin, size - 1 + margin, size - 1 + margin)
    mid = (size - 1) / 2
    texture = make_texture(rng, extent, "noise", 0.35)
    layer = _make_layer("plane", Affine(float(disparity), 0.0, 0.0, mid, mid), Shape("all"), texture, "plane", extent)
    views = render_views([layer], size, angular)
    return rgb_to_gray(views.reshape(angular, angular, size, size, 3))


MAX_SYNTH_SIZE = 4096  # px per side of a generated view
#: The dataset adapter (lfbench.data.dataset.DATASETS) that reads what :func:`write_benchmark` writes.
SYNTH_LAYOUT = "hci"
#: The side and the angular resolution of generated views, declared once: ``lfbench demo --size`` and ``lfbench
#: synth --angular`` read and check them at parse time, :func:`check_args` from Python (the seed and the number
#: of scenes are the shared flags lfbench.utils.flags.SEED and SCENE_COUNT).
@dataclass(frozen=True, kw_only=True)
class SynthFlags:
    """The sizes of generated views, as ``lfbench synth`` and ``lfbench demo`` take them."""

    size: int = option(128, help="scene width and height in px", low=16, high=MAX_SYNTH_SIZE, metavar="S")
    angular: int = option(9, help="A x A views, odd (3: the centre view and its neighbours)", low=3, high=MAX_CAMS,
                          metavar="A")


SYNTH_SIZE, ANGULAR = section_flags(SynthFlags).values()


def require(param: Param, value: Any) -> Any:
    """``value`` checked as ``param`` declares it (a numpy integer taken as an int); SpecError ``size: must be in
    [16, 4096], got 8`` otherwise."""
    problem = param.problem(int(value) if isinstance(value, np.integer) else value)
    if problem:
        raise SpecError(f"{param.name}: {problem}")
    return value


def check_args(size: int, angular: int = 9) -> None:
    """SpecError for sizes outside the bounds, before anything is allocated."""
    require(SYNTH_SIZE, size)
    require(ANGULAR, angular)
    if angular % 2 == 0:
        raise SpecError(f"angular: must be odd (a centre view), got {angular}")
    if size * size * angular * angular > MAX_VIEW_PIXELS:
        raise SpecError(f"{angular}x{angular} views of {size}x{size} px is more than lfbench reads "
                        f"({MAX_VIEW_PIXELS} px): use a smaller size or angular resolution")


def _visibility(layers: Sequence[Layer], x: np.ndarray, y: np.ndarray, lid: np.ndarray, disp: np.ndarray,
                angular: int, size: int) -> np.ndarray:
    """(A*A, N) bool: centre points (x, y) (N,) on layers ``lid`` with disparity ``disp`` traced into
    every view; visible where the same surface point wins the z-buffer there, inside the image."""
    su_all, sv_all = view_offsets(angular)
    out = np.empty((su_all.size, x.size), dtype=bool)
    per_chunk = max(1, _MAX_SAMPLES_PER_CHUNK // (4 * x.size))
    for start in range(0, su_all.size, per_chunk):
        su, sv = su_all[start:start + per_chunk, None], sv_all[start:start + per_chunk, None]
        vx, vy = x[None] - su * disp[None], y[None] - sv * disp[None]
        shape = vx.shape
        vlid, _, px, py = trace_points(layers, vx.ravel(), vy.ravel(), np.broadcast_to(su, shape).ravel(),
                                       np.broadcast_to(sv, shape).ravel())
        same = ((vlid.reshape(shape) == lid[None]) & (np.abs(px.reshape(shape) - x[None]) < _HIT_TOL)
                & (np.abs(py.reshape(shape) - y[None]) < _HIT_TOL))
        inside = (vx >= -0.5) & (vx <= size - 0.5) & (vy >= -0.5) & (vy <= size - 0.5)
        out[start:start + su.shape[0]] = same & inside
    return out


def generate_scene(seed: int, size: int = 128, angular: int = 9, name: str | None = None,
                   category: str = "synthetic", *, disparity_range: tuple[float, float] | None = None
                   ) -> SyntheticScene:
    """Generate one scene, deterministic in (seed, size, angular); ``size`` px square, A x A views.
    ``disparity_range``: (min, max) px the scene's disparities are mapped into (the same layout at other
    depths: :func:`disparity_map`); None: the generator's own (about [-2.1, 2.3] px)."""
    check_args(size, angular)
    remap = disparity_map(disparity_range)
    name = name or f"synth_{seed}"
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(size), int(angular)]))
    layers = layout_scene(rng, size, angular, remap)
    views = render_views(layers, size, angular)
    views = views.reshape(angular, angular, size, size, 3)

    # exact ground truth: the winning layer at each centre-view pixel centre (s = 0: p = x)
    yy, xx = np.mgrid[0:size, 0:size]
    xf, yf = xx.ravel().astype(np.float64), yy.ravel().astype(np.float64)
    zero = np.zeros_like(xf)
    lid, disp, _, _ = trace_points(layers, xf, yf, zero, zero)
    layer_id = lid.reshape(size, size)
    disparity = disp.reshape(size, size)


    params = scene_parameters(size, angular, disparity, name, category, seed)
    depth = params.disparity_to_depth(disparity).astype(np.float32)
    masks = evaluation_masks(layers, layer_id, disparity)
    return SyntheticScene(name=name, category=category, seed=int(seed), views=views,
                          disparity=disparity.astype(np.float32), depth=depth, layer_id=layer_id,
                          masks=masks, params=params, layers=layers)


# --------------------------------------------------------------------------- writing


def quantize(views: np.ndarray) -> np.ndarray:
    """Float views in [0, 1] -> uint8 as written to the PNGs (round to nearest)."""
    return np.round(np.clip(views, 0.0, 1.0) * 255.0).astype(np.uint8)


def write_scene(scene: SyntheticScene, folder: str | Path, layout: str = SYNTH_LAYOUT) -> Path:
    """Write ``scene`` into ``folder`` (created) in the layout of dataset adapter ``layout`` (default
    :data:`SYNTH_LAYOUT`), by that adapter's writer (:meth:`lfbench.data.dataset.Dataset.write_scene`; HCI's writes
    each file atomically: its views quantized by :func:`quantize`, parameters, ground-truth disparity and depth,
    and masks)."""
    return DATASETS.get(layout).write_scene(Path(folder), scene)


def scene_name(seed: int, index: int) -> str:
    """The name (folder) of scene ``index`` of the set generated with ``seed``: ``synth_<seed>_<index>``."""
    return f"synth_{seed}_{index}"


def scene_seed(seed: int, index: int) -> int:
    """The seed of scene ``index`` of a benchmark generated with ``seed`` (independent streams)."""
    return int(np.random.SeedSequence([int(seed), int(index)]).generate_state(1, np.uint32)[0])


def _write_scene(target: Path, seed: int, size: int | tuple[int, int], angular: int, layout: str,
                 disparity_range: tuple[float, float] | None = None) -> Path:
    """Generate one scene (its category: the folder above ``target``; ``size``: S or (W, H), generated square
    at max(W, H) and cropped to the centre, :meth:`SyntheticScene.crop`) and write it as ``target`` in the
    layout of dataset adapter ``layout`` (written beside it, renamed into place when complete; an existing
    ``target`` is swapped out only after the new one is whole)."""
    width, height = size if isinstance(size, tuple | list) else (size, size)
    scene = generate_scene(seed, size=max(width, height), angular=angular, name=target.name,
                           category=target.parent.name, disparity_range=disparity_range).crop(width, height)
    target.parent.mkdir(parents=True, exist_ok=True)
    tmp = fresh_dir(target.parent, f".{target.name}.", ".tmp")
    try:
        write_scene(scene, tmp, layout)
        replace_dir(tmp, target)  # an existing target only with force
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return target


def _write_one(job: tuple) -> Path:
    """One scene of :func:`write_scenes` (a pool item)."""
    return _write_scene(*job)


def write_scenes(targets: Sequence[Path], seeds: Sequence[int], *, size: int | tuple[int, int], angular: int,
                 layout: str = SYNTH_LAYOUT, disparity_range: tuple[float, float] | None = None, workers: int = 1,
                 progress: bool = False) -> list[Path]:
    """Generate scene k from ``seeds[k]`` and write it as ``targets[k]`` (its category: the folder above) in the
    layout of dataset adapter ``layout`` (its :meth:`lfbench.data.dataset.Dataset.write_scene`), the views S x S
    px (``size`` S) or W x H px (``size`` (W, H): rendered square at max(W, H), the centre cropped), and return
    ``targets``. ``workers`` > 1 writes that many scenes at a time in worker processes (lfbench's one pool,
    lfbench.utils.executor.ProcessPool, spawned, without torch); each scene depends only on its own seed,
    so the files are the same for any number."""
    from tqdm import tqdm

    from lfbench.utils.executor import ClusterOptions, ProcessPool

    jobs = [(Path(t), seed, size, angular, layout, disparity_range) for t, seed in zip(targets, seeds, strict=True)]
    bar = tqdm(total=len(jobs), desc="synth", unit="scene", disable=not progress)
    try:
        ProcessPool(ClusterOptions("pool"), jobs=min(int(workers), max(len(jobs), 1))).map(
            _write_one, jobs, labels=[str(job[0]) for job in jobs], threads=None, on_done=lambda _: bar.update())
    finally:
        bar.close()
    return [job[0] for job in jobs]


def write_benchmark(out: str | Path, seed: int = 0, size: int = 128, scenes: int = 4,
                    category: str | Sequence[str] = "synthetic", angular: int = 9, force: bool = False,
                    progress: bool = False, workers: int = 1,
                    disparity_range: tuple[float, float] | None = None) -> list[Path]:
    """Write ``scenes`` scenes as OUT/<category>/synth_<seed>_<i>/ and return their folders.

    ``category`` is one name for all scenes or one per scene. Each scene is written into a temporary
    folder beside its destination and renamed into place when complete, so an interrupted run
    leaves no half-written scene. An existing scene folder is an error unless ``force``; all
    destinations are checked before anything is generated. ``workers`` > 1 generates that many scenes
    at a time in separate processes (:func:`write_scenes`); each scene depends only on its own seed, so the
    files are the same. ``disparity_range``: (min, max) px the disparities are mapped into
    (:func:`generate_scene`; None: the generator's own).
    """
    check_args(size, angular)
    disparity_map(disparity_range)  # SpecError for an impossible range, before anything is written
    require(SEED, seed)
    require(SCENE_COUNT, scenes)
    if int(workers) != workers or workers < 1:
        raise SpecError(f"workers must be a positive integer, got {workers}")
    cats = [category] * scenes if isinstance(category, str) else list(category)
    if len(cats) != scenes:
        raise SpecError(f"{len(cats)} categories given for {scenes} scenes")
    for cat in cats:
        if not cat or cat in (".", "..") or "/" in cat or "\\" in cat:
            raise SpecError(f"invalid category name {cat!r}")
    out = Path(out)
    targets = [out / cat / scene_name(seed, i) for i, cat in enumerate(cats)]
    for t in targets:
        if not force and os.path.lexists(t):
            raise DataError("scene folder already exists (use --force to overwrite)", t)
        if os.path.lexists(t) and not stat.S_ISDIR(os.lstat(t).st_mode):  # --force replaces scene folders only
            check_replaceable(t)  # a device, FIFO or socket is refused; a file or link is replaced
    return write_scenes(targets, [scene_seed(seed, i) for i in range(scenes)], size=size, angular=angular,
                        disparity_range=disparity_range, workers=workers, progress=progress)
