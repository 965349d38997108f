"""Check new results against golden metrics: exit 1 with a readable diff when any metric worsened
beyond its tolerance, went missing, changed resolution or is not finite (or outside the metric's
range), and exit 1 when nothing was compared (an empty golden file, or every golden scene absent
under --skip-absent-scenes) unless --allow-empty; exit 0 otherwise. The summary line says how many
golden records were compared and how many were skipped, and why. The golden file is validated first
(finite numbers within each metric's range, tolerances narrower than it, known metrics, no
duplicates: exit 2 otherwise); records of NEW absent from it are reported (and fail with
--fail-on-new).

Exit codes: 0 the gate passed; 1 it ran and did not pass (a regression, or nothing compared);
2 the input is unusable (a malformed golden or results file, a bad flag).

With --update, write NEW as the golden file instead (tolerance from --tolerance; refused when NEW
holds no finite record, unless --allow-empty)."""

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
    p.add_argument("--allow-empty", action="store_true",
                   help="pass when nothing was compared (an empty golden file, or every golden scene absent with "
                        "--skip-absent-scenes); by default a gate that compared nothing fails (exit 1)")
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
    from lfbench.results import Results
    from lfbench.runs.regress import check, make_golden, read_golden

    tolerance = _parse_tolerance(args.tolerance)  # checked even without --update: a typo is an error
    if args.update:
        from lfbench.utils.outputs import check_output_file

        args.golden = check_output_file(args.golden)  # before reading NEW (a link: the file it leads to)
    new = Results.read(args.new)  # its names checked (no record twice, no two names of one file name)
    if args.update:
        n = make_golden(new, tolerance, args.golden, source=args.new, allow_empty=args.allow_empty)
        skipped = len(new.records) - n
        print(f"wrote {n} golden records to {args.golden}"
              + (f" ({skipped} non-finite values left out)" if skipped else ""))
        return 0
    golden = read_golden(args.golden)
    result = check(golden, new, skip_absent_scenes=args.skip_absent_scenes, fail_on_new=args.fail_on_new,
                   allow_empty=args.allow_empty)
    for f in result.findings:
        if f.failed or not args.quiet:
            print(f.message)
    print(result.summary())
    hint = result.stale_hint(args.golden, args.new)
    if hint:
        print(hint)
    return 0 if result.passed else 1
