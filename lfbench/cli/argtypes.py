"""argparse pieces the commands share: types that check a flag's range when it is parsed (one usage line,
exit 2), before any work, and flags declared alike by several commands."""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = ["add_method_device", "float_range", "int_range"]


def int_range(low: int, high: int) -> Callable[[str], int]:
    """An argparse ``type``: a whole number from ``low`` to ``high``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number, got {text[:40]!r}") from None
        if not low <= value <= high:
            raise argparse.ArgumentTypeError(f"must be from {low} to {high}, got {value}")
        return value

    parse.__name__ = "integer"
    return parse


def float_range(low: float, high: float, *, low_open: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite number from ``low`` (excluded with ``low_open``) to ``high``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a number, got {text[:40]!r}") from None
        if not (low < value if low_open else low <= value) or not value <= high:
            raise argparse.ArgumentTypeError(f"must be {'above' if low_open else 'from'} {low:g} to {high:g}, "
                                             f"got {text[:40]}")
        return value

    parse.__name__ = "number"
    return parse


def add_method_device(p: argparse.ArgumentParser) -> None:
    """``--device``: where the methods of a command run, handed to ``create_from_spec`` as the default of
    a method's ``device`` parameter (None: the method's own default)."""
    p.add_argument("--device", metavar="DEVICE",
                   help="where methods that have a device parameter run (a spec's own device=... wins): "
                        "auto, cpu, cuda or cuda:K (default: the method's, auto)")
