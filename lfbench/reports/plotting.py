"""Drawing with matplotlib (Agg backend) and writing figures and images, for every figure of lfbench
(reports, ablation plots, training curves): :func:`pyplot`, :func:`colormap`, :func:`add_colorbar`,
:func:`save_figure` (PNG), :func:`save_formats` (PNG / PDF / SVG), :func:`write_image` (an RGB array,
one pixel per element), :func:`as_gray`, and the colours a method or an interpolation keeps on every
figure of a report (:func:`method_colours`, :data:`INTERPOLATION_COLOURS`).

Files are written atomically (lfbench.utils.atomic) and carry no metadata link (PNG 'Software', PDF
'Producer' and 'Creator', SVG 'Creator' are left out), so they can go into the offline HTML report.
matplotlib is imported on first use: commands that draw nothing do not pay its start-up (~0.3 s).
"""

from __future__ import annotations

import io
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from PIL import Image

from lfbench.utils.atomic import write_bytes
from lfbench.utils.errors import SpecError

__all__ = ["DPI", "FIGURE_FORMATS", "INTERPOLATION_COLOURS", "LEGEND_WIDTH", "add_colorbar", "as_gray", "colormap",
           "legend_label", "method_colours", "pyplot", "save_figure", "save_formats", "write_image"]

DPI = 90  # of the figures drawn by save_figure unless a caller says otherwise
FIGURE_FORMATS = ("png", "pdf", "svg")
_NO_LINK_METADATA = {"png": {"Software": None}, "pdf": {"Producer": None, "Creator": None}, "svg": {"Creator": None}}
#: The colour of each disparity interpolation on the Table IV figures (plane sweep and ablation plots).
INTERPOLATION_COLOURS = {"bilinear": "tab:blue", "nearest": "tab:orange", "phase": "tab:green"}
#: matplotlib's ten default line colours (tab10, its default cycle), then tab20b's twenty: method colours.
_METHOD_PALETTE = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
                   "#bcbd22", "#17becf",
                   "#393b79", "#5254a3", "#6b6ecf", "#9c9ede", "#637939", "#8ca252", "#b5cf6b", "#cedb9c",
                   "#8c6d31", "#bd9e39", "#e7ba52", "#e7cb94", "#843c39", "#ad494a", "#d6616b", "#e7969c",
                   "#7b4173", "#a55194", "#ce6dbd", "#de9ed6")
LEGEND_WIDTH = 30  # characters per legend line: longer labels wrap instead of running off the figure


def method_colours(labels: Sequence[str]) -> dict[str, str]:
    """One colour per method, by its position in ``labels`` (e.g. the results' methods): matplotlib's ten
    default colours, then tab20b's twenty, then again from the start. Every chart of a report draws a
    method in this colour, so a method is the same colour on the radar and on the BadPix series."""
    return {label: _METHOD_PALETTE[i % len(_METHOD_PALETTE)] for i, label in enumerate(dict.fromkeys(labels))}


def legend_label(label: str, width: int = LEGEND_WIDTH) -> str:
    """``label`` wrapped for a legend: lines of at most ``width`` characters, broken only after a comma or a
    space (a spec's ``key=value`` or a number is never split: ``d_max=2.0`` stays whole, even where it alone is
    longer than ``width``). Every character is kept (a break at a space drops nothing but that space)."""
    lines: list[str] = []
    current = ""
    for token in re.findall(r"[^, ]*[, ]|[^, ]+$", label):  # each with the comma or space that ends it
        if current and len((current + token).rstrip(" ")) > width:
            lines.append(current)
            current = token.lstrip(" ") if not token.isspace() else ""
        else:
            current += token
    lines.append(current)
    return "\n".join(line.rstrip(" ") for line in lines) or label


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def colormap(name: str):
    """The matplotlib colormap ``name`` (a callable of values in [0, 1] to RGBA)."""
    import matplotlib

    return matplotlib.colormaps[name]


def as_gray(image: np.ndarray | None, shape: tuple[int, int]) -> np.ndarray | None:
    """A centre view (H, W[, 3]) in [0, 1] as gray (H, W) float32, or None if absent or mis-shaped."""
    if image is None:
        return None
    img = np.asarray(image, dtype=np.float32)
    if img.ndim == 3:
        img = img[..., :3] @ np.array([0.299, 0.587, 0.114], dtype=np.float32)
    return np.clip(img, 0, 1) if img.shape == shape else None


def add_colorbar(fig: Any, ax: Any, cmap: str, vmin: float, vmax: float, label: str = "") -> None:
    """A colour bar of ``cmap`` over [vmin, vmax] beside ``ax`` (one axes or a list of them)."""
    import matplotlib as mpl

    sm = mpl.cm.ScalarMappable(norm=mpl.colors.Normalize(vmin=vmin, vmax=vmax), cmap=cmap)
    cb = fig.colorbar(sm, ax=ax, fraction=0.046, pad=0.03)
    cb.ax.tick_params(labelsize=7)
    if label:
        cb.set_label(label, fontsize=7)


def _figure_bytes(fig: Any, fmt: str, dpi: int) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi, metadata=_NO_LINK_METADATA[fmt])
    return buf.getvalue()


def save_figure(fig: Any, path: str | Path, dpi: int = DPI) -> Path:
    """Write a matplotlib figure as PNG atomically and close it (no 'Software' metadata)."""
    plt = pyplot()
    try:
        data = _figure_bytes(fig, "png", dpi)
    finally:
        plt.close(fig)
    write_bytes(path, data)
    return Path(path)


def save_formats(fig: Any, path: str | Path, formats: Sequence[str] = ("png",), dpi: int = 110) -> list[Path]:
    """Write ``fig`` as path.<format> for each of png / pdf / svg (atomically) and close it. ``path`` is
    the file name without its format (a trailing .png / .pdf / .svg is replaced; any other dot, as in
    'pairwise_planesweep_interval=0.25', is part of the name)."""
    plt = pyplot()
    unknown = [f for f in formats if f not in FIGURE_FORMATS]
    if unknown or not formats:
        plt.close(fig)
        raise SpecError(f"unknown figure format {', '.join(unknown) or '(none)'}; use {', '.join(FIGURE_FORMATS)}")
    path = Path(path)
    stem = path.with_suffix("") if path.suffix.lstrip(".") in FIGURE_FORMATS else path
    written = []
    try:
        for fmt in dict.fromkeys(formats):
            target = stem.with_name(f"{stem.name}.{fmt}")
            write_bytes(target, _figure_bytes(fig, fmt, dpi))
            written.append(target)
    finally:
        plt.close(fig)
    return written


def write_image(path: str | Path, rgb: np.ndarray) -> Path:
    """Write an (H, W, 3) float RGB array in [0, 1] as a PNG, one pixel per array element (atomic)."""
    arr = np.round(np.clip(np.asarray(rgb, dtype=np.float64), 0, 1) * 255).astype(np.uint8)
    buf = io.BytesIO()
    Image.fromarray(arr, "RGB").save(buf, format="PNG")
    write_bytes(path, buf.getvalue())
    return Path(path)
