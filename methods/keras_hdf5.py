"""Opening the authors' Keras checkpoints (HDF5) safely, for every importer (SubFocal/LFattNet, EPINET): a
regular file only (a FIFO would block HDF5's open, a device never end), one DataError line naming the file for
a missing file, a file that is not HDF5 and any structure the importer's reader trips over."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any, TypeVar

from lfbench.utils.errors import DataError
from lfbench.utils.readfile import check_regular_file

T = TypeVar("T")


def open_hdf5(path: Path) -> Any:
    """``h5py.File(path, "r")``; DataError naming the file when it is not a regular HDF5 file."""
    import h5py

    if Path(path).exists():
        check_regular_file(path, "Keras checkpoint")
    try:
        return h5py.File(path, "r")
    except FileNotFoundError:
        raise DataError("checkpoint not found", path) from None
    except OSError as exc:
        raise DataError(f"not an HDF5 file ({str(exc).splitlines()[0]})", path) from None


def read_hdf5(path: Path, reader: Callable[[Any, Path], T], what: str) -> T:
    """``reader(file, path)`` on the opened file; its DataError as raised, any other error of reading a
    malformed file (a missing member, a wrong type, a truncated dataset) as ``not <what> (<reason>)``."""
    f = open_hdf5(path)
    try:
        with f:
            return reader(f, path)
    except DataError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, OSError, RuntimeError) as exc:
        reason = " ".join(str(exc).split())[:120] or type(exc).__name__
        raise DataError(f"not {what} ({reason})", path) from None


__all__ = ["open_hdf5", "read_hdf5"]
