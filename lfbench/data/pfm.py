"""PFM (portable float map) read/write, as used by the HCI benchmark for disparity maps.

Header ``Pf`` (1 channel) or ``PF`` (3 channels), then ``width height``, then a scale whose sign
gives the byte order (negative = little endian). Rows are stored bottom-up; we flip on read and
write so that arrays are top-down (row 0 = top of the image), like every other image.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import BinaryIO

import numpy as np

from lfbench.utils.atomic import atomic_open
from lfbench.utils.errors import DataError
from lfbench.utils.readfile import check_regular_file

_MAX_HEADER_LINE = 256
#: The most pixels of any PFM lfbench reads (HCI's high-resolution ground truth: 5120 x 5120 = 2**24.6),
#: checked against the header before the data is read.
MAX_PFM_PIXELS = 2**27

Shape = tuple[int, int]


def _header_line(f, path: Path) -> str:
    while True:
        raw = f.readline(_MAX_HEADER_LINE)
        if not raw:
            raise DataError("not a PFM file: header ends early", path)
        try:
            line = raw.decode("ascii").strip()
        except UnicodeDecodeError:
            raise DataError("not a PFM file: header is not ASCII", path) from None
        if line and not line.startswith("#"):
            return line


def read_pfm(path: str | Path, *, shape: Shape | None = None, max_shape: Shape | None = None,
             what: str = "PFM map") -> np.ndarray:
    """Read a PFM file as float32, (H, W) for ``Pf`` or (H, W, 3) for ``PF``, rows top-down.

    Values are multiplied by |scale| as the benchmark toolkit does (scale is 1 in HCI files).
    The header's dimensions are checked before any data is read: against ``shape`` (H, W) exactly
    when given (e.g. a scene's ground truth), against ``max_shape`` (H, W) as an upper bound per side
    (e.g. a prediction, which may be cropped), and always against MAX_PFM_PIXELS; ``what`` names the
    map in those errors. Raises DataError naming the file for any malformed, truncated or oversized input.
    """
    path = Path(path)
    check_regular_file(path, "PFM file")  # a FIFO would block open(), a device never end
    try:
        f = open(path, "rb")
    except FileNotFoundError:
        raise DataError("file not found", path) from None
    except IsADirectoryError:
        raise DataError("is a folder, expected a PFM file", path) from None
    with f:
        return _read_pfm_stream(f, path, shape, max_shape, what)


def parse_pfm(data: bytes, source: str | Path = "<bytes>", *, shape: Shape | None = None,
              max_shape: Shape | None = None, what: str = "PFM map") -> np.ndarray:
    """Like :func:`read_pfm` for a PFM held in memory (e.g. a zip member); errors name ``source``."""
    return _read_pfm_stream(io.BytesIO(data), Path(source), shape, max_shape, what)


def _check_dimensions(width: int, height: int, shape: Shape | None, max_shape: Shape | None, path: Path,
                      what: str) -> None:
    """DataError unless the header's width x height fits ``shape``, ``max_shape`` and MAX_PFM_PIXELS."""
    if shape is not None and (height, width) != tuple(shape):
        raise DataError(f"{what} is {width}x{height}, expected {shape[1]}x{shape[0]}", path)
    if max_shape is not None and (height > max_shape[0] or width > max_shape[1]):
        raise DataError(f"{what} is {width}x{height}, scene is {max_shape[1]}x{max_shape[0]}: larger than the scene",
                        path)
    if width * height > MAX_PFM_PIXELS:
        raise DataError(f"{what} is {width}x{height} ({width * height} px), more than lfbench reads "
                        f"({MAX_PFM_PIXELS} px)", path)


def _read_pfm_stream(f: BinaryIO, path: Path, shape: Shape | None = None, max_shape: Shape | None = None,
                     what: str = "PFM map") -> np.ndarray:
    ident = _header_line(f, path)
    if ident not in ("Pf", "PF"):
        raise DataError("not a PFM file: the first line is not 'Pf' or 'PF'", path)  # never echo content
    channels = 1 if ident == "Pf" else 3
    dims = _header_line(f, path).split()
    try:
        width, height = (int(v) for v in dims)
        if width <= 0 or height <= 0:
            raise ValueError
    except ValueError:
        raise DataError("bad PFM dimensions: expected two positive integers 'width height'", path) from None
    _check_dimensions(width, height, shape, max_shape, path, what)
    try:
        scale = float(_header_line(f, path))
        if scale == 0 or not np.isfinite(scale):
            raise ValueError
    except ValueError:
        raise DataError("bad PFM scale: must be a finite non-zero number", path) from None
    dtype = np.dtype("<f4" if scale < 0 else ">f4")
    count = width * height * channels
    start = f.tell()  # compare sizes before reading: absurd dimensions must not allocate memory
    available = f.seek(0, io.SEEK_END) - start
    f.seek(start)
    if available != count * 4:
        what = "truncated" if available < count * 4 else "trailing bytes after the data in"
        raise DataError(f"{what} PFM: expected {count * 4} data bytes for {width}x{height}x{channels}, "
                        f"found {available}", path)
    payload = f.read(count * 4)
    data = np.frombuffer(payload, dtype=dtype)
    shape = (height, width) if channels == 1 else (height, width, 3)
    out = np.flipud(data.reshape(shape)).astype(np.float32)
    if abs(scale) != 1.0:
        out *= np.float32(abs(scale))
    return out


def write_pfm(path: str | Path, data: np.ndarray) -> None:
    """Write (H, W) or (H, W, 3) data as little-endian float32 PFM, atomically (exact round trip)."""
    arr = np.asarray(data)
    if arr.ndim not in (2, 3) or (arr.ndim == 3 and arr.shape[2] != 3):
        raise ValueError(f"PFM holds (H, W) or (H, W, 3) arrays, got shape {arr.shape}")
    ident = b"Pf" if arr.ndim == 2 else b"PF"
    height, width = arr.shape[:2]
    payload = np.ascontiguousarray(np.flipud(arr), dtype="<f4").tobytes()
    with atomic_open(path, "wb") as f:
        f.write(ident + b"\n" + f"{width} {height}\n".encode() + b"-1.0\n" + payload)
