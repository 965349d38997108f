"""Check a benchmark submission (folder or zip) more strictly than the official toolkit: every
expected disp_maps/<scene>.pfm parses as a gray PFM of the right size with finite values only, every
runtimes/<scene>.txt holds one positive number of seconds, no unexpected files, and no zip member
escapes the submission folder. Problems are listed one per line on stdout; exit code 2 if any.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "check a submission folder or zip (disp_maps/*.pfm, runtimes/*.txt)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", type=Path, metavar="DIR|ZIP", help="submission folder or zip file")
    p.add_argument("--scenes", default="",
                   help="comma-separated expected scenes (default: the 12 benchmark scenes)")
    p.add_argument("--size", default="512", metavar="N|WxH", help="size of every disparity map in px (default 512)")


def run(args: argparse.Namespace) -> int:
    from lfbench.data.submission_check import iter_problem_lines, parse_size, validate_submission
    from lfbench.utils.errors import DataError

    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()] or None
    report = validate_submission(args.path, scenes=scenes, size=parse_size(args.size))
    if report.ok:
        print(f"OK: {len(report.scenes)} scenes")
        return 0
    lines = list(iter_problem_lines(report))
    for line in lines:
        print(line)
    sys.stdout.flush()  # the list comes before the one-line error on stderr
    n = len(lines)
    raise DataError(f"invalid submission: {n} problem{'s' if n != 1 else ''} (listed above); first: {lines[0]}",
                    args.path)
