"""Re-run, each in a fresh process, the surviving mutmut mutants of functions that run at import.

mutmut runs a mutant's tests in a process forked after lfbench was imported, with the tests it saw reach
the mutated function. Functions that run while lfbench is imported (the metric definitions, the registry)
therefore never run mutated there, and are credited to whichever test was collecting at the time: their
mutants "survive" whatever the tests check. This script finds those functions (it imports the mutated
package with mutmut's call recording on), then runs each of their surviving mutants in a fresh Python
process that imports the mutated package with the mutant switched on, against the scoring tests.

    python tools/mutation/recheck_import_time.py --out results/mutation/recheck_import_time.json

Run after `mutmut run` (from the repository root; `nox -s mutation` does both).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(Path(__file__).parent))
MUTANTS = ROOT / "mutants"
MODULES = ("lfbench.scoring.base", "lfbench.scoring.general", "lfbench.scoring.rules", "lfbench.scoring.pixels",
           "lfbench.scoring.prepare", "lfbench.scoring.region_metrics", "lfbench.scoring.metrics",
           "lfbench.scoring.score", "lfbench.runs.regress", "lfbench.scoring.pixelwise", "lfbench.data.disparity",
           "lfbench.utils.readfile")
# the tests of the metric definitions and the registry (what runs at import): first those that build what they check
# in their own body (fast: -x stops at the first failure), then the definitions table
TESTS = ("tests/test_scoring_mutants_late.py", "tests/test_scoring_mutants_full.py",
         "tests/test_scoring_edges.py", "tests/test_scoring_engine_mutants.py", "tests/test_metrics.py",
         "tests/test_region_metrics.py", "tests/test_prepare.py", "tests/test_scoring_engine.py")
# subprocesses: they import the unmutated code
DESELECT = ("tests/test_region_metrics.py::test_cli_evaluate_all_metrics",
            "tests/test_scoring_engine.py::test_cli_jobs_option",
            "tests/test_scoring_engine.py::test_scale_benchmark_quick_run")
SURVIVED = 0

_HITS = """
import json
from mutmut.state import state
import {modules}
print(json.dumps(sorted(state()._stats)))
"""


def _env(mutant: str) -> dict[str, str]:
    # PYTHONPATH puts the mutated copy before the editable install; -P keeps the current folder off sys.path
    return {**os.environ, "PYTHONPATH": str(MUTANTS), "MUTANT_UNDER_TEST": mutant}


def import_time_functions() -> set[str]:
    """Qualified mutmut names (module.x_function) of the mutated functions that run at import."""
    code = _HITS.format(modules=", ".join(MODULES))
    out = subprocess.run([sys.executable, "-P", "-c", code], cwd=MUTANTS, env=_env("stats"), capture_output=True,
                         text=True, check=True).stdout
    return set(json.loads(out.strip().splitlines()[-1]))


def survivors() -> list[str]:
    names = []
    for meta in sorted(MUTANTS.rglob("*.py.meta")):
        codes = json.loads(meta.read_text(encoding="utf-8"))["exit_code_by_key"]
        names += [name for name, code in codes.items() if code == SURVIVED]
    return names


def killed_in_fresh_process(mutant: str, tests: tuple[str, ...] = TESTS) -> bool:
    cmd = [sys.executable, "-P", "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", *tests,
           *(f"--deselect={d}" for d in DESELECT)]
    return subprocess.run(cmd, cwd=MUTANTS, env=_env(mutant), stdout=subprocess.DEVNULL,
                          stderr=subprocess.DEVNULL).returncode != 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--jobs", type=int, default=2, help="test processes at once")
    parser.add_argument("--tests", nargs="+", default=list(TESTS), help="test files (default: %(default)s)")
    parser.add_argument("--only", nargs="+", help="re-check only these mutants (full mutmut names)")
    parser.add_argument("--skip-explained", action="store_true",
                        help="leave out survivors whose change classify.py explains by its rules (presentation "
                             "fields, copy flags, float('NAN')): a partial run's shortcut")
    args = parser.parse_args()
    at_import = import_time_functions()
    todo = [m for m in survivors() if re.sub(r"__mutmut_\d+$", "", m) in at_import]
    if args.only:
        todo = [m for m in todo if m in args.only]
    if args.skip_explained:
        from classify import reason_of
        from survivors import SURVIVED as CODE
        from survivors import survivors as with_diffs
        diffs = {name: diff for name, _, diff in with_diffs(MUTANTS, (CODE,))}
        todo = [m for m in todo if reason_of(m, diffs[m]) is None]
    print(f"{len(todo)} surviving mutants of {len(at_import)} functions that run at import", flush=True)
    verdicts = {}
    with ThreadPoolExecutor(args.jobs) as pool:
        results = pool.map(lambda m: killed_in_fresh_process(m, tuple(args.tests)), todo)
        for i, (mutant, killed) in enumerate(zip(todo, results, strict=True), 1):
            verdicts[mutant] = "killed" if killed else "survived"
            print(f"[{i}/{len(todo)}] {verdicts[mutant]:8} {mutant}", flush=True)
    report = {"import_time_functions": sorted(at_import), "tests": args.tests, "deselected": list(DESELECT),
              "verdicts": verdicts}
    args.out.write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    n_killed = sum(v == "killed" for v in verdicts.values())
    print(f"{n_killed} of {len(verdicts)} killed in a fresh process")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
