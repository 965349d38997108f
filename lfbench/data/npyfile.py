"""Read a user's .npy file safely: the header is parsed and checked before any data is loaded.

``np.load`` trusts the header: a 100-byte file claiming (100000, 100000, 81) float32 asks for
3 TB. :func:`read_npy` reads the header (``np.lib.format``), checks dtype, shape and the file's
size against it and a bound, and only then loads the array (never with pickle).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from lfbench.utils.errors import DataError
from lfbench.utils.readfile import check_regular_file

__all__ = ["MAX_NPY_BYTES", "read_npy"]

MAX_NPY_BYTES = 8 * 1024**3


def read_npy(path: str | Path, check: Callable[[tuple[int, ...], np.dtype], str | None] | None = None,
             max_bytes: int = MAX_NPY_BYTES) -> np.ndarray:
    """The array of ``path``; DataError naming the file when it is missing, not a .npy, holds objects,
    is larger than ``max_bytes``, has a size that does not match its header, or when ``check(shape,
    dtype)`` returns a reason (called before the data is read)."""
    path = Path(path)
    if path.exists():  # a device or FIFO would block or never end; a missing file is reported below
        check_regular_file(path, "input")
    try:
        with open(path, "rb") as f:
            try:
                version = np.lib.format.read_magic(f)
                header = (np.lib.format.read_array_header_1_0 if version == (1, 0)
                          else np.lib.format.read_array_header_2_0)(f, max_header_size=10000)
            except (ValueError, OSError, EOFError, SyntaxError, TypeError):
                raise DataError("cannot read .npy: bad magic or header", path) from None
            shape, fortran, dtype = header
            start = f.tell()
            size = f.seek(0, 2) - start
    except FileNotFoundError:
        raise DataError("input not found", path) from None
    except IsADirectoryError:
        raise DataError("is a folder, expected a .npy file", path) from None
    if dtype.hasobject:
        raise DataError("cannot read .npy: it holds Python objects (pickle); only numeric arrays are read", path)
    if check is not None:
        reason = check(tuple(shape), dtype)
        if reason:
            raise DataError(reason, path)
    nbytes = math.prod(shape) * dtype.itemsize
    if nbytes > max_bytes:
        raise DataError(f"array of shape {tuple(shape)} ({nbytes / 1024**3:.3g} GiB) is larger than lfbench "
                        f"reads ({max_bytes / 1024**3:.3g} GiB)", path)
    if size != nbytes:
        what = "truncated" if size < nbytes else "trailing bytes after the data in"
        raise DataError(f"{what} .npy: header says {tuple(shape)} {dtype} ({nbytes} bytes), found {size}", path)
    try:
        return np.load(path, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise DataError(f"cannot read .npy: {' '.join(str(exc).split())[:160]}", path) from None
