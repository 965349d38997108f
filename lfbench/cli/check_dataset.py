"""Check a dataset's adapter, then from the dataset's own ground truth that lfbench reads its view grid and
disparity sign the way the data was made.

First the adapter's contract (lfbench.data.adapter_check: its name, summary and protocol, its scenes' angular
and spatial sizes, views, ground truth, and that each scene pickles back as a ``--jobs`` worker rebuilds it):
one line per broken promise on stderr, exit 2; when it holds, one line saying so (``--adapter-only`` stops
there). Then every view of the centre's row, column and diagonals is warped onto the centre view by the
ground-truth disparity under each of the 8 readings of the grid (lfbench.data.orientation), and the reading
with the least photometric error is the data's. One line per scene with ground truth, then a summary. Exit 0
when no scene contradicts lfbench's reading, 1 when one does (the line says what to change), 2 on bad input
(no data root, an unknown layout, no scene with ground truth).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

HELP = ("check a dataset adapter's contract, then from the ground truth that lfbench reads the view grid and disparity "
        "sign as the data was made")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", type=Path, metavar="ROOT", help="data root of a known dataset (see `lfbench datasets`)")
    p.add_argument("--dataset", metavar="NAME", help="read ROOT as this dataset instead of detecting its layout")
    p.add_argument("--scenes", default="", help="comma-separated scene, category or split names (default: all)")
    p.add_argument("--details", action="store_true", help="the error of every reading under each scene")
    p.add_argument("--adapter-only", action="store_true",
                   help="check only the dataset adapter's contract (no ground truth needed)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from lfbench.data.adapter_check import check_adapter
    from lfbench.data.dataset import open_datasets
    from lfbench.data.orientation import AS_READ, check_orientation, has_centre_view
    from lfbench.utils.errors import DataError

    dataset, protocol, bench = open_datasets([args.data], args.dataset)
    border = protocol.border_px
    scenes = bench.select([s for s in args.scenes.split(",") if s.strip()])
    adapter = check_adapter(dataset, args.data, protocol, scenes, progress=lambda it: tqdm(
        it, desc="adapter", unit="scene", total=len(scenes), disable=args.no_progress, leave=False))
    for problem in adapter.problems:
        print(f"lfbench check-dataset: error: {DataError(problem)}", file=sys.stderr)  # DataError: one visible line
    if not adapter.holds:
        return 2
    print(adapter.summary())
    if args.adapter_only:
        return 0
    with_gt = [s for s in scenes if s.has_gt()]
    if not with_gt:
        raise DataError(f"none of the selected scenes has ground truth to check against ({dataset.name})", args.data)
    for scene in with_gt:  # before any work: the readings turn the grid about its centre view
        rows, cols = scene.angular_size
        if not has_centre_view(rows, cols):
            raise DataError(f"the view grid is {rows}x{cols}: check-dataset needs a centre view (odd rows and "
                            "columns)", scene.path)
    checks = []
    for scene in tqdm(with_gt, desc="check-dataset", unit="scene", disable=args.no_progress, leave=False):
        check = check_orientation(scene.name, scene.gray_views(), scene.gt_disparity(), border_px=border)
        scene.release_views()  # one scene's views in memory at a time
        checks.append(check)
        best, runner_up, ratio = check.best, check.runner_up, check.ratio
        said = (f"{scene.name}: {best.name}: mean error {check.errors[best]:.4f} against {check.errors[runner_up]:.4f} "
                f"({runner_up.name}), {ratio:.2f}x")
        if not math.isfinite(check.errors[best]):
            said += f" - undecided (no pixel of the centre view inside the {border} px border samples another view)"
        elif not check.decided:
            said += " - undecided (too little disparity or texture to tell the readings apart)"
        elif best is not AS_READ:
            said += f" - CONTRADICTS lfbench's reading ({dataset.name}); a TOML dataset would {best.toml_fix}"
        print(said)
        if args.details:
            for orientation, error in sorted(check.errors.items(), key=lambda kv: kv[1]):
                print(f"    {error:.4f}  {orientation.name}")
    agree = sum(c.agrees for c in checks)
    contradict = sum(c.decided and not c.agrees for c in checks)
    undecided = len(checks) - agree - contradict
    print(f"{dataset.name} at {args.data}: {agree} of {len(checks)} scenes with ground truth agree with lfbench's "
          f"reading, {contradict} contradict it, {undecided} undecided; {len(scenes) - len(with_gt)} without ground "
          "truth")
    return 1 if contradict else 0
