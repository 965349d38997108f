"""Paired comparison of two methods of results/table3/run over its 8 synthetic samples, per metric: the mean
difference (a - b) with its 95 % bootstrap CI over samples, the exact sign-flip test and the Wilcoxon
signed-rank test (lfbench.scoring.stats.paired_scene_test). Writes results/table3/paired.md.

    python results/table3/paired.py [RUN] [A_PREFIX] [B_PREFIX]   # default: run, subfocal, planesweep
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from lfbench.scoring.metrics import get_metric
from lfbench.scoring.stats import paired_scene_test

HERE = Path(__file__).resolve().parent


def main(argv: list[str]) -> int:
    run = Path(argv[0]) if argv else HERE / "run"
    a_prefix, b_prefix = (argv[1], argv[2]) if len(argv) > 2 else ("subfocal", "planesweep")
    records = json.loads((run / "results.json").read_text(encoding="utf-8"))["records"]
    values: dict[tuple[str, str], dict[str, float]] = {}
    for r in records:
        values.setdefault((r["method"], r["metric"]), {})[r["scene"]] = float(r["value"])
    methods = sorted({m for m, _ in values})
    a = next(m for m in methods if m.startswith(a_prefix))
    b = next(m for m in methods if m.startswith(b_prefix))
    lines = [f"# {a} against {b}, paired over the synthetic samples", "",
             "Made by `python results/table3/paired.py` from `run/results.json` (synthetic UrbanLF-Syn-layout "
             "scenes: not comparable to the paper's numbers).", "",
             "| metric | mean a | mean b | a - b | 95 % CI (bootstrap over samples) | a better on | sign-flip p | "
             "Wilcoxon p |", "|---|---|---|---|---|---|---|---|"]
    for metric in sorted({mt for _, mt in values}):
        va, vb = values.get((a, metric), {}), values.get((b, metric), {})
        scenes = sorted(set(va) & set(vb))
        xa, xb = [va[s] for s in scenes], [vb[s] for s in scenes]
        test = paired_scene_test(xa, xb, measure=metric)
        better = sum(x < y for x, y in zip(xa, xb, strict=True))
        lines.append(f"| {get_metric(metric).label} | {sum(xa) / len(xa):.3f} | {sum(xb) / len(xb):.3f} | "
                     f"{test.difference:.3f} | [{test.low:.3f}, {test.high:.3f}] | {better} of {len(scenes)} | "
                     f"{test.p_value:.4f} | {test.p_wilcoxon:.4f} |")
    lines += ["", f"Tests: {test.test}; Wilcoxon signed-rank (scipy). With 8 samples the smallest possible "
              "two-sided p of either test is 2 / 2^8 = 0.0078.", ""]
    (HERE / "paired.md").write_text("\n".join(lines), encoding="utf-8")
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
