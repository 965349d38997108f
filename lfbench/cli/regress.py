"""Check new results against golden metrics: exit 1 with a readable diff when any metric worsened
beyond its tolerance, went missing, changed resolution or is not finite; exit 0 otherwise. The
golden file is validated first (finite numbers, known metrics, no duplicates: exit 2 otherwise);
records of NEW absent from it are reported (and fail with --fail-on-new).

With --update, write NEW as the golden file instead (tolerance from --tolerance)."""

from __future__ import annotations

import argparse
from pathlib import Path

HELP = "compare results with golden metrics (CI regression check)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("golden", type=Path,
                   help="golden JSON: list of {method, scene, metric, value, tolerance, resolution}")
    p.add_argument("new", type=Path, help="new results.json (or the folder holding it)")
    p.add_argument("--update", action="store_true", help="write NEW's records as the golden file instead of checking")
    p.add_argument("--tolerance", default="0.001", metavar="T|metric=T,...",
                   help="tolerance for --update: one number, or per metric id or METHOD/METRIC glob, e.g. "
                        "'*=0.01,mse_x100=0.005,published*/*=1e-6' (METHOD/METRIC keys win)")
    p.add_argument("--skip-absent-scenes", action="store_true",
                   help="ignore golden records of scenes absent from NEW (e.g. real scenes when the data is not here)")
    p.add_argument("--fail-on-new", action="store_true",
                   help="fail when NEW holds records that the golden file lacks (default: report them only)")
    p.add_argument("--quiet", action="store_true", help="print only failures and the summary")


def _parse_tolerance(text: str):
    from lfbench.runs.regress import check_tolerance
    from lfbench.utils.errors import SpecError

    try:
        if "=" not in text:
            tolerance = float(text)
        else:
            tolerance = {k.strip(): float(v) for k, v in (item.split("=", 1) for item in text.split(","))}
    except ValueError:
        raise SpecError(f"--tolerance: cannot parse {text!r}") from None
    try:
        check_tolerance(tolerance)
    except SpecError as exc:
        raise SpecError(f"--tolerance {text!r}: {exc}") from None
    return tolerance


def run(args: argparse.Namespace) -> int:
    from lfbench.runs.regress import check_unique, compare, make_golden, read_golden
    from lfbench.runs.results import Results

    tolerance = _parse_tolerance(args.tolerance)  # checked even without --update: a typo is an error
    new = Results.read(args.new)
    if args.update:
        n = make_golden(new, tolerance, args.golden, source=args.new)
        skipped = len(new.records) - n
        print(f"wrote {n} golden records to {args.golden}"
              + (f" ({skipped} non-finite values left out)" if skipped else ""))
        return 0
    check_unique(new, args.new)
    golden = read_golden(args.golden)
    findings = compare(golden, new, skip_absent_scenes=args.skip_absent_scenes, fail_on_new=args.fail_on_new)
    failed = [f for f in findings if f.failed]
    for f in findings:
        if f.failed or not args.quiet:
            print(f.message)
    better = sum(f.kind == "better" for f in findings)
    new_records = sum(f.kind == "new" for f in findings)
    status = "FAIL" if failed else "OK"
    print(f"{status}: {len(golden)} golden metrics, {len(failed)} regressions, {better} improved beyond tolerance"
          + (f", {new_records} new records not in the golden file" if new_records else ""))
    return 1 if failed else 0
