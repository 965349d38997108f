"""Start-up of the light `lfbench` commands beside a bare interpreter, measured in the same run (issue 32.5).

    python benchmarks/startup.py --out results/bench/startup            # a few minutes (torch's import dominates)
    python benchmarks/startup.py --repeats 3 --out /tmp/startup          # a minute
    python benchmarks/startup.py --before OLD/lfbench --out DIR          # also an older install, in the same turns

Times, as a user starts them, the installed ``lfbench`` console script for ``--help``, ``methods``,
``info planesweep`` and ``evaluate --help``, beside ``python -c pass`` (the floor: an interpreter that
does nothing), ``python -c "import numpy"`` and ``python -c "import torch"`` (what a command pays if it
imports them). Each is a fresh process, run ``--repeats`` times in turns (so that the load of the machine
falls on every command alike); the table gives the median and the fastest wall time and the median
above the floor. Each lfbench command is also run once with ``PYTHONPROFILEIMPORTTIME=1`` (what
``python -X importtime`` prints): the record keeps its slowest top-level imports (cumulative µs), which
say where a start-up goes. Every process runs in an empty temporary folder (nothing is imported from the
current one). ``--before SCRIPT`` times the same lfbench commands through another console script (e.g. one
that puts an older checkout first on ``sys.path``) in the same turns, labelled ``(before)``.

Writes OUT/startup.json and OUT/startup.md. Speed is measured here, never in the tests.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FLOOR = "python -c pass"


LFBENCH_ARGS = (["--help"], ["methods"], ["info", "planesweep"], ["evaluate", "--help"])


def commands(lfbench: str, before: str | None = None) -> dict[str, list[str]]:
    """Label -> argv of every process timed; the lfbench ones through the installed console script (and
    through ``before``, labelled "(before)")."""
    py = sys.executable
    cmds = {FLOOR: [py, "-c", "pass"], "python -c 'import numpy'": [py, "-c", "import numpy"],
            "python -c 'import torch'": [py, "-c", "import torch"]}
    for args in LFBENCH_ARGS:
        cmds[" ".join(["lfbench", *args])] = [lfbench, *args]
        if before is not None:
            cmds[" ".join(["lfbench", *args, "(before)"])] = [before, *args]
    return cmds


def _run(argv: list[str], cwd: Path, env: dict[str, str] | None = None) -> tuple[float, str]:
    """Wall time of one process (s) and its stderr; a failed command stops the benchmark."""
    start = time.perf_counter()
    proc = subprocess.run(argv, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    wall = time.perf_counter() - start
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} exited {proc.returncode}: {proc.stderr.strip()[-500:]}")
    return wall, proc.stderr


def top_imports(importtime: str, n: int = 6) -> list[dict[str, object]]:
    """The ``n`` slowest top-level imports (cumulative µs) of a ``-X importtime`` report."""
    rows = []
    for line in importtime.splitlines():
        if not line.startswith("import time:") or "cumulative" in line:
            continue
        _self_us, cumulative, name = line.split(":", 1)[1].split("|")
        if name.startswith("   "):  # " " then two spaces per level: nested, counted in its top-level import
            continue
        rows.append({"module": name.strip(), "cumulative_ms": round(int(cumulative) / 1000, 1)})
    return sorted(rows, key=lambda r: -float(r["cumulative_ms"]))[:n]


def measure(repeats: int, lfbench: str, before: str | None = None) -> dict[str, object]:
    cmds = commands(lfbench, before)
    times: dict[str, list[float]] = {label: [] for label in cmds}
    load_before = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="lfbench-startup-") as tmp:
        cwd = Path(tmp)
        for argv in cmds.values():  # one untimed run each: the files are in the page cache
            _run(argv, cwd)
        for _ in range(repeats):
            for label, argv in cmds.items():
                times[label].append(_run(argv, cwd)[0])
        imports = {}
        env = {**os.environ, "PYTHONPROFILEIMPORTTIME": "1"}
        for label, argv in cmds.items():
            if label.startswith("lfbench"):
                imports[label] = top_imports(_run(argv, cwd, env)[1])
    floor = statistics.median(times[FLOOR])
    records = []
    for label, argv in cmds.items():
        med = statistics.median(times[label])
        records.append({"command": label, "argv": [Path(argv[0]).name, *argv[1:]], "repeats": repeats,
                        "median_s": round(med, 4), "min_s": round(min(times[label]), 4),
                        "above_floor_s": round(med - floor, 4), "top_imports": imports.get(label, [])})
    return {"machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                        "python": platform.python_version(), "load_before": [round(x, 2) for x in load_before],
                        "load_after": [round(x, 2) for x in os.getloadavg()]},
            "records": records}


def markdown(report: dict[str, object]) -> str:
    m = report["machine"]
    lines = [f"Start-up, median of {report['records'][0]['repeats']} fresh processes each, in turns "
             f"({m['cores']} cores, Python {m['python']}, load {m['load_before'][0]} before, "
             f"{m['load_after'][0]} after).", "",
             "| command | median (s) | fastest (s) | above `python -c pass` (s) | slowest top-level imports (ms) |",
             "|---|---:|---:|---:|---|"]
    for r in report["records"]:
        top = ", ".join(f"{i['module']} {i['cumulative_ms']:g}" for i in r["top_imports"][:4]) or "–"
        lines.append(f"| `{r['command']}` | {r['median_s']:.3f} | {r['min_s']:.3f} | {r['above_floor_s']:.3f} "
                     f"| {top} |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="folder for startup.json and startup.md")
    p.add_argument("--repeats", type=int, default=10, help="timed runs of each command (default 10)")
    p.add_argument("--lfbench", default=str(Path(sys.executable).parent / "lfbench"),
                   help="the console script to time (default: the one beside this Python)")
    p.add_argument("--before", default=None, metavar="SCRIPT",
                   help="also time the lfbench commands through this console script, in the same turns")
    args = p.parse_args(argv)
    if args.repeats < 1:
        p.error("--repeats must be >= 1")
    report = measure(args.repeats, args.lfbench, args.before)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "startup.json").write_text(json.dumps(report, indent=1) + "\n", encoding="utf-8")
    (args.out / "startup.md").write_text(markdown(report), encoding="utf-8")
    print(markdown(report), end="")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
