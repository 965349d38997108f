"""List mutmut's surviving mutants with the change each makes, after `mutmut run` (`nox -s mutation`).

Reads the verdicts from mutants/**/*.py.meta and each mutant's code from mutants/**/*.py (mutmut keeps
the original of every mutated function as ``x_<name>__mutmut_orig`` and mutant N as
``x_<name>__mutmut_N``); prints one block per survivor: its name and the unified diff of its function.
With ``--recheck`` (the report of recheck_import_time.py), mutants killed there in a fresh process are left
out and those it re-ran and saw survive are marked.

    python tools/mutation/survivors.py --recheck results/mutation/recheck_import_time.json \
        > results/mutation/survivors.txt
"""

from __future__ import annotations

import argparse
import ast
import difflib
import json
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SURVIVED = 0  # mutmut's exit code for a mutant whose tests passed
NO_TESTS = 33


def _functions(source: str) -> dict[str, str]:
    """Top-level and class-level function name -> source text (mutmut's mangled names)."""
    tree = ast.parse(source)
    lines = source.splitlines()
    out: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and "__mutmut_" in node.name:
            out[node.name] = "\n".join(lines[node.lineno - 1:node.end_lineno])
    return out


def survivors(mutants: Path, codes: tuple[int, ...]) -> list[tuple[str, int, str]]:
    """(mutant name, exit code, diff) for every mutant whose exit code is in ``codes``, in file order."""
    rows = []
    for meta_path in sorted(mutants.rglob("*.py.meta")):
        meta = json.loads(meta_path.read_text(encoding="utf-8"))
        funcs = _functions(meta_path.with_suffix("").read_text(encoding="utf-8"))
        for name, code in meta["exit_code_by_key"].items():
            if code not in codes:
                continue
            local = name.rsplit(".", 1)[-1]  # x_func__mutmut_N (class methods: xǁClassǁmethod__mutmut_N)
            base = re.sub(r"__mutmut_\d+$", "", local)
            orig, mutant = funcs.get(f"{base}__mutmut_orig", ""), funcs.get(local, "")
            diff = difflib.unified_diff(orig.replace(f"{base}__mutmut_orig", base).splitlines(),
                                        mutant.replace(local, base).splitlines(), lineterm="", n=1)
            rows.append((name, code, "\n".join(list(diff)[2:])))
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mutants", type=Path, default=ROOT / "mutants")
    parser.add_argument("--no-tests", action="store_true", help="also list mutants no test reaches")
    parser.add_argument("--recheck", type=Path, nargs="+", help="recheck_import_time.py's JSON reports (a later "
                        "one's verdict wins)")
    args = parser.parse_args()
    codes = (SURVIVED, NO_TESTS) if args.no_tests else (SURVIVED,)
    verdicts = {}
    for report in args.recheck or ():
        verdicts.update(json.loads(report.read_text(encoding="utf-8"))["verdicts"])
    rows = [row for row in survivors(args.mutants, codes) if verdicts.get(row[0]) != "killed"]
    print(f"# {len(rows)} surviving mutants ({sum(v == 'killed' for v in verdicts.values())} more were killed "
          "when re-run in a fresh process: recheck_import_time.json)\n")
    for name, code, diff in rows:
        tag = "  (no tests)" if code == NO_TESTS else "  (survived in a fresh process too)" if name in verdicts else ""
        print(f"=== {name}{tag}\n{diff}\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
