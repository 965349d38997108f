"""Generate synthetic light fields in the HCI layout with exact ground truth (no dataset needed).

Writes DIR/<category>/synth_<seed>_<i>/ for i = 0..K-1: input_Cam000..png, parameters.cfg,
gt_disp_lowres.pfm, gt_depth_lowres.pfm and evaluation masks (<mask>_lowres.png). The same seed,
size and angular resolution always give the same files. An existing scene folder is an error
unless --force.
"""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "generate synthetic HCI-format scenes with exact ground truth"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", required=True, type=Path, metavar="DIR", help="data root to write into")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--size", type=int, default=128, metavar="S", help="views are S x S px (default 128)")
    p.add_argument("--scenes", type=int, default=4, metavar="K", help="number of scenes (default 4)")
    p.add_argument("--category", default="synthetic", metavar="NAME", help="category folder (default synthetic)")
    p.add_argument("--angular", type=int, default=9, metavar="A", help="A x A views, odd (default 9)")
    p.add_argument("--force", action="store_true", help="overwrite existing scene folders")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="scenes generated at a time in separate processes (default: the available cores)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    import time

    from lfbench.data.synth import write_benchmark
    from lfbench.utils.hardware import available_cores

    start = time.perf_counter()
    paths = write_benchmark(args.out, seed=args.seed, size=args.size, scenes=args.scenes, category=args.category,
                            angular=args.angular, force=args.force, progress=not args.no_progress,
                            workers=available_cores() if args.workers is None else args.workers)
    for path in paths:
        print(path)
    print(f"wrote {len(paths)} scene(s) of {args.size}x{args.size} px, {args.angular}x{args.angular} views "
          f"in {time.perf_counter() - start:.1f} s")
    return 0
