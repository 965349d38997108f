"""Re-run mutants, each in a fresh process, against given test files; write one "name<TAB>verdict" line each.

For survivors of a `mutmut run` that tests written afterwards may kill, without a new whole run: each mutant's
tests run in a new Python importing the mutated package (mutants/) with the mutant switched on, as
recheck_import_time.py does (so a function that ran before mutmut's fork is mutated too). By default the
mutants are the mutants folder's survivors and those no test reached, whose change classify.py does not explain.

    python tools/mutation/fresh_verdicts.py --tests tests/test_scoring_mutants_full.py ... \\
        --out results/mutation/full_run/fresh_verdicts.tsv
"""

from __future__ import annotations

import argparse
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent))
from classify import reason_of  # noqa: E402
from recheck_import_time import MUTANTS, killed_in_fresh_process  # noqa: E402
from survivors import NO_TESTS, SURVIVED, survivors  # noqa: E402


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tests", nargs="+", required=True, help="test files run for each mutant")
    parser.add_argument("--names", type=Path, help="a file of mutant names, one per line (default: the "
                                                    "survivors and no-test mutants classify.py does not explain)")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    if args.names is not None:
        todo = [n.strip() for n in args.names.read_text(encoding="utf-8").splitlines() if n.strip()]
    else:
        todo = [n for n, _, diff in survivors(MUTANTS, (SURVIVED, NO_TESTS)) if reason_of(n, diff) is None]
    if killed_in_fresh_process("none_such", tuple(args.tests)):
        raise SystemExit("the tests fail with no mutant switched on: fix them first")
    with ThreadPoolExecutor(args.jobs) as pool:
        verdicts = list(pool.map(lambda m: killed_in_fresh_process(m, tuple(args.tests)), todo))
    lines = [f"{name}\t{'killed' if killed else 'survived'}" for name, killed in zip(todo, verdicts, strict=True)]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    print(f"{sum(verdicts)} of {len(todo)} killed in a fresh process")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
