"""Read a user's file with a byte cap: every reader of configs, specs, golden and results files,
parameters.cfg, runtimes and CSVs goes through here.

A size taken from ``stat`` is no bound: a device (``/dev/zero``) or a FIFO reports 0 bytes and never
ends, a file in /proc reports 0 and holds more. So only regular files are opened (a FIFO would block
``open`` itself; it is opened non-blocking and refused), and at most ``max_bytes + 1`` bytes are read:
a file with more is refused, whatever its ``stat`` says.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from lfbench.utils.errors import DataError, LFBenchError

__all__ = ["MAX_CSV_COLUMNS", "MAX_CSV_ROWS", "MAX_TEXT_BYTES", "check_regular_file", "file_sha256", "read_bytes",
           "read_csv", "read_head", "read_text"]

#: The default cap of a text file lfbench reads (configs, specs, CSVs, golden files are far smaller).
MAX_TEXT_BYTES = 64 * 1024**2
#: The most columns and rows a CSV table lfbench reads back may hold (ci.csv has 8 columns and one row per
#: method, scene and metric; a paper's table a dozen columns).
MAX_CSV_COLUMNS = 256
MAX_CSV_ROWS = 1_000_000


def _size(n: int) -> str:
    return f"{n / 1024**2:g} MiB" if n >= 1024**2 else f"{n} bytes"


def _open(path: Path, what: str, error: type[LFBenchError]) -> int:
    """A read-only descriptor of the regular file ``path`` (non-blocking open: a FIFO must not hang)."""
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        if os.path.islink(path):
            raise error(f"{what} is a symbolic link that leads nowhere", path) from None
        raise error(f"{what} not found", path) from None
    except OSError as exc:  # a folder opens read-only (POSIX): fstat below names it
        raise error(f"cannot read {what}: {exc.strerror or exc}", path) from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        kind = "a folder" if stat.S_ISDIR(mode) else "not a regular file (a device, FIFO or socket)"
        raise error(f"{what} is {kind}, expected a file", path)
    return fd


def check_regular_file(path: str | Path, what: str = "file", *, error: type[LFBenchError] = DataError) -> None:
    """``error`` naming ``path`` unless it is an existing regular file (after following links): for readers
    that open the file themselves (PIL, numpy, torch) and must not be handed a device or a FIFO."""
    os.close(_open(Path(path), what, error))


def read_head(path: str | Path, n: int, what: str = "file", *, error: type[LFBenchError] = DataError) -> bytes:
    """The first ``n`` bytes of the regular file ``path`` (fewer when it is shorter): a header read without
    handing the file to a decoder; ``error`` naming it as :func:`read_bytes` does."""
    path = Path(path)
    fd = _open(path, what, error)
    try:
        return os.read(fd, n)
    except OSError as exc:
        raise error(f"cannot read {what}: {exc.strerror or exc}", path) from None
    finally:
        os.close(fd)


def read_bytes(path: str | Path, what: str = "file", max_bytes: int = MAX_TEXT_BYTES, *,
               error: type[LFBenchError] = DataError) -> bytes:
    """The bytes of the regular file ``path``, at most ``max_bytes``; ``error`` (a one-line
    :class:`LFBenchError`) naming the file and ``what`` it is when it is missing, a folder, not a regular
    file, unreadable or larger than ``max_bytes`` (counted while reading, not taken from ``stat``)."""
    path = Path(path)
    fd = _open(path, what, error)
    chunks: list[bytes] = []
    total = 0
    try:
        while total <= max_bytes:
            chunk = os.read(fd, min(max_bytes + 1 - total, 1 << 20))
            if not chunk:
                break
            chunks.append(chunk)
            total += len(chunk)
    except OSError as exc:
        raise error(f"cannot read {what}: {exc.strerror or exc}", path) from None
    finally:
        os.close(fd)
    if total > max_bytes:
        raise error(f"{what} is larger than {_size(max_bytes)}, more than lfbench reads", path)
    return b"".join(chunks)


def file_sha256(path: str | Path, what: str = "file", *, error: type[LFBenchError] = DataError) -> str:
    """SHA-256 (hex) of the bytes of the regular file ``path``, read in 1 MiB pieces (any size: nothing is
    held); ``error`` naming the file when it is missing, not a regular file or unreadable."""
    import hashlib

    path = Path(path)
    fd = _open(path, what, error)
    digest = hashlib.sha256()
    try:
        while chunk := os.read(fd, 1 << 20):
            digest.update(chunk)
    except OSError as exc:
        raise error(f"cannot read {what}: {exc.strerror or exc}", path) from None
    finally:
        os.close(fd)
    return digest.hexdigest()


def read_text(path: str | Path, what: str = "file", max_bytes: int = MAX_TEXT_BYTES, *,
              error: type[LFBenchError] = DataError, errors: str = "strict") -> str:
    """:func:`read_bytes` decoded as UTF-8 (``errors`` as in ``bytes.decode``); ``error`` naming the file
    when it is not UTF-8 text."""
    raw = read_bytes(path, what, max_bytes, error=error)
    try:
        return raw.decode("utf-8", errors=errors)
    except UnicodeDecodeError:
        raise error(f"{what} is not UTF-8 text", path) from None


def read_csv(path: str | Path, what: str = "CSV table", max_bytes: int = MAX_TEXT_BYTES, *,
             max_columns: int = MAX_CSV_COLUMNS, max_rows: int = MAX_CSV_ROWS, **options):
    """A CSV file as a pandas DataFrame, read with :func:`read_text`'s cap; ``options`` go to
    ``pandas.read_csv`` (e.g. ``dtype=str``); DataError naming the file when it cannot be read or parsed,
    or holds more than ``max_rows`` lines or a line of more than ``max_columns`` comma-separated fields:
    both counted before pandas parses it, whose time grows with rows x columns (a 3-row ci.csv of
    100,000 columns took a minute to report)."""
    import io

    import pandas as pd

    text = read_text(path, what, max_bytes)
    rows = text.splitlines()
    if len(rows) > max_rows + 1:
        raise DataError(f"{what} has {len(rows)} lines, more than lfbench reads ({max_rows} rows and a header)", path)
    widest = max((row.count(",") + 1 for row in rows), default=0)  # quoted commas count too: a bound
    if widest > max_columns:
        raise DataError(f"{what} has a line of {widest} comma-separated fields, more than lfbench reads "
                        f"({max_columns} columns)", path)
    try:
        return pd.read_csv(io.StringIO(text), **options)
    except (pd.errors.ParserError, pd.errors.EmptyDataError) as exc:
        raise DataError(f"not a readable CSV table: {str(exc).splitlines()[0]}", path) from None
