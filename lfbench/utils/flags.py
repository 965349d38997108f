"""The command-line flags several commands (or several benches of ``lfbench bench``) share, each declared once as
an option of a section (:class:`SharedFlags`, with :func:`~lfbench.utils.options.option`: type, default, bounds,
help, metavar) and seen as a :class:`Flag` (:func:`section_flags`: the same type names, bounds and messages as
every declared option). A command's own flags are declared the same way, in a section beside its parser.
lfbench.cli.argtypes adds them to the parsers (the argparse ``type`` comes from the bounds: one usage line, exit
2), docs/command-line.md is generated from them, and a library function that takes such a value from Python
checks it with :meth:`Flag.require`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

from lfbench.utils.errors import SpecError
from lfbench.utils.options import BadValue, Bounds, Param, option, option_fields

__all__ = ["Flag", "FLAGS", "flag_name", "SharedFlags", "section_flags", "POSITIVE", "JOBS", "SEED", "SCENE_COUNT",
           "DEVICE", "REPEAT", "THREADS", "TIMEOUT", "MAX_MEMORY", "MAX_JOBS"]

#: The most worker processes of ``evaluate --jobs`` and ``ablate --jobs``. Every worker imports numpy (and torch,
#: for ablation cells) and holds a scene or a training run: a few hundred MB each, so 256 workers already ask for
#: tens of GB; no pool of lfbench shares anything that grows with more (cores are divided among the workers).
MAX_JOBS = 256


def flag_name(name: str) -> str:
    """The command-line spelling of an option's name: ``gpus_per_job`` -> ``--gpus-per-job``."""
    return "--" + name.replace("_", "-")


@dataclass(frozen=True)
class Flag(Param):
    """A declared option written ``--name-with-dashes VALUE`` on the command line (``metavar``: VALUE)."""

    metavar: str | None = None

    @property
    def flag(self) -> str:
        return flag_name(self.name)

    def require(self, value: Any) -> Any:
        """``value`` given from Python (a library call's guard), checked as the flag is: SpecError ``--jobs:
        must be in [1, 256], got 0`` otherwise."""
        try:
            return self.check(value)
        except BadValue as exc:
            raise SpecError(f"{self.flag}: {exc}") from None


def section_flags(cls: type) -> dict[str, Flag]:
    """The options of the section ``cls`` (declared with :func:`~lfbench.utils.options.option`) as command-line
    flags, by name: each with its type, default, help, bounds and ``metavar`` as declared there, so that a value
    given as a flag and one given in a table or from Python are the same declaration (every option has a
    default: a flag is never required)."""
    flags = {}
    for f, opt, kind in option_fields(cls):
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore[misc]
        flags[f.name] = Flag(f.name, kind, default, opt.help, opt.bounds if opt.bounds.text() else None, opt.metavar)
    return flags


@dataclass(frozen=True, kw_only=True)
class SharedFlags:
    """The flags several commands share (``--jobs`` of evaluate, synth and ablate, ...), declared once."""

    jobs: int = option(1, help="worker processes at a time (1: all in this process)", low=1, high=MAX_JOBS,
                       metavar="N")
    seed: int = option(0, help="seed of the generator (a 64-bit signed integer, as in TOML configs)", low=0,
                       high=2**63 - 1, metavar="SEED")
    scenes: int = option(4, help="number of generated scenes", low=1, high=1000, metavar="K")
    device: str | None = option(None, help="where networks run: auto, cpu, cuda or cuda:K", metavar="DEVICE")
    repeat: int = option(1, help="timed runs per case", low=1, high=10**6, metavar="N")
    threads: int = option(0, help="torch CPU threads (0 = all cores)", low=0, high=4096, metavar="N")
    timeout: float | None = option(None, help="give up a case after S seconds", low=0, high=1e12, low_open=True,
                                   metavar="S")
    max_memory: float | None = option(None, help="memory budget of inference in GB (default: 4 on the CPU, the "
                                      "GPU's free memory on CUDA)", low=0, high=1e12, low_open=True, metavar="GB")


_SHARED = section_flags(SharedFlags)
JOBS, SEED, SCENE_COUNT, DEVICE, REPEAT, THREADS, TIMEOUT, MAX_MEMORY = (
    _SHARED[name] for name in ("jobs", "seed", "scenes", "device", "repeat", "threads", "timeout", "max_memory"))
#: Bounds of a positive float (``--timeout``, ``--max-memory``, a bench's ``--interval``).
POSITIVE = Bounds(0, 1e12, low_open=True)

#: Every shared flag, in the order docs/command-line.md lists them.
FLAGS: tuple[Flag, ...] = (JOBS, SEED, SCENE_COUNT, DEVICE, REPEAT, THREADS, TIMEOUT, MAX_MEMORY)
