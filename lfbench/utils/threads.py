"""Torch's intra-op thread count, set for a block and restored afterwards."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator

__all__ = ["torch_threads"]


@contextlib.contextmanager
def torch_threads(n: int | None) -> Iterator[int]:
    """Run the block with ``n`` torch threads (None: leave the count as it is; 0 or less: one per CPU
    core) and restore the previous count on exit, also on an exception. Yields the count in force."""
    import torch

    before = torch.get_num_threads()
    if n is not None:
        torch.set_num_threads(int(n) if n > 0 else (os.cpu_count() or 1))
    try:
        yield torch.get_num_threads()
    finally:
        torch.set_num_threads(before)
