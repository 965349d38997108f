"""Text in lfbench's figures is plain text, whatever it holds.

Method labels, scene names, folder names and titles come from users: a ``$...$`` in one of them would be
parsed by matplotlib as mathtext (and ``$\\x$`` fails to parse, losing every figure of a run), and a
user's matplotlibrc may turn on ``text.usetex`` (LaTeX on every string). Each function that makes and
saves a figure is decorated with :func:`plain_text`; a log axis gets plain tick labels from
:func:`plain_log_ticks` (matplotlib's default log tick labels are mathtext).
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import Any, ParamSpec, TypeVar

__all__ = ["PLAIN_TEXT_RC", "plain_log_ticks", "plain_text"]

P = ParamSpec("P")
R = TypeVar("R")

#: matplotlib settings under which every figure is drawn and saved.
PLAIN_TEXT_RC = {"text.parse_math": False, "text.usetex": False}


def plain_text(draw: Callable[P, R]) -> Callable[P, R]:
    """Decorator of a function that makes and saves a figure: it runs under :data:`PLAIN_TEXT_RC`, so
    every label, title, legend entry and tick label (also those made only when saving) is plain text."""

    @functools.wraps(draw)
    def drawn_as_plain_text(*args: P.args, **kwargs: P.kwargs) -> R:
        import matplotlib

        with matplotlib.rc_context(PLAIN_TEXT_RC):
            return draw(*args, **kwargs)

    return drawn_as_plain_text


def plain_log_ticks(axis: Any) -> None:
    """Plain-text tick labels (1e-02, 0.1, ...) on a log-scaled matplotlib ``axis``."""
    from matplotlib.ticker import LogFormatter

    axis.set_major_formatter(LogFormatter())
    axis.set_minor_formatter(LogFormatter(labelOnlyBase=False))
