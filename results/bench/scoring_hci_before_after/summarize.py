"""Summarize make.sh's runs: per round the before/after wall seconds (best of 3) and CPU seconds of
`lfbench bench metrics`, their medians, and the paired ratio after / before with a sign-flip test over rounds
(lfbench.scoring.stats.paired_scene_test on the log of the times).

    python summarize.py OUT_DIR BEFORE_COMMIT AFTER_COMMIT > summary.md
"""

from __future__ import annotations

import json
import math
import statistics
import sys
from pathlib import Path

from lfbench.scoring.stats import paired_scene_test


def _record(path: Path) -> dict:
    (record,) = [r for r in json.loads(path.read_text(encoding="utf-8")) if r.get("bench") == "metrics"]
    return record


def main(out: Path, before: str, after: str) -> int:
    rounds = sorted(int(p.stem.split("_")[1]) for p in out.glob("before_*.json"))
    rows = [(r, _record(out / f"before_{r}.json"), _record(out / f"after_{r}.json")) for r in rounds]
    print(f"# HCI scoring speed before ({before}) and after ({after}) the dataset seam\n")
    print("`lfbench bench metrics --methods 20 --threads 1 --repeat 3`: 12 generated 512x512 HCI scenes x 20 "
          "predictions, the 5 general metrics (scores_per_s: predictions scored per second, best of 3; "
          "cpu_seconds: the process's CPU time per run, mean of the 3: above the wall time where numpy and scipy "
          f"use both cores). Made by `bash make.sh` ({len(rows)} interleaved rounds, one machine, one run).\n")
    print("| round | before s | after s | before scores/s | after scores/s | before CPU s | after CPU s |")
    print("|---|---|---|---|---|---|---|")
    for r, b, a in rows:
        print(f"| {r} | {b['seconds']:.4f} | {a['seconds']:.4f} | {b['scores_per_s']:.1f} | {a['scores_per_s']:.1f} "
              f"| {b['cpu_seconds']:.3f} | {a['cpu_seconds']:.3f} |")
    for key, what in (("seconds", "wall (best of 3)"), ("cpu_seconds", "CPU (mean per run)")):
        b = [row[1][key] for row in rows]
        a = [row[2][key] for row in rows]
        test = paired_scene_test([math.log(x) for x in a], [math.log(x) for x in b])
        print(f"\n{what}: median before {statistics.median(b):.4f} s, after {statistics.median(a):.4f} s; "
              f"after / before = {math.exp(test.difference):.3f} (geometric mean over rounds, 95 % bootstrap CI "
              f"[{math.exp(test.low):.3f}, {math.exp(test.high):.3f}]; sign-flip p = {test.p_value:.3f})")
    m = rows[0][2]["machine"]
    print(f"\nmachine: {m['cpu']}, {m['cores']} cores, {m.get('cpu_capability', '?')}, torch {m['torch']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(Path(sys.argv[1]), sys.argv[2], sys.argv[3]))
