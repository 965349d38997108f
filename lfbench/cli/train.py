"""Train a network from a TOML config (examples: configs/*.toml): SubFocal by default, or any registered
trainable network named by the config's ``method``. Every key of the config, with its type, default, bounds
and meaning: docs/training-config.md (or ``python -m lfbench.training.reference``).

Runs the config's stages in order (e.g. L1, then UAFL from the stage-1 weights with a fresh
optimizer), validating on the chosen scenes every N steps. Checkpoints go to OUT/checkpoint.pt
(atomic); re-running the same command after a kill or Ctrl-C resumes from the last one. The
final weights are OUT/final.pt, runnable as ``METHOD:weights=OUT/final.pt`` (e.g. subfocal). For data-parallel training
start it with torchrun, e.g. ``torchrun --nproc-per-node 4 -m lfbench train CONFIG.toml``.
"""

from __future__ import annotations

import argparse
import os
import shlex
from pathlib import Path

HELP = "train SubFocal or a plugin's network from a TOML config (resumable, multi-process with torchrun)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", type=Path, help="training config (TOML)")
    p.add_argument("--out", type=Path, default=None,
                   help="output folder (default: the config's 'out', else runs/<config name>)")
    p.add_argument("--resume", action="store_true",
                   help="require a checkpoint in OUT to resume from (without it, one is used when present)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar (log lines only)")


def run(args: argparse.Namespace) -> int:
    from lfbench.training.config import TrainConfig, expand_path  # imported here: `lfbench --help` needs no torch
    from lfbench.training.loop import train

    cfg = TrainConfig.from_toml(args.config)
    if args.out is not None:
        out = args.out
    elif cfg.out:
        out = expand_path(cfg.out, cfg.source)
    else:
        out = Path("runs") / args.config.stem
    command = shlex.join(["lfbench", "train", str(args.config), "--out", str(out)]
                         + (["--resume"] if args.resume else []) + (["--no-progress"] if args.no_progress else []))
    world = int(os.environ.get("WORLD_SIZE", "1"))
    if world > 1:
        nproc = os.environ.get("LOCAL_WORLD_SIZE", str(world))
        command = f"torchrun --nproc-per-node {nproc} -m {command}"
    train(cfg, out, require_checkpoint=args.resume, command=command, progress=False if args.no_progress else None)
    return 0
