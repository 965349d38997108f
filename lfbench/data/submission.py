"""The benchmark's submission format: ``disp_maps/<scene>.pfm`` and ``runtimes/<scene>.txt``.

A disparity map is (H, W) float32 (512x512 for HCI), a runtime one float in seconds.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from lfbench.data.pfm import read_pfm, write_pfm
from lfbench.utils.atomic import write_text
from lfbench.utils.errors import DataError

DISP_DIR, RUNTIME_DIR = "disp_maps", "runtimes"


def disp_map_path(root: str | Path, scene: str) -> Path:
    return Path(root) / DISP_DIR / f"{scene}.pfm"


def runtime_path(root: str | Path, scene: str) -> Path:
    return Path(root) / RUNTIME_DIR / f"{scene}.txt"


def read_runtime(path: str | Path) -> float:
    """The runtime in s from a runtimes/<scene>.txt (first line, one float)."""
    path = Path(path)
    try:
        first = path.read_text(encoding="utf-8", errors="replace").strip().splitlines()
    except FileNotFoundError:
        raise DataError("missing runtime file", path) from None
    try:
        value = float(first[0]) if first else float("nan")
    except ValueError:
        raise DataError(f"runtime {first[0][:30]!r} is not a number", path) from None
    return value


def write_runtime(path: str | Path, seconds: float) -> None:
    if not math.isfinite(seconds) or seconds <= 0:
        raise ValueError(f"runtime must be a positive number of seconds, got {seconds}")
    write_text(path, f"{seconds:0.10f}\n")


def submission_scenes(root: str | Path) -> list[str]:
    """Scene names that have a disparity map in the submission folder."""
    d = Path(root) / DISP_DIR
    if not d.is_dir():
        raise DataError(f"not a submission folder: no {DISP_DIR}/ inside", root)
    return sorted(p.stem for p in d.glob("*.pfm"))


def read_submission_map(root: str | Path, scene: str) -> tuple[np.ndarray, float | None]:
    """(disparity (H, W) float32, runtime in s or None if its file is absent) of one scene."""
    disp = read_pfm(disp_map_path(root, scene))
    rt = runtime_path(root, scene)
    return disp, (read_runtime(rt) if rt.is_file() else None)


def write_submission_map(root: str | Path, scene: str, disparity: np.ndarray, runtime_s: float) -> None:
    """Write one scene's map and runtime, each atomically."""
    disparity = np.asarray(disparity, dtype=np.float32)
    if disparity.ndim != 2:
        raise ValueError(f"disparity must be (H, W), got {disparity.shape}")
    write_pfm(disp_map_path(root, scene), disparity)
    write_runtime(runtime_path(root, scene), runtime_s)
