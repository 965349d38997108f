"""Run ``planesweep`` on the real HCI scenes and print its scores and runtime per scene.

    LFBENCH_HCI_ROOT=../shared/data/hci python benchmarks/planesweep_real.py
    python benchmarks/planesweep_real.py --data DIR --scenes backgammon,antinous --threads 2 \
        --method planesweep:interval=0.5,interpolation=nearest

Scores are the benchmark's general metrics at low resolution (512x512, 15 px border), as
``lfbench evaluate --lowres-only`` computes them. Time is measured twice: the prediction on views
already in memory (the method's own cost) and the CPU time of that prediction (all threads); the
views are loaded from the PNGs before the clock starts. Torch runs on ``--threads`` threads (default 2,
the budget the issue sets: under 60 s per 512x512 scene on 2 cores).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

ISSUE_TARGETS = {"backgammon": (10.0, 10.0), "antinous": (30.0, 25.0)}  # BadPix 0.07, MSE x100 (issue 2)
METRICS = ("badpix_0.07", "badpix_0.03", "badpix_0.01", "mse_x100", "q25_x100")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", type=Path, default=os.environ.get("LFBENCH_HCI_ROOT"),
                   help="HCI data root (default: $LFBENCH_HCI_ROOT)")
    p.add_argument("--scenes", default="backgammon,antinous", help="comma-separated scene names")
    p.add_argument("--method", default="planesweep", help="method spec (default: planesweep)")
    p.add_argument("--threads", type=int, default=2, help="torch threads (default 2)")
    args = p.parse_args(argv)
    if args.data is None:
        p.error("no data root: pass --data or set LFBENCH_HCI_ROOT")

    import torch

    from lfbench.data.hci import HCIDataset
    from lfbench.method.registry import create_from_spec
    from lfbench.scoring.rules import ScoringRules
    from lfbench.scoring.score import score_scene

    torch.set_num_threads(args.threads)
    method = create_from_spec(args.method)
    scenes = HCIDataset.open(args.data).select([s.strip() for s in args.scenes.split(",") if s.strip()])
    rules = ScoringRules(allow_highres=False)
    print(f"{method.label} on {len(scenes)} scene(s), torch threads {torch.get_num_threads()}, "
          f"low resolution, {rules.border_px} px border")
    header = f"{'scene':12s} " + " ".join(f"{m:>11s}" for m in METRICS) + f" {'wall s':>7s} {'cpu s':>7s}  target"
    print(header)
    failed = False
    for scene in scenes:
        scene.gray_views()  # load the PNGs before timing
        wall, cpu = time.perf_counter(), time.process_time()
        pred = method.predict(scene)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        score = score_scene(scene, pred.disparity, rules=rules, source=f"{method.label} on {scene.name}")
        values = " ".join(f"{score.values[m]:11.3f}" for m in METRICS)
        verdict = ""
        if scene.name in ISSUE_TARGETS:
            bp, mse = ISSUE_TARGETS[scene.name]
            ok = score.values["badpix_0.07"] <= bp and score.values["mse_x100"] <= mse and wall < 60
            failed |= not ok
            verdict = f"{'ok' if ok else 'MISSED'} (BadPix0.07 <= {bp:g}, MSE <= {mse:g}, < 60 s)"
        print(f"{scene.name:12s} {values} {wall:7.1f} {cpu:7.1f}  {verdict}", flush=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"machine load average (1 min) at the end: {load:.2f} on {os.cpu_count()} CPUs")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
