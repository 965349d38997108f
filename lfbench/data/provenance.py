"""Where a data root came from: roots written by ``lfbench synth`` carry a marker file, so that every table
scored on them can say that the data is synthetic (its numbers show that a pipeline runs, not how methods
rank on a real dataset, and are not comparable with a paper's).

The marker is a regular file ``SYNTHETIC`` at the root (a short text naming the generator). It is read back
from a folder the user may not own: only its presence as a regular file inside the root counts (a link,
folder or FIFO of that name is not a marker), and its content is never read."""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable
from pathlib import Path

from lfbench.utils.atomic import write_text

__all__ = ["SYNTHETIC_CAPTION", "SYNTHETIC_MARKER", "is_synthetic_root", "mark_synthetic"]

#: The marker's file name at a data root.
SYNTHETIC_MARKER = "SYNTHETIC"

#: The caption line of every table scored on synthetic data.
SYNTHETIC_CAPTION = ("SYNTHETIC DATA (lfbench synth): our numbers show that the pipeline runs; they do not say how "
                     "the methods rank on the real dataset and are not comparable with the paper's")


def mark_synthetic(root: str | Path, command: str) -> Path:
    """Write the marker at ``root`` (``command``: how the data was made, for the person who opens the folder)."""
    path = Path(root) / SYNTHETIC_MARKER
    write_text(path, f"Written by {command}: synthetic scenes with exact ground truth, not a real dataset.\n")
    return path


def is_synthetic_root(roots: str | Path | Iterable[str | Path]) -> bool:
    """Whether any of ``roots`` carries the marker (a regular file, not followed through a link)."""
    for root in [roots] if isinstance(roots, str | Path) else roots:
        try:
            if stat.S_ISREG(os.lstat(Path(root) / SYNTHETIC_MARKER).st_mode):
                return True
        except OSError:
            continue
    return False
