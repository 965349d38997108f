"""Peak memory of ``lfbench check-dataset`` and ``lfbench evaluate`` on a synthetic set: whether a run holds every
scene's decoded views (growing with the number of scenes) or one scene's at a time (issue 38, memory).

    python benchmarks/scene_memory.py --out results/bench/scene_memory                 # about a minute
    python benchmarks/scene_memory.py --before /tmp/old_checkout --out /tmp/mem         # also an older checkout

Writes ``--scenes`` synthetic HCI-layout scenes of ``--size`` px (``lfbench synth``) into a temporary folder, then
runs each command as a fresh process on the first scene alone and on all of them, and reads the child's peak
resident set size (``getrusage(RUSAGE_CHILDREN).ru_maxrss``, each command in its own measuring process). A run
that streams its scenes needs about as much for all scenes as for one. ``--before DIR`` runs the same commands
with DIR first on ``PYTHONPATH`` (an older checkout of lfbench), in the same turns. Writes OUT/scene_memory.json
and OUT/scene_memory.md. Memory is measured here, never in the tests.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

MEASURE = ("import resource, subprocess, sys; subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL, "
           "stderr=subprocess.DEVNULL); print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss)")


def peak_mib(argv: list[str], env: dict[str, str], cwd: Path) -> float:
    """Peak RSS (MiB) of the process ``argv`` (Linux: ru_maxrss in KiB), measured by a fresh parent, run in
    ``cwd`` (not the checkout: ``python -m`` puts the current folder first on sys.path)."""
    out = subprocess.run([sys.executable, "-c", MEASURE, *argv], check=True, capture_output=True, text=True, env=env,
                         cwd=cwd)
    return int(out.stdout.strip()) / 1024.0


def commands(data: Path, scenes: list[str], out: Path) -> dict[str, list[str]]:
    """The command lines measured, on the scenes named ``scenes``."""
    lfbench = [sys.executable, "-m", "lfbench"]
    names = ",".join(scenes)
    return {"check-dataset": [*lfbench, "check-dataset", str(data), "--scenes", names, "--no-progress"],
            "evaluate planesweep": [*lfbench, "evaluate", "--data", str(data), "--scenes", names, "--method",
                                    "planesweep", "--out", str(out), "--no-progress"]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--scenes", type=int, default=8)
    parser.add_argument("--size", type=int, default=192, help="px per side of each view")
    parser.add_argument("--before", type=Path, help="an older checkout of lfbench, measured in the same turns")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "data"
        subprocess.run([sys.executable, "-m", "lfbench", "synth", "--out", str(data), "--scenes", str(args.scenes),
                        "--size", str(args.size), "--seed", "5"], check=True, capture_output=True, cwd=tmp)
        names = sorted(p.name for p in (data / "synthetic").iterdir())
        builds = {"now": dict(os.environ)}
        if args.before is not None:
            builds["before"] = {**os.environ, "PYTHONPATH": os.pathsep.join(
                p for p in (str(args.before.resolve()), os.environ.get("PYTHONPATH")) if p)}
        for subset in (names[:1], names):
            for build, env in builds.items():
                for label, cmd in commands(data, subset, Path(tmp) / f"ev_{build}_{len(subset)}").items():
                    rows.append({"build": build, "command": label, "scenes": len(subset),
                                 "peak_rss_mib": round(peak_mib(cmd, env, Path(tmp)), 1)})
    record = {"python": sys.version.split()[0], "machine": platform.machine(), "size_px": args.size,
              "views": 81, "rows": rows}
    (args.out / "scene_memory.json").write_text(json.dumps(record, indent=2) + "\n")
    lines = [f"Peak RSS of a fresh process, {args.size}x{args.size} px 9x9 synthetic scenes "
             "(`python benchmarks/scene_memory.py`)", "", "| build | command | scenes | peak RSS (MiB) |",
             "| --- | --- | ---: | ---: |"]
    lines += [f"| {r['build']} | {r['command']} | {r['scenes']} | {r['peak_rss_mib']:.1f} |" for r in rows]
    (args.out / "scene_memory.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
