"""A training run's folder: the names of its files (:class:`RunPaths`), the lock that keeps one ``lfbench
train`` per folder (:func:`run_folder_lock`) and the check of a resume checkpoint read back from it
(:func:`check_resume_state`: a tampered or foreign file fails in one line)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from filelock import FileLock, Timeout

from lfbench.utils.errors import DataError
from lfbench.utils.names import file_name

EXPORTS = "train"  # the output set (lfbench.utils.outputs) of a run's final exports: final.pt and summary.json


@dataclass(frozen=True)
class RunPaths:
    out: Path

    @property
    def checkpoint(self) -> Path:
        return self.out / "checkpoint.pt"

    @property
    def final(self) -> Path:
        return self.out / "final.pt"

    @property
    def best(self) -> Path:
        return self.out / "best.pt"

    @property
    def metrics(self) -> Path:
        return self.out / "metrics.jsonl"

    @property
    def command(self) -> Path:
        return self.out / "command.txt"

    @property
    def config(self) -> Path:
        return self.out / "config.toml"

    @property
    def summary(self) -> Path:
        return self.out / "summary.json"

    @property
    def data(self) -> Path:
        return self.out / "data"

    def stage_weights(self, index: int, name: str) -> Path:
        return self.out / stage_weights_name(index, name)


def stage_weights_name(index: int, name: str) -> str:
    """File name of the weights after stage ``index`` (0-based) named ``name``: ``stage<k>_<name>.pt``,
    the name as a file name (lfbench.utils.names; the config refuses two that are one)."""
    return f"stage{index + 1}_{file_name(name)}.pt"


_STATE_TYPES: dict[str, tuple[type, ...]] = {
    "config": (dict,), "stage": (int,), "step": (int,), "global_step": (int,), "model": (dict,),
    "optimizer": (dict, type(None)), "rng": (dict,), "elapsed_s": (int, float), "best_badpix": (int, float),
    "last_validation": (dict, type(None)),
}


def check_resume_state(state: dict[str, Any], path: Path) -> None:
    """DataError naming ``path`` when a training checkpoint lacks an entry or holds one of the wrong type
    (a tampered or foreign file must fail in one line, not deep inside the loop)."""
    for key, kinds in _STATE_TYPES.items():
        if key not in state:
            raise DataError(f"training checkpoint has no {key!r} entry", path)
        value = state[key]
        if isinstance(value, bool) or not isinstance(value, kinds):
            raise DataError(f"training checkpoint entry {key!r} is a {type(value).__name__}", path)
    if state["stage"] < 0 or state["step"] < 0 or state["global_step"] < 0:
        raise DataError("training checkpoint has a negative stage or step", path)
    if not isinstance(state["config"].get("stages"), list):
        raise DataError("training checkpoint config has no list of stages", path)
    if state["stage"] > len(state["config"]["stages"]):
        raise DataError(f"training checkpoint is at stage {state['stage'] + 1}, beyond its config's "
                        f"{len(state['config']['stages'])} stage(s)", path)


LOCK_NAME = ".lfbench-train.lock"


@contextlib.contextmanager
def run_folder_lock(out: Path) -> Iterator[None]:
    """Hold an exclusive lock on the run folder ``out`` (created if needed): a second ``lfbench train``
    into the same folder is refused at once (DataError) instead of interleaving logs and checkpoints.
    The lock is an OS file lock (filelock): it goes away with the process, even after kill -9."""
    if out.exists() and not out.is_dir():
        raise DataError("output folder is a file", out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        lock = FileLock(str(out / LOCK_NAME))
        lock.acquire(timeout=0)
    except Timeout:
        raise DataError("another lfbench train is running into this folder (it holds "
                        f"{LOCK_NAME}); wait for it or use another --out", out) from None
    except OSError as exc:
        raise DataError(f"cannot write into the output folder: {exc.strerror or exc}", out) from None
    try:
        yield
    finally:
        lock.release()


__all__ = ["EXPORTS", "LOCK_NAME", "RunPaths", "check_resume_state", "run_folder_lock", "stage_weights_name"]
