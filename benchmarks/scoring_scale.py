"""How scoring grows with methods, scenes and resolution, beside a floor measured in the same run (issue 23.4).

    python benchmarks/scoring_scale.py --work /tmp/scoring_scale --out results/bench/scoring_scale   # ~10 min
    python benchmarks/scoring_scale.py --quick --work /tmp/q --out /tmp/q/out                       # seconds

Builds a synthetic benchmark in the full HCI layout (benchmarks/hci_layout.py: the 9-scene set of the issue,
high-resolution ground truth on the stratified scenes, every mask; and, unless --quick, every scene of the 4
categories) with submission folders of generated methods, then times, on one thread:

- ``process_1``: one method's whole ``lfbench evaluate --all-metrics`` process (start-up and writing included);
- ``methods``: scoring 1, 10 and 100 methods (``lfbench.runs.runner.evaluate`` in this process, every metric
  of every scene, the maps read from the submissions), the seconds per method and per further method;
- ``jobs``: 10 methods with ``--jobs 2`` against ``--jobs 1`` (same numbers checked);
- ``scenes`` and ``resolution``: the per-method cost on the full set against the 9 scenes, and with every
  scene scored at low resolution (``--lowres-only``);
- ``floor``: in the same run, what no scorer can avoid: reading each method's maps and one pass of numpy over
  the same pixels (|gt - pred| > t counted at every scored pixel, high resolution included), plus reading
  the ground truth and masks once per run. Reported beside each time as ``ratio_to_floor``.

Writes OUT/scoring_scale.json and OUT/scoring_scale.md. Speed is measured here, never in the tests.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import shutil
import struct
import subprocess
import sys
import time
from pathlib import Path

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # one thread, as the issue measures
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from hci_layout import write_benchmark, write_submissions  # noqa: E402

from lfbench.data.hci import HCIDataset  # noqa: E402
from lfbench.data.scene import HIGHRES, read_mask  # noqa: E402
from lfbench.data.submission import read_submission_map  # noqa: E402
from lfbench.method.registry import create_from_spec  # noqa: E402
from lfbench.runs.runner import evaluate  # noqa: E402
from lfbench.scoring.prepare import read_label_mask  # noqa: E402
from lfbench.scoring.rules import ScoringRules, metric_resolution  # noqa: E402
from lfbench.scoring.score import applicable_metrics  # noqa: E402
from lfbench.utils.malloc import retain_freed_memory  # noqa: E402


def _scenes(root: Path) -> list:
    return [s for s in HCIDataset.open(root) if s.has_gt()]


def _methods(subs: Path, n: int) -> list:
    return [create_from_spec(f"published:path={subs / f'm{k:03d}'}") for k in range(n)]


def _timed(fn) -> tuple[float, object]:
    """(seconds, fn()): CPU seconds of this process (other processes on the cores inflate wall time)."""
    start = time.process_time()
    out = fn()
    return time.process_time() - start, out


def _wall(fn) -> tuple[float, object]:
    start = time.perf_counter()
    out = fn()
    return time.perf_counter() - start, out


def score(root: Path, subs: Path, n: int, rules: ScoringRules = ScoringRules(), jobs: int = 1):
    """CPU seconds to score ``n`` methods on every scene with ground truth under ``root`` (every metric), and the
    results."""
    scenes, methods = _scenes(root), _methods(subs, n)
    return _timed(lambda: evaluate(methods, scenes, metrics=lambda s: applicable_metrics(s, rules), rules=rules,
                                   progress=False, jobs=jobs))


def _bits(results) -> list:
    """Every record with its value as its 8 bytes (NaN equals NaN), and the runs."""
    return [(r.method, r.scene, r.metric, struct.pack("<d", r.value), r.resolution) for r in results.records] + [
        (r.method, r.scene, r.nonfinite_pixels, r.aligned_from, tuple(r.notes)) for r in results.runs]


def floor(root: Path, subs: Path, n: int, rules: ScoringRules = ScoringRules()) -> dict[str, float]:
    """The floor of scoring ``n`` methods, in CPU seconds: reading the files scoring reads once (each scene's
    ground truth and masks at the resolutions its metrics are scored at: 'fixed_s'), then per method
    reading its maps and one numpy pass over the same pixels (|gt - pred| > t counted at every pixel of the
    general metrics' resolution, the prediction taken to high resolution by an index: 'per_method_s')."""
    scenes = _scenes(root)
    start = time.process_time()
    kept = []
    for scene in scenes:
        needed: dict[str, set[str]] = {}
        for metric in applicable_metrics(scene, rules):
            res = metric_resolution(scene, metric, rules)
            needed.setdefault(res, set()).update(metric.required_masks)
        for res, masks in needed.items():
            scene.gt_disparity(res)
            for name in masks:
                path = scene.path / f"{name}_{res}.png"
                (read_label_mask(path) if name in ("mask_boxes", "mask_dots_by_size") else read_mask(path))
        res = rules.general_resolution(scene)
        kept.append((scene, scene.gt_disparity(res)))
    fixed = time.process_time() - start
    start = time.process_time()
    bad = 0
    for k in range(n):
        for scene, gt in kept:
            pred, _ = read_submission_map(subs / f"m{k:03d}", scene.name)
            scale = gt.shape[0] // pred.shape[0]
            if scale > 1:
                index = np.arange(gt.shape[0]) // scale
                pred = pred.take(index, axis=0).take(index, axis=1)
            bad += int(np.count_nonzero(np.abs(pred - gt) > 0.07))
    return {"fixed_s": fixed, "per_method_s": (time.process_time() - start) / n, "checksum": bad}


def whole_process(root: Path, subs: Path, out: Path) -> dict[str, float]:
    """Wall and CPU seconds (user + system) of one ``lfbench evaluate --all-metrics`` process on one method."""
    cmd = [sys.executable, "-m", "lfbench", "-q", "evaluate", "--data", str(root), "--method",
           f"published:path={subs / 'm000'}", "--all-metrics", "--out", str(out), "--no-progress"]
    before = os.times()
    start = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - start
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return {"seconds": wall, "cpu_s": cpu}


def run(work: Path, quick: bool) -> dict:
    logging.getLogger("lfbench").setLevel(logging.ERROR)  # the generated NaN pixels are noted per scene
    retain_freed_memory()  # as scoring does (lfbench.runs.runner.score_task): the floor and the scorer get memory alike
    size, scale = (32, 4) if quick else (512, 10)
    counts = (1, 2) if quick else (1, 10, 100)
    work.mkdir(parents=True, exist_ok=True)
    issue, full, subs = work / "issue9", work / "full", work / "subs"
    for folder in (issue, full, subs):
        shutil.rmtree(folder, ignore_errors=True)
    t_build, _ = _timed(lambda: write_benchmark(issue, "issue", size=size, scale=scale))
    if not quick:
        write_benchmark(full, "full", size=size, scale=scale)
    write_submissions(subs, [(s.name, s.gt_disparity()) for s in _scenes(issue)], max(counts))
    if not quick:  # the other scenes of the full set, for the 10 methods scored on it
        names = {s.name for s in _scenes(issue)}
        write_submissions(subs, [(s.name, s.gt_disparity()) for s in _scenes(full) if s.name not in names], 10)
    record: dict = {"machine": {"cpu": platform.processor() or platform.machine(), "cores": os.cpu_count(),
                                "threads": 1, "python": platform.python_version(), "numpy": np.__version__,
                                "load_before": os.getloadavg()[0]},
                    "data": {"size": size, "highres_scale": scale, "scenes_issue": len(_scenes(issue)),
                             "highres_scenes_issue": sum(s.has_gt(HIGHRES) for s in _scenes(issue)),
                             "build_s": t_build},
                    "methods": [], "quick": quick}
    floors = [floor(issue, subs, counts[-1] if quick else 10) for _ in range(2)]  # the first pays page faults
    fl = {key: min(f[key] for f in floors) for key in ("fixed_s", "per_method_s")}
    record["floor"] = {**fl, "runs": floors}
    runs = [whole_process(issue, subs, work / "process_out") for _ in range(3)]
    record["process_1"] = {"runs": runs, "seconds": min(r["seconds"] for r in runs),
                           "cpu_s": min(r["cpu_s"] for r in runs), "max_seconds": max(r["seconds"] for r in runs)}
    score(issue, subs, 1)  # warm-up: imports on first use, page cache
    baseline = None
    for n in counts:
        seconds, results = score(issue, subs, n)
        row = {"methods": n, "seconds": seconds, "per_method_s": seconds / n, "records": len(results.records),
               "floor_s": fl["fixed_s"] + n * fl["per_method_s"]}
        row["ratio_to_floor"] = row["seconds"] / row["floor_s"]
        if baseline is not None:
            row["per_further_method_s"] = (seconds - baseline) / (n - 1)
        baseline = seconds if n == 1 else baseline
        record["methods"].append(row)
    n_jobs = counts[-1] if quick else 10
    t1, r1 = score(issue, subs, n_jobs)
    wall1, _ = _wall(lambda: score(issue, subs, n_jobs))
    wall2, (_, r2) = _wall(lambda: score(issue, subs, n_jobs, jobs=2))
    record["jobs"] = {"methods": n_jobs, "jobs_1_wall_s": wall1, "jobs_2_wall_s": wall2,
                      "identical": _bits(r1) == _bits(r2)}
    n_res = counts[-1] if quick else 10
    t_low, _ = score(issue, subs, n_res, ScoringRules(allow_highres=False))
    record["resolution"] = {"methods": n_res, "default_s": t1 if n_res == n_jobs else score(issue, subs, n_res)[0],
                            "lowres_only_s": t_low}
    if not quick:
        t_full, res_full = score(full, subs, 10)
        record["scenes"] = {"methods": 10, "issue_scenes": len(_scenes(issue)), "issue_s": t1,
                            "full_scenes": len(_scenes(full)), "full_s": t_full,
                            "full_highres_scenes": sum(s.has_gt(HIGHRES) for s in _scenes(full)),
                            "full_records": len(res_full.records),
                            "full_floor": min((floor(full, subs, 10) for _ in range(2)), key=lambda f: f["fixed_s"])}
    record["machine"]["load_after"] = os.getloadavg()[0]
    return record


def markdown(r: dict) -> str:
    fl = r["floor"]
    d, mach = r["data"], r["machine"]
    lines = [f"# Scoring at scale ({'quick' if r['quick'] else 'full'} run)", "",
             f"{d['scenes_issue']} scenes ({d['highres_scenes_issue']} with {d['highres_scale']}x high-resolution "
             f"ground truth), {d['size']}x{d['size']} px, every metric; one thread; {mach['cores']} cores, load "
             f"{mach['load_before']:.1f} -> {mach['load_after']:.1f}. Times are CPU seconds of the scoring process "
             "(wall time where marked).", "",
             "One method's whole `lfbench evaluate --all-metrics` process, 3 runs: "
             f"**{r['process_1']['seconds']:.2f} s** wall at best, {r['process_1']['max_seconds']:.2f} s at worst "
             f"({r['process_1']['cpu_s']:.2f} s CPU at best; the spread is system time, page faults of this VM).", "",
             f"Floor: reading gt and masks once {fl['fixed_s']:.2f} s; per method (reading its maps + one numpy pass "
             f"over the same pixels) {fl['per_method_s']:.3f} s.", "",
             "| methods | seconds | s per method | s per further method | floor s | ratio to floor |",
             "|---|---|---|---|---|---|"]
    for m in r["methods"]:
        further = f"{m['per_further_method_s']:.2f}" if "per_further_method_s" in m else ""
        lines.append(f"| {m['methods']} | {m['seconds']:.2f} | {m['per_method_s']:.2f} | {further} | "
                     f"{m['floor_s']:.2f} | {m['ratio_to_floor']:.2f} |")
    j = r["jobs"]
    lines += ["", f"`--jobs 2` on {j['methods']} methods: {j['jobs_2_wall_s']:.2f} s wall against "
              f"{j['jobs_1_wall_s']:.2f} s with `--jobs 1` (2 cores); identical records: {j['identical']}."]
    res = r["resolution"]
    lines += ["", f"Resolution: {res['methods']} methods {res['default_s']:.2f} s as the benchmark scores them, "
              f"{res['lowres_only_s']:.2f} s with every scene at low resolution."]
    if "scenes" in r:
        s = r["scenes"]
        full_floor = s["full_floor"]["fixed_s"] + 10 * s["full_floor"]["per_method_s"]
        lines += ["", f"Scenes: {s['methods']} methods on the {s['issue_scenes']} scenes {s['issue_s']:.2f} s; on "
                  f"every scene with ground truth of the 4 categories ({s['full_scenes']}, "
                  f"{s['full_highres_scenes']} at high resolution) {s['full_s']:.2f} s (floor {full_floor:.2f} s)."]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--work", type=Path, required=True, help="scratch folder for the generated benchmark (~2 GB)")
    p.add_argument("--out", type=Path, required=True, help="folder for scoring_scale.json and scoring_scale.md")
    p.add_argument("--quick", action="store_true", help="32x32 scenes, 1 and 2 methods (a smoke run)")
    args = p.parse_args(argv)
    record = run(args.work, args.quick)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "scoring_scale.json").write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
    (args.out / "scoring_scale.md").write_text(markdown(record), encoding="utf-8")
    print(markdown(record))
    return 0


if __name__ == "__main__":
    sys.exit(main())
