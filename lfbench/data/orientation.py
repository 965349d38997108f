"""Which way a dataset's view grid and disparity sign really run, read from its own ground truth.

lfbench reads ``views[v, u]`` as angular row v, column u, with HCI's geometry
``centre(x, y) = view_{v,u}(x - (u - uc) d, y - (v - vc) d)`` (positive d = nearer than the focus plane).
A dataset whose files number the grid the other way (columns first), count a row from the bottom, or give
disparity with the opposite sign still opens and scores, only wrongly. Its ground truth says which: warp
every view onto the centre view by the ground-truth disparity under each of the 8 ways a square grid can be
turned or mirrored (the dihedral group; reversing both axes is the same as negating the disparity), and the
true reading is the one where the views agree with the centre (least photometric error). Pure functions of
arrays; ``lfbench check-dataset`` runs them over a data root.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

__all__ = ["AS_READ", "DECISIVE_RATIO", "ORIENTATIONS", "Orientation", "OrientationCheck", "check_orientation",
           "distinct_readings", "has_centre_view", "orientation_errors", "warp_error"]

#: The best reading must beat every other by this factor (error ratio) for the check to name it.
DECISIVE_RATIO = 1.25
_VIEWS_PER_CALL = 9  # views warped at once (bounds the sampling grid's memory: 9 x H x W x 2 floats)


@dataclass(frozen=True)
class Orientation:
    """One of the 8 readings of a square view grid: first transpose (swap rows and columns), then reverse the
    row order and/or the column order (the order in which lfbench.data.pattern.ViewLayout applies its keys)."""

    name: str
    transpose: bool
    reverse_rows: bool
    reverse_cols: bool

    def apply(self, views: np.ndarray) -> np.ndarray:
        """``views`` (V, U, ...) re-indexed as this reading sees them (a view, no copy)."""
        out = views.swapaxes(0, 1) if self.transpose else views
        if self.reverse_rows:
            out = out[::-1]
        if self.reverse_cols:
            out = out[:, ::-1]
        return out

    @property
    def toml_keys(self) -> dict[str, bool]:
        """The ``[views]`` keys of ``lfbench-dataset.toml`` that read data stored this way as lfbench reads it."""
        keys = {"transpose": self.transpose, "reverse_rows": self.reverse_rows, "reverse_columns": self.reverse_cols}
        return {k: v for k, v in keys.items() if v}

    @property
    def toml_fix(self) -> str:
        """What a TOML dataset sets to be read this way ("" for lfbench's own reading)."""
        said = " and ".join(f"views.{k} = true" for k in self.toml_keys)
        if self.reverse_rows and self.reverse_cols and not self.transpose:
            said += " (or ground_truth.scale = -1: the disparity's sign)"
        return f"set {said}" if said else ""


#: lfbench's reading first; the other 7 named by what the data does differently.
ORIENTATIONS: tuple[Orientation, ...] = (
    Orientation("as read (lfbench's convention)", False, False, False),
    Orientation("disparity sign opposite to HCI's (or both angular axes reversed)", False, True, True),
    Orientation("angular rows numbered bottom to top", False, True, False),
    Orientation("angular columns numbered right to left", False, False, True),
    Orientation("rows and columns swapped (the first index is the column)", True, False, False),
    Orientation("rows and columns swapped, and the disparity sign opposite", True, True, True),
    Orientation("rows and columns swapped, rows numbered bottom to top", True, True, False),
    Orientation("rows and columns swapped, columns numbered right to left", True, False, True),
)
AS_READ = ORIENTATIONS[0]


def has_centre_view(rows: int, cols: int) -> bool:
    """Whether a rows x cols grid has a centre view (odd both ways), which every reading turns the grid about."""
    return rows % 2 == 1 and cols % 2 == 1


def warp_error(gray: np.ndarray, disparity: np.ndarray, *, border_px: int = 0) -> float:
    """Mean absolute difference between the centre view and the views of its row, column and diagonals, warped
    onto it by ``disparity``.

    gray: (V, U, H, W) views in [0, 1], V and U odd; disparity: (H, W) px per view step, the centre view's.
    View (v, u) is sampled (bilinear) at ``(x - (u - uc) d, y - (v - vc) d)``; samples falling outside a view
    and the ``border_px`` frame of the centre are left out. Occlusions add error to every reading alike.
    """
    n_rows, n_cols, h, w = gray.shape
    if not has_centre_view(n_rows, n_cols):
        raise ValueError(f"the view grid must have a centre view (odd size), got {n_rows}x{n_cols}")
    if disparity.shape != (h, w):
        raise ValueError(f"disparity is {disparity.shape}, the views are {h}x{w}")
    vc, uc = n_rows // 2, n_cols // 2
    centre = torch.from_numpy(np.array(gray[vc, uc], dtype=np.float32))
    d = torch.from_numpy(np.array(disparity, dtype=np.float32))
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float32), torch.arange(w, dtype=torch.float32),
                            indexing="ij")
    inner = torch.zeros(h, w, dtype=torch.bool)
    inner[border_px:h - border_px, border_px:w - border_px] = True
    inner &= torch.isfinite(d)
    d = torch.where(inner, d, torch.zeros_like(d))
    # the star through the centre (its row, column and diagonals): every reading maps it onto itself
    others = [(v, u) for v in range(n_rows) for u in range(n_cols) if (v, u) != (vc, uc)
              and (v == vc or u == uc or abs(v - vc) == abs(u - uc))]
    total, count = 0.0, 0
    for start in range(0, len(others), _VIEWS_PER_CALL):
        chunk = others[start:start + _VIEWS_PER_CALL]
        du = torch.tensor([u - uc for _, u in chunk], dtype=torch.float32)[:, None, None]
        dv = torch.tensor([v - vc for v, _ in chunk], dtype=torch.float32)[:, None, None]
        sx, sy = xs - du * d, ys - dv * d  # (n, H, W) sampling positions, px
        valid = inner & (sx >= 0) & (sx <= w - 1) & (sy >= 0) & (sy <= h - 1)
        grid = torch.stack([sx * (2.0 / max(w - 1, 1)) - 1.0, sy * (2.0 / max(h - 1, 1)) - 1.0], dim=-1)
        src = torch.from_numpy(np.stack([np.asarray(gray[v, u], dtype=np.float32) for v, u in chunk]))[:, None]
        warped = F.grid_sample(src, grid, mode="bilinear", padding_mode="zeros", align_corners=True)[:, 0]
        total += float((warped - centre).abs()[valid].sum(dtype=torch.float64))
        count += int(valid.sum())
    return total / count if count else math.nan


def distinct_readings(rows: int, cols: int) -> list[Orientation]:
    """The readings that differ on a rows x cols grid, in :data:`ORIENTATIONS` order: the transposed ones only
    for a square grid, and of readings that order the views alike (on one row of views, reversing the rows
    changes nothing) the first."""
    grid = np.arange(rows * cols).reshape(rows, cols)
    seen: set[bytes] = set()
    readings = []
    for o in ORIENTATIONS:
        if o.transpose and rows != cols:
            continue
        key = np.ascontiguousarray(o.apply(grid)).tobytes()
        if key not in seen:
            seen.add(key)
            readings.append(o)
    return readings


def orientation_errors(gray: np.ndarray, disparity: np.ndarray, *, border_px: int = 0) -> dict[Orientation, float]:
    """:func:`warp_error` under every distinct reading of the grid (:func:`distinct_readings`)."""
    return {o: warp_error(o.apply(gray), disparity, border_px=border_px)
            for o in distinct_readings(gray.shape[0], gray.shape[1])}


@dataclass(frozen=True)
class OrientationCheck:
    """What one scene's ground truth says about the reading of its views."""

    scene: str
    errors: dict[Orientation, float]  # mean absolute error (gray levels in [0, 1]) per reading

    @property
    def ranked(self) -> list[Orientation]:
        """The readings, least error first."""
        return sorted(self.errors, key=lambda o: self.errors[o])

    @property
    def best(self) -> Orientation:
        return self.ranked[0]

    @property
    def runner_up(self) -> Orientation:
        return self.ranked[1]

    @property
    def ratio(self) -> float:
        """The runner-up's error over the best's (>= 1; inf when the best is exact)."""
        first, second = (self.errors[o] for o in self.ranked[:2])
        return math.inf if first == 0 < second else (second / first if first > 0 else 1.0)

    @property
    def decided(self) -> bool:
        """Whether the views tell the readings apart (a scene of almost no disparity or texture does not)."""
        return self.ratio >= DECISIVE_RATIO

    @property
    def agrees(self) -> bool:
        """Decided, and for lfbench's reading."""
        return self.decided and self.best is AS_READ


def check_orientation(name: str, gray: np.ndarray, disparity: np.ndarray, *, border_px: int = 0
                      ) -> OrientationCheck:
    """The reading a scene's ground truth supports (gray: (V, U, H, W); disparity: (H, W))."""
    return OrientationCheck(name, orientation_errors(gray, disparity, border_px=border_px))
