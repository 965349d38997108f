"""The command-line flags several commands (or several benches of ``lfbench bench``) share, each declared once:
name, type, default, bounds and help, as a :class:`~lfbench.utils.options.Param` (the same type names, bounds
and messages as every declared option). lfbench.cli.argtypes adds them to the parsers (the argparse ``type``
comes from the bounds: one usage line, exit 2), docs/command-line.md is generated from them, and a library
function that takes such a value from Python checks it with :meth:`Flag.require`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from lfbench.utils.errors import SpecError
from lfbench.utils.options import BadValue, Bounds, Param, Range

__all__ = ["Flag", "FLAGS", "JOBS", "SEED", "SCENE_COUNT", "DEVICE", "REPEAT", "THREADS", "TIMEOUT", "MAX_MEMORY",
           "MAX_JOBS"]

#: The most worker processes of ``evaluate --jobs`` and ``ablate --jobs``. Every worker imports numpy (and torch,
#: for ablation cells) and holds a scene or a training run: a few hundred MB each, so 256 workers already ask for
#: tens of GB; no pool of lfbench shares anything that grows with more (cores are divided among the workers).
MAX_JOBS = 256


@dataclass(frozen=True)
class Flag(Param):
    """A declared option written ``--name-with-dashes VALUE`` on the command line (``metavar``: VALUE)."""

    metavar: str | None = None

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def require(self, value: Any) -> Any:
        """``value`` given from Python (a library call's guard), checked as the flag is: SpecError ``--jobs:
        must be in [1, 256], got 0`` otherwise."""
        try:
            return self.check(value)
        except BadValue as exc:
            raise SpecError(f"{self.flag}: {exc}") from None


JOBS = Flag("jobs", int, 1, "worker processes at a time (1: all in this process)", Range(1, MAX_JOBS), "N")
SEED = Flag("seed", int, 0, "seed of the generator (a 64-bit signed integer, as in TOML configs)",
            Range(0, 2**63 - 1), "SEED")
SCENE_COUNT = Flag("scenes", int, 4, "number of generated scenes", Range(1, 1000), "K")
DEVICE = Flag("device", str | None, None, "where networks run: auto, cpu, cuda or cuda:K", None, "DEVICE")
REPEAT = Flag("repeat", int, 1, "timed runs per case", Range(1, 10**6), "N")
THREADS = Flag("threads", int, 0, "torch CPU threads (0 = all cores)", Range(0, 4096), "N")
POSITIVE = Bounds(0, 1e12, low_open=True)
TIMEOUT = Flag("timeout", float | None, None, "give up a case after S seconds", POSITIVE, "S")
MAX_MEMORY = Flag("max_memory", float | None, None, "memory budget of inference in GB (default: 4 on the CPU, the "
                  "GPU's free memory on CUDA)", POSITIVE, "GB")

#: Every shared flag, in the order docs/command-line.md lists them.
FLAGS: tuple[Flag, ...] = (JOBS, SEED, SCENE_COUNT, DEVICE, REPEAT, THREADS, TIMEOUT, MAX_MEMORY)
