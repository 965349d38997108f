"""Method labels and scene names as file names, with one rule for every file and folder lfbench names
after them (maps folders, figures, HTML pages, ablation method folders), and a refusal when two names
would share one file.

:func:`file_name` keeps letters, digits and ``. _ - =`` and writes every other character as ``_``, so
``m<1`` and ``m>1`` both become ``m_1``: :class:`FileNames` (and :func:`file_names`) hand out the names
of one kind in one place and refuse, with a DataError naming both, a second label that would get a name
already taken (compared in lower case: the same file on macOS and Windows), or a name lfbench itself
uses there.
"""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path

from lfbench.utils.errors import DataError

__all__ = ["MAX_NAME_BYTES", "FileNames", "file_name", "file_names"]

#: Longer names are cut and end in a hash of the whole label (file systems allow 255 bytes, and lfbench
#: adds prefixes and suffixes such as ``method-`` and ``.disp.png``).
MAX_NAME_BYTES = 160
_KEPT = "._-="


def file_name(label: str) -> str:
    """``label`` as one file-name component: letters, digits and ``. _ - =`` kept, any other character
    ``_``; a name of dots only (``.``, ``..``) or an empty one becomes underscores; a name longer than
    MAX_NAME_BYTES (UTF-8) is cut and ends in ``-`` and 12 hex digits of the label's SHA-256."""
    name = "".join(c if c.isalnum() or c in _KEPT else "_" for c in label)
    if not name.strip("."):
        name = "_" * max(len(name), 1)
    if len(name.encode("utf-8")) > MAX_NAME_BYTES:
        digest = hashlib.sha256(label.encode("utf-8", "surrogatepass")).hexdigest()[:12]
        cut = name.encode("utf-8")[:MAX_NAME_BYTES - 13].decode("utf-8", "ignore")
        name = f"{cut}-{digest}"
    return name


class FileNames:
    """The file names of one kind of label (``what``: 'method label', 'scene', ...) in one place.

    Calling it with a label gives :func:`file_name` of it, the same name each time; DataError when
    another label already has that name (ignoring case) or when it is one of ``reserved`` (names
    lfbench writes there itself). ``source``: the file the labels came from, named in the error.
    """

    def __init__(self, what: str, *, reserved: Iterable[str] = (), source: str | Path | None = None) -> None:
        self.what = what
        self.source = source
        self._owner: dict[str, str] = {}  # name in lower case -> the label that has it
        self._reserved = {r.lower() for r in reserved}

    def __call__(self, label: str) -> str:
        return self.claim(label, file_name(label))

    def claim(self, label: str, name: str) -> str:
        """Give ``label`` the file name ``name`` (one built from file names, e.g. ``pairwise_A_vs_B``),
        refused like a name of :meth:`__call__`."""
        key = name.lower()
        if key in self._reserved:
            raise DataError(f"{self.what}: {label!r} would have the file name {name!r}, which lfbench uses there "
                            "itself: rename it", self.source)
        owner = self._owner.setdefault(key, label)
        if owner != label:
            raise DataError(f"{self.what}: {owner!r} and {label!r} would share the file name {name!r} (file names "
                            f"keep letters, digits and {' '.join(_KEPT)}; any case): rename one", self.source)
        return name


def file_names(labels: Iterable[str], what: str, *, reserved: Iterable[str] = (),
               source: str | Path | None = None) -> dict[str, str]:
    """Label -> file name for each distinct label of ``labels`` (in order), refused as :class:`FileNames`
    refuses a collision."""
    names = FileNames(what, reserved=reserved, source=source)
    return {label: names(label) for label in dict.fromkeys(labels)}
