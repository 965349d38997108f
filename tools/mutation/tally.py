"""Count mutmut's verdicts per mutated file, with the survivors classify.py explains and those it does not.

Reads mutants/**/*.py.meta (what `mutmut run` wrote, finished or not) and writes a Markdown table: per file the
mutants, killed, timeouts, survivors (explained / known not killed / unexplained, by classify.py's reasons),
mutants no test reached, and those not run yet; then the unexplained survivors' functions. ``--recheck``: reports
of recheck_import_time.py, whose "killed" verdicts count as killed. ``--fresh``: mutants re-run in fresh
processes (a file of names, one per line, with the verdict after a tab: killed / survived), which override the
mutants folder's verdicts (mutmut's forked runs see no mutant of a function that ran before the fork).
``--listing``: `mutmut results` of earlier runs of the same code (the mutants they did not kill, a line each; runs of
other files each): the verdicts of the mutants this folder has not run, those they leave out counted as killed;
for a folder made again to tally earlier runs whose folders are gone, with the verdicts of the mutants run since.

    python tools/mutation/tally.py --mutants mutants --out results/mutation/full_run/tally.md
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from collections import Counter
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from classify import NOT_KILLED, reason_of  # noqa: E402
from mutmut.stats import status_by_exit_code  # noqa: E402  mutmut's own reading of its exit codes
from survivors import ROOT, SURVIVED, survivors  # noqa: E402

# mutmut's statuses -> this table's columns (a crash or SIGKILL of the tests, "segfault", detected the mutant)
COLUMN_OF = {"killed": "killed", "segfault": "killed", "timeout": "timeout", "no tests": "no tests",
             "not checked": "not run"}
COLUMNS = ("mutants", "killed", "timeout", "survived: explained", "known, not killed", "unexplained", "no tests",
           "not run")


def read_listing(path: Path) -> dict[str, str]:
    """The statuses of a `mutmut results` listing ("    name: status" lines), by mutant name."""
    statuses = {}
    for line in path.read_text(encoding="utf-8").splitlines():
        name, sep, status = line.strip().rpartition(": ")
        if sep:
            statuses[name] = status
    return statuses


def tally(mutants: Path, killed_elsewhere: set[str], listing: dict[str, str] | None = None
          ) -> tuple[dict[str, Counter], Counter]:
    """Per file (path under mutants/) a Counter of COLUMNS; and the unexplained survivors' functions. ``listing``:
    the statuses of an earlier run for the mutants not run here (absent: killed)."""
    diffs = {name: diff for name, _, diff in survivors(mutants, (SURVIVED, None) if listing else (SURVIVED,))}
    rows: dict[str, Counter] = {}
    unexplained: Counter = Counter()
    for meta in sorted(mutants.rglob("*.py.meta")):
        row = rows.setdefault(str(meta.relative_to(mutants).with_suffix("")), Counter())
        for name, code in json.loads(meta.read_text(encoding="utf-8"))["exit_code_by_key"].items():
            row["mutants"] += 1
            if code is None and listing is not None:
                status = listing.get(name, "killed")
            else:
                status = status_by_exit_code[code]
            if name in killed_elsewhere:
                row["killed"] += 1
            elif status in COLUMN_OF:
                row[COLUMN_OF[status]] += 1
            elif status == "survived":
                reason = reason_of(name, diffs.get(name, ""))
                column = ("unexplained" if reason is None else "known, not killed" if reason.startswith(NOT_KILLED)
                          else "survived: explained")
                row[column] += 1
                if reason is None:
                    unexplained[re.sub(r"__mutmut_\d+$", "", name)] += 1
            else:
                row[status] += 1
    return rows, unexplained


def markdown(rows: dict[str, Counter], unexplained: Counter) -> str:
    extra = sorted({k for row in rows.values() for k in row if k not in COLUMNS})
    head = ["file", *COLUMNS, *extra, "killed + timeout of run"]
    lines = ["| " + " | ".join(head) + " |", "|" + " --- |" * len(head)]
    total: Counter = Counter()
    for file, row in [*rows.items(), ("**total**", None)]:
        row = total if row is None else row
        if row is not total:
            total.update(row)
        run = row["mutants"] - row["not run"]
        share = f"{100 * (row['killed'] + row['timeout']) / run:.1f} %" if run else "-"
        lines.append("| " + " | ".join([file, *(str(row[c]) for c in (*COLUMNS, *extra)), share]) + " |")
    body = "\n".join(lines)
    funcs = "\n".join(f"- `{name}`: {n}" for name, n in sorted(unexplained.items())) or "- none"
    return ("# Mutants per file\n\nWritten by `python tools/mutation/tally.py` (see README.md beside it).\n\n"
            f"{body}\n\n## Unexplained survivors by function\n\n{funcs}\n")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mutants", type=Path, default=ROOT / "mutants")
    parser.add_argument("--recheck", type=Path, nargs="*", default=[])
    parser.add_argument("--fresh", type=Path, nargs="*", default=[])
    parser.add_argument("--listing", type=Path, nargs="+", help="`mutmut results` of earlier runs of the same code "
                                                                   "(of other files each)")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    killed = set()
    for report in args.recheck:
        killed |= {n for n, v in json.loads(report.read_text(encoding="utf-8"))["verdicts"].items() if v == "killed"}
    for fresh in args.fresh:
        for line in fresh.read_text(encoding="utf-8").splitlines():
            name, _, verdict = line.partition("\t")
            if verdict.strip() == "killed":
                killed.add(name.strip())
    listing = None if args.listing is None else {k: v for path in args.listing for k, v in read_listing(path).items()}
    rows, unexplained = tally(args.mutants, killed, listing)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(markdown(rows, unexplained), encoding="utf-8")
    print(f"{sum(unexplained.values())} unexplained survivors in {len(unexplained)} functions")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
