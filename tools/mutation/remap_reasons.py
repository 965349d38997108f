"""Carry classify.py's per-mutant reasons over a refactor: find each named mutant again in the moved code.

classify.py names the survivors it explains one by one (``scoring.metrics.x_bad_pix__mutmut_16``); a name is
the module, the function and mutmut's number within the function, so moving a function to another module,
renaming it or editing the function changes the name. This script generates the mutants of the code the
reasons were written for (``--old COMMIT``, the files of its ``[tool.mutmut] only_mutate``) and of the working
tree (the current ``only_mutate``) with mutmut's own generator (no tests are run), and matches each named
mutant by its change: the same function and the same removed and added lines (the old code's with the
``--rename`` replacements made, whitespace ignored); among identical changes in one function, the one with
the same number. It prints the mapping and the names it cannot find (code that is gone or was rewritten:
their survivors are classified afresh by the next ``nox -s mutation``); ``--write`` rewrites the names in
classify.py. Issue 21's move of the scoring code was carried over with

    python tools/mutation/remap_reasons.py --old b93fa51 --rename _prepare=check_maps \\
        --rename _percentage=percent_of --rename _bad_pix_metric=bad_pix_metric \\
        --rename _badpix_family=badpix_family --rename "scene: Scene,=scene: Scene | SceneReference," --write
"""

from __future__ import annotations

import argparse
import difflib
import re
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

from mutmut.mutation.file_mutation import mutate_file_contents

sys.path.insert(0, str(Path(__file__).parent))
from classify import REASONS  # noqa: E402
from survivors import ROOT, _functions  # noqa: E402

Change = tuple[str, str, str]  # (function, removed lines, added lines)


#: What issue 25 mutated, for a commit whose pyproject.toml has no [tool.mutmut] yet (the run of b93fa51)
ISSUE25_FILES = ["lfbench/scoring/metrics.py", "lfbench/scoring/rules.py", "lfbench/scoring/region_metrics.py",
                 "lfbench/runs/regress.py"]


def only_mutate(root: Path) -> list[str]:
    config = tomllib.loads((root / "pyproject.toml").read_text(encoding="utf-8"))
    return config.get("tool", {}).get("mutmut", {}).get("only_mutate", ISSUE25_FILES)


def changes(root: Path, files: list[str]) -> dict[str, Change]:
    """Mutant name (as classify.py writes it) -> its change, for every mutant of ``files`` under ``root``."""
    out: dict[str, Change] = {}
    for rel in files:
        mutated = mutate_file_contents(rel, (root / rel).read_text(encoding="utf-8"))
        funcs = _functions(mutated.code)
        module = rel.removeprefix("lfbench/").removesuffix(".py").replace("/", ".")
        for local in mutated.mutant_names:
            base = re.sub(r"__mutmut_\d+$", "", local)
            orig, mutant = funcs.get(f"{base}__mutmut_orig", ""), funcs.get(local, "")
            diff = list(difflib.unified_diff(orig.replace(f"{base}__mutmut_orig", base).splitlines(),
                                             mutant.replace(local, base).splitlines(), lineterm="", n=0))[2:]
            removed = " ".join(line[1:] for line in diff if line.startswith("-"))
            added = " ".join(line[1:] for line in diff if line.startswith("+"))
            out[f"{module}.{local}"] = (base, removed, added)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", required=True, help="the commit whose code classify.py's names refer to")
    parser.add_argument("--rename", action="append", default=[], metavar="OLD=NEW",
                        help="a name the refactor renamed (functions, and calls in the changed lines)")
    parser.add_argument("--write", action="store_true", help="rewrite the names in classify.py")
    args = parser.parse_args()
    renames = [tuple(r.split("=", 1)) for r in args.rename]

    def norm(text: str, renamed: bool = False) -> str:
        """``text`` without whitespace; with the renames applied when it is the old code's."""
        for old, new in renames if renamed else ():
            text = text.replace(old, new)
        return re.sub(r"\s+", "", text)

    with tempfile.TemporaryDirectory() as tmp:
        archive = subprocess.run(["git", "archive", args.old, "lfbench", "pyproject.toml"], cwd=ROOT,
                                 capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", tmp], input=archive, check=True)
        old = changes(Path(tmp), only_mutate(Path(tmp)))
    new = changes(ROOT, only_mutate(ROOT))
    found: dict[Change, list[str]] = {}
    for name, (func, removed, added) in new.items():
        found.setdefault((norm(func), norm(removed), norm(added)), []).append(name)
    mapping, lost = {}, []
    for name in (n for names in REASONS.values() for n in names):
        if name not in old:
            lost.append(f"{name}: not a mutant of {args.old}")
            continue
        func, removed, added = old[name]
        hits = found.get((norm(func, True), norm(removed, True), norm(added, True)), [])
        same = [h for h in hits if h.rsplit("__mutmut_", 1)[1] == name.rsplit("__mutmut_", 1)[1]]
        if len(hits) == 1 or len(same) == 1:
            mapping[name] = hits[0] if len(hits) == 1 else same[0]
        else:
            lost.append(f"{name}: {len(hits)} mutants make its change -{removed.strip()[:70]} +{added.strip()[:70]}")
    for name, moved in mapping.items():
        if moved != name:
            print(f"{name} -> {moved}")
    for line in lost:
        print(f"NOT FOUND {line}")
    print(f"{len(mapping)} of {len(mapping) + len(lost)} named mutants found, "
          f"{sum(a != b for a, b in mapping.items())} under a new name")
    if args.write:
        path = Path(__file__).with_name("classify.py")
        text = path.read_text(encoding="utf-8")
        for name, moved in mapping.items():
            text = text.replace(f'"{name}"', f'"{moved}"')
        path.write_text(text, encoding="utf-8")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
