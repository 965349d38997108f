"""Python subprocesses import lfbench (and plugins) as this process does, never from the current folder.

``python -m MODULE`` and ``python -c`` put the current folder first on sys.path: started from a folder
holding a clone named ``lfbench`` (or a folder named like a plugin's package), a worker imported that
instead of the installed package. ``PYTHONSAFEPATH=1`` (Python 3.11+, the ``-P`` flag) leaves the
current folder out, and the worker's own subprocesses inherit it.
"""

from __future__ import annotations

import contextlib
import os
from collections.abc import Iterator, Mapping

__all__ = ["SAFE_PATH", "safe_path_env", "safe_path_environ"]

#: The environment that keeps the current folder off a Python subprocess's sys.path.
SAFE_PATH = {"PYTHONSAFEPATH": "1"}


def safe_path_env(env: Mapping[str, str] | None = None) -> dict[str, str]:
    """``env`` (default: this process's environment) with :data:`SAFE_PATH`, for ``subprocess.run(env=...)``."""
    return {**(os.environ if env is None else env), **SAFE_PATH}


@contextlib.contextmanager
def safe_path_environ() -> Iterator[None]:
    """:data:`SAFE_PATH` in os.environ while the block runs, for launchers that copy os.environ when they
    start a process (submitit's executors); the previous value is restored."""
    before = {k: os.environ.get(k) for k in SAFE_PATH}
    os.environ.update(SAFE_PATH)
    try:
        yield
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
