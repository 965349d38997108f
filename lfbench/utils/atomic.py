"""Atomic file writes: a reader sees the old file or the complete new one, never half of one."""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import IO

from lfbench.utils.errors import DataError

__all__ = ["FILE_MODE", "atomic_open", "check_replaceable", "fresh_dir", "replace_dir", "write_bytes", "write_text"]


#: The mode of a new file (rw-r--r--): a result is readable by others, as a file made by open() under
#: the usual umask 022 is. An existing file keeps its own mode.
FILE_MODE = 0o644


_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"),
          (stat.S_ISFIFO, "a FIFO"), (stat.S_ISSOCK, "a socket"))


def check_replaceable(path: str | Path) -> None:
    """DataError naming ``path`` unless a write may replace it: absent, a regular file, or a symbolic link (the
    link itself is replaced, never followed). A device (a copy of ``/dev/null`` made with mknod), FIFO, socket or
    folder is never replaced by a file. Every write of lfbench goes through :func:`atomic_open`, which checks
    this; a command checks the files it names before its work (:func:`lfbench.utils.outputs.check_output_file`)."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return
    except OSError as exc:
        raise DataError(f"cannot write: {exc.strerror or exc}", path) from None
    if stat.S_ISREG(mode) or stat.S_ISLNK(mode):
        return
    kind = next((name for test, name in _KINDS if test(mode)), "not a regular file")
    raise DataError(f"is {kind}, not a regular file: lfbench writes only regular files and does not replace it",
                    path)


@contextlib.contextmanager
def atomic_open(path: str | Path, mode: str = "wb", *, file_mode: int | None = None, **kwargs) -> Iterator[IO]:
    """Open a temporary file beside ``path``; on clean exit fsync it and rename it over ``path`` (a regular
    file, a symbolic link, which is replaced, or nothing: :func:`check_replaceable`).

    On an exception the temporary file is removed and ``path`` is left untouched. The file gets
    ``file_mode`` if given, else the mode of the file it replaces, else :data:`FILE_MODE` (set on the
    file itself: the process umask is never changed, which would race with other threads).
    """
    path = Path(path)
    check_replaceable(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if file_mode is None:
        try:
            file_mode = stat.S_IMODE(path.stat().st_mode)
        except OSError:
            file_mode = FILE_MODE
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise _naming(exc, path, exc.filename) from None  # the temporary's name
    try:
        os.fchmod(fd, file_mode)  # mkstemp makes 0600
        with os.fdopen(fd, mode, **kwargs) as handle:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except OSError as exc:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise _naming(exc, path, tmp) from None
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def _naming(exc: OSError, path: Path, tmp: str | None) -> OSError:
    """``exc`` naming ``path`` when it names no file or the temporary (a full disk fails a write(), which
    names nothing): the error says which file could not be written."""
    if exc.filename is not None and exc.filename not in (tmp, str(path.parent)):
        return exc
    return type(exc)(exc.errno, exc.strerror, str(path)) if exc.errno is not None else exc


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_open(path, "wb") as f:
        f.write(data)


def write_text(path: str | Path, text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    with atomic_open(path, "w", encoding="utf-8", newline="\n") as f:
        f.write(text)


def fresh_dir(parent: str | Path, prefix: str, suffix: str = "") -> Path:
    """A new, empty folder ``parent/<prefix><random><suffix>`` for output that is renamed into place when
    complete. Unlike ``tempfile.mkdtemp`` (always 0700) its mode comes from the umask, as any folder the
    user makes does, so a renamed result (an HTML site, generated scenes) is as readable as its neighbours."""
    parent = Path(parent)
    while True:
        path = parent / f"{prefix}{secrets.token_hex(4)}{suffix}"
        try:
            path.mkdir()
            return path
        except FileExistsError:
            continue


def replace_dir(finished: Path, target: Path) -> None:
    """Rename the complete folder ``finished`` to ``target`` (same file system). An existing ``target`` is
    moved aside first and removed only after the swap, so ``target`` is at every moment whole (old or new)."""
    if not target.exists():
        os.replace(finished, target)
        return
    old = fresh_dir(target.parent, f".{target.name}.", ".old")
    os.replace(target, old / target.name)
    os.replace(finished, target)
    shutil.rmtree(old, ignore_errors=True)
