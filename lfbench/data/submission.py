"""The benchmark's submission format: ``disp_maps/<scene>.pfm`` and ``runtimes/<scene>.txt`` (a map may also
be ``disp_maps/<scene>.npy``, as UrbanLF's outputs are: read, never written).

A disparity map is (H, W) float32 (512x512 for HCI), a runtime one float in seconds.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from lfbench.data.npyfile import read_npy
from lfbench.data.pfm import MAX_PFM_PIXELS, read_pfm, write_pfm
from lfbench.utils.atomic import write_text
from lfbench.utils.errors import DataError
from lfbench.utils.readfile import read_text

DISP_DIR, RUNTIME_DIR = "disp_maps", "runtimes"


def disp_map_path(root: str | Path, scene: str) -> Path:
    """Where a scene's map is written: ``disp_maps/<scene>.pfm``."""
    return Path(root) / DISP_DIR / f"{scene}.pfm"


def find_disp_map(root: str | Path, scene: str) -> Path:
    """The scene's stored map: ``disp_maps/<scene>.pfm``, else ``disp_maps/<scene>.npy`` (e.g. UrbanLF outputs)
    where only that exists; the .pfm path when neither does."""
    pfm = disp_map_path(root, scene)
    npy = pfm.with_suffix(".npy")
    if not (pfm.exists() or pfm.is_symlink()) and (npy.exists() or npy.is_symlink()):
        return npy
    return pfm


def runtime_path(root: str | Path, scene: str) -> Path:
    return Path(root) / RUNTIME_DIR / f"{scene}.txt"


def check_inside(root: str | Path, path: str | Path) -> None:
    """DataError unless ``path`` is a regular file whose real location is inside the folder ``root``
    (validate-submission's rule: no symbolic link may lead out of a submission)."""
    root, path = Path(root), Path(path)
    try:
        real = path.resolve(strict=True)
        inside = real.is_relative_to(root.resolve(strict=True))
    except (OSError, RuntimeError):  # a dangling link or a loop
        raise DataError("broken symbolic link or unreadable path", path) from None
    if not inside:
        raise DataError("symbolic link leading out of the submission folder (not allowed)", path)
    if real.is_dir():
        raise DataError("is a folder, expected a file", path)
    if not real.is_file():
        raise DataError("not a regular file", path)


MAX_RUNTIME_BYTES = 4096  # a runtime file holds one number


def read_runtime(path: str | Path) -> float:
    """The runtime in s from a runtimes/<scene>.txt as the toolkit reads it: its first line as one float
    (surrounding spaces allowed; what follows the first line is ignored). The value is returned as
    written (NaN, 0 or a negative number included: runtime metrics leave such a runtime out).
    DataError naming the file when it is missing, larger than MAX_RUNTIME_BYTES or its first line is not
    a number (an empty file included, which the toolkit cannot read either)."""
    path = Path(path)
    text = read_text(path, "runtime file", MAX_RUNTIME_BYTES, errors="replace")
    try:
        return float(text.split("\n", 1)[0])
    except ValueError:  # the file's text is not shown: never echo file content
        raise DataError("runtime is not a number (expected one number of seconds)", path) from None


def write_runtime(path: str | Path, seconds: float) -> None:
    if not math.isfinite(seconds) or seconds <= 0:
        raise ValueError(f"runtime must be a positive number of seconds, got {seconds}")
    write_text(path, f"{seconds:0.10f}\n")


def submission_scenes(root: str | Path) -> list[str]:
    """Scene names that have a disparity map in the submission folder."""
    d = Path(root) / DISP_DIR
    if not d.is_dir():
        raise DataError(f"not a submission folder: no {DISP_DIR}/ inside", root)
    return sorted({p.stem for p in [*d.glob("*.pfm"), *d.glob("*.npy")]})


def read_submission_map(root: str | Path, scene: str, max_shape: tuple[int, int] | None = None
                        ) -> tuple[np.ndarray, float | None]:
    """(disparity (H, W) float32, runtime in s or None if its file is absent) of one scene. ``max_shape``
    (H, W): the largest map the scene can take (its own size; a cropped map is smaller), checked against
    the PFM or .npy header before the data is read. The map is ``<scene>.pfm``, else ``<scene>.npy``
    (:func:`find_disp_map`): a 2-D array of floats, never unpickled."""
    path = find_disp_map(root, scene)
    check_inside(root, path)
    disp = read_npy_map(path, max_shape) if path.suffix == ".npy" else \
        read_pfm(path, max_shape=max_shape, what="prediction")
    rt = runtime_path(root, scene)
    if not (rt.exists() or rt.is_symlink()):
        return disp, None
    check_inside(root, rt)
    return disp, read_runtime(rt)


def read_npy_map(path: Path, max_shape: tuple[int, int] | None = None) -> np.ndarray:
    """A prediction stored as .npy: (H, W) floating point (as float32), each side at most ``max_shape``'s and
    at most MAX_PFM_PIXELS pixels, checked against its header before the data is read (lfbench.data.npyfile)."""
    def check(shape: tuple[int, ...], dtype: np.dtype) -> str | None:
        if len(shape) != 2:
            return f"prediction must be a 2-D (H, W) array, got shape {shape}"
        if dtype.kind != "f":
            return f"prediction must hold floating-point disparities, got {dtype}"
        if max_shape is not None and (shape[0] > max_shape[0] or shape[1] > max_shape[1]):
            return (f"prediction is {shape[1]}x{shape[0]} px (W x H), larger than the scene's "
                    f"{max_shape[1]}x{max_shape[0]}")
        if math.prod(shape) > MAX_PFM_PIXELS:
            return f"prediction of {shape[1]}x{shape[0]} px is larger than lfbench reads ({MAX_PFM_PIXELS} px)"
        return None

    return np.ascontiguousarray(read_npy(path, check), dtype=np.float32)


def write_submission_map(root: str | Path, scene: str, disparity: np.ndarray, runtime_s: float | None) -> None:
    """Write one scene's map and runtime, each atomically; no runtime file unless ``runtime_s`` is a positive
    finite number (a method that reports no runtime gets none made up: its runtime records stay absent)."""
    disparity = np.asarray(disparity, dtype=np.float32)
    if disparity.ndim != 2:
        raise ValueError(f"disparity must be (H, W), got {disparity.shape}")
    write_pfm(disp_map_path(root, scene), disparity)
    if runtime_s is not None and math.isfinite(runtime_s) and runtime_s > 0:
        write_runtime(runtime_path(root, scene), runtime_s)
