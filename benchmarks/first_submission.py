"""What scoring one submission costs against its floor, in one run (issue 39.7).

    python benchmarks/first_submission.py --work /tmp/first --out results/bench/first_submission --rounds 5
    python benchmarks/first_submission.py --work /tmp/first --out results/bench/first_submission \\
        --before /tmp/old-checkout      # also the code of another checkout, interleaved round by round

On the generated 9-scene HCI benchmark of benchmarks/scoring_scale.py (512x512, the stratified scenes with 10x
high-resolution ground truth, every mask; benchmarks/hci_layout.py), one thread, each round measures:

- ``process``: one ``lfbench evaluate --all-metrics`` process on one submission (start-up, imports, reading,
  scoring, writing the tables): CPU seconds (user + system of the child) and wall seconds;
- ``floor``: what no scorer of that submission avoids (scoring_scale.floor, in this process, CPU s): reading the
  scenes' ground truth and masks at the resolutions their metrics are scored at, then the submission's maps and
  one numpy pass over the same pixels; ``floor_process``: the same in a fresh interpreter (start-up and the numpy
  import included; CPU and wall), the floor of a whole process;
- with ``--before DIR``: the same ``lfbench evaluate`` with DIR's ``lfbench`` first on sys.path (a checkout of an
  earlier commit), in the same round.

Writes OUT/first_submission.json (every round) and OUT/first_submission.md (medians, ratios). Speed is measured
here, never in the tests. The cores of this machine are shared: CPU seconds are the numbers to compare.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one thread, as scoring_scale
    os.environ.setdefault(_var, "1")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))


def _child(cmd: list[str], env: dict[str, str] | None = None, cwd: Path | None = None) -> dict[str, float]:
    """Wall and CPU seconds (user + system) of one child process; it must exit 0. ``cwd``: a folder without an
    lfbench/ of its own (``python -m`` puts the working folder before PYTHONPATH)."""
    before, start = os.times(), time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, env=env, cwd=cwd)
    wall, after = time.perf_counter() - start, os.times()
    return {"cpu_s": (after.children_user - before.children_user) + (after.children_system - before.children_system),
            "wall_s": wall}


def evaluate_process(root: Path, sub: Path, out: Path, pythonpath: Path | None = None) -> dict[str, float]:
    env = dict(os.environ)
    if pythonpath is not None:
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(pythonpath), env.get("PYTHONPATH")) if p)
    return _child([sys.executable, "-m", "lfbench", "-q", "evaluate", "--data", str(root), "--method",
                   f"published:path={sub}", "--all-metrics", "--out", str(out), "--no-progress"], env, root.parent)


def floor_process(root: Path, subs: Path) -> dict[str, float]:
    """The floor (scoring_scale.floor of one method) in a fresh interpreter: start-up and imports included."""
    code = (f"import sys; sys.path.insert(0, {str(HERE)!r}); import scoring_scale as s; from pathlib import Path; "
            f"s.retain_freed_memory(); s.floor(Path({str(root)!r}), Path({str(subs)!r}), 1)")
    return _child([sys.executable, "-c", code], cwd=root.parent)


def build(work: Path) -> tuple[Path, Path]:
    from hci_layout import write_benchmark, write_submissions

    from lfbench.data.hci import HCIDataset

    root, subs = work / "issue9", work / "subs"
    if not (subs / "m000").is_dir():
        write_benchmark(root, "issue", size=512, scale=10)
        write_submissions(subs, [(s.name, s.gt_disparity()) for s in HCIDataset.open(root) if s.has_gt()], 1)
    return root, subs


def bytecode_cached(before: Path | None) -> list[str]:
    """Compile the timed packages' modules to bytecode first, as an installed package has them: a process that
    finds no ``__pycache__`` compiles every module it imports (~0.4 CPU s for lfbench), and where
    PYTHONDONTWRITEBYTECODE is set (as on the project machines) it does so in every round, a cost no user
    pays twice. Returns the folders compiled."""
    import compileall

    import lfbench

    folders = [Path(lfbench.__file__).resolve().parent, HERE]
    if before is not None:
        folders.append(before / "lfbench")
    for folder in folders:
        if not compileall.compile_dir(str(folder), quiet=1):
            raise SystemExit(f"first_submission: {folder} does not compile")
    return [str(f) for f in folders]


def run(work: Path, rounds: int, before: Path | None) -> dict:
    import logging

    import numpy as np
    from scoring_scale import floor, retain_freed_memory

    logging.getLogger("lfbench").setLevel(logging.ERROR)
    retain_freed_memory()  # as scoring does (lfbench.runs.runner.score_task)
    root, subs = build(work)
    compiled = bytecode_cached(before)
    rows = []
    evaluate_process(root, subs / "m000", work / "warm")  # page cache
    for k in range(rounds):
        row = {"floor": floor(root, subs, 1), "floor_process": floor_process(root, subs),
               "process": evaluate_process(root, subs / "m000", work / f"out_{k}")}
        if before is not None:
            row["before"] = evaluate_process(root, subs / "m000", work / f"before_{k}", before)
        row["load"] = os.getloadavg()[0]
        rows.append(row)
    same = (work / "out_0" / "results.csv").read_bytes() == (work / "warm" / "results.csv").read_bytes()
    if before is not None:
        same &= (work / "before_0" / "results.csv").read_bytes() == (work / "warm" / "results.csv").read_bytes()
    return {"machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(), "threads": 1,
                        "python": platform.python_version(), "numpy": np.__version__},
            "before": str(before) if before else None, "bytecode_compiled": compiled, "rounds": rows,
            "identical_records": same}


def _median(rows: list[dict], *keys: str) -> float:
    values = []
    for row in rows:
        value = row
        for key in keys:
            value = value[key]
        values.append(value)
    return statistics.median(values)


def summary(r: dict) -> dict[str, float]:
    rows = r["rounds"]
    out = {"floor_cpu_s": _median(rows, "floor", "fixed_s") + _median(rows, "floor", "per_method_s"),
           "floor_process_cpu_s": _median(rows, "floor_process", "cpu_s"),
           "floor_process_wall_s": _median(rows, "floor_process", "wall_s"),
           "process_cpu_s": _median(rows, "process", "cpu_s"), "process_wall_s": _median(rows, "process", "wall_s")}
    if r["before"]:
        out["before_cpu_s"] = _median(rows, "before", "cpu_s")
        out["before_wall_s"] = _median(rows, "before", "wall_s")
    return out


def markdown(r: dict) -> str:
    s = summary(r)
    n = len(r["rounds"])
    loads = [row["load"] for row in r["rounds"]]
    lines = ["# One submission against its floor", "",
             f"9 generated 512x512 HCI scenes (4 with 10x high-resolution ground truth), every metric, one thread; "
             f"{n} rounds, medians; load average {min(loads):.1f} to {max(loads):.1f} on {r['machine']['cores']} "
             f"cores; every timed package's bytecode compiled first, as installed. Records identical across "
             f"runs{' and code' if r['before'] else ''}: {r['identical_records']}.",
             "", "| | CPU s | wall s | CPU / floor | CPU / process floor |", "|---|---:|---:|---:|---:|",
             f"| floor (in process: read gt, masks, maps; one numpy pass) | {s['floor_cpu_s']:.2f} | | 1.00 | |",
             f"| floor as a process (start-up and imports included) | {s['floor_process_cpu_s']:.2f} | "
             f"{s['floor_process_wall_s']:.2f} | {s['floor_process_cpu_s'] / s['floor_cpu_s']:.2f} | 1.00 |"]
    rows = [("before", "`lfbench evaluate`, before"), ("process", "`lfbench evaluate`, one submission")]
    for key, label in rows:
        if f"{key}_cpu_s" in s:
            cpu = s[f"{key}_cpu_s"]
            lines.append(f"| {label} | {cpu:.2f} | {s[f'{key}_wall_s']:.2f} | {cpu / s['floor_cpu_s']:.2f} | "
                         f"{cpu / s['floor_process_cpu_s']:.2f} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--work", type=Path, required=True, help="scratch folder (the generated benchmark, ~450 MB)")
    p.add_argument("--out", type=Path, required=True, help="folder for first_submission.json and .md")
    p.add_argument("--rounds", type=int, default=5, help="rounds, each every measurement once (default 5)")
    p.add_argument("--before", type=Path, default=None,
                   help="a checkout whose lfbench/ is timed beside this one's (put first on PYTHONPATH)")
    args = p.parse_args(argv)
    args.work = args.work.resolve()
    if args.before is not None and not (args.before / "lfbench" / "__init__.py").is_file():
        print(f"first_submission: {args.before} holds no lfbench/ package", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    record = run(args.work, args.rounds, args.before)
    record["summary"] = summary(record)
    (args.out / "first_submission.json").write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    (args.out / "first_submission.md").write_text(markdown(record), encoding="utf-8")
    print(markdown(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
