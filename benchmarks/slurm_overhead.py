"""What SLURM costs an ablation: measured on the one-node test cluster of tests/slurm_cluster.py (munged,
slurmctld, slurmd of this host), with the example plugin's 4-cell grid (tinycnn, channels 4 and 8 x seeds 1
and 2, 25 training steps each, 1 CPU per cell):

    python benchmarks/slurm_overhead.py --out results/slurm     # ~11 min on 2 loaded cores

Writes OUT/slurm_overhead.json and OUT/slurm_overhead.md (``--table-from OUT/slurm_overhead.json`` rewrites the
table from the JSON):
- ``cluster_start_s``: munged started -> ``sinfo`` shows the node idle;
- ``submit_to_start_s``: ``sbatch`` called -> the job script's first command runs (an empty 1-CPU job,
  ``--repeats`` times, each on the idle node; SLURM's default ``batch_sched_delay`` is 3 s);
- ``requeue_to_restart_s``: ``scontrol requeue`` of a running job -> it runs again without intervention
  (SLURM keeps a requeued batch job pending for a while);
- ``job_s``: one job that does nothing (``int("0")``) through lfbench's own submit-and-wait
  (lfbench.utils.executor.executor_for(...).map: submitit, the job's Python start and imports, the result file,
  squeue polling), ``--repeats`` times per executor, slurm and local, each on the idle node;
- ``ablate``: wall seconds of ``lfbench ablate`` on the grid with ``--jobs 1``, ``--jobs 2``, ``--executor local``
  and ``--executor slurm`` (each in a fresh output folder, synthetic data generation and the test-time job
  included), the best of ``--ablate-repeats`` interleaved runs.
Every record carries the load average before and after: other work on the cores inflates all the times.
Needs slurm-wlm and munge (see tests/slurm_cluster.py); not part of the tests.
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

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from helpers import example_grid, install_example_plugin  # noqa: E402
from slurm_cluster import FINAL_STATES, running_cluster  # noqa: E402

MODES = {"jobs 1": ["--jobs", "1"], "jobs 2": ["--jobs", "2"], "executor local": ["--executor", "local"],
         "executor slurm": ["--executor", "slurm", "--cpus-per-job", "1"]}


def load() -> float:
    return round(os.getloadavg()[0], 2)


def submit_to_start(cluster, tmp: Path, repeats: int) -> list[float]:
    """Seconds from calling sbatch to the first command of the job script, for ``repeats`` empty jobs."""
    out = []
    for k in range(repeats):
        stamp = tmp / f"start_{k}.txt"
        cluster.wait_idle()  # on the idle node (back to back, a job starts as the previous one ends)
        t0 = time.time()
        job = cluster.run("sbatch", "--parsable", "--cpus-per-task=1", "--output=/dev/null",
                          "--wrap", f"date +%s.%N > {stamp}").stdout.strip()
        while cluster.jobs().get(job, {}).get("state") not in FINAL_STATES:
            time.sleep(0.05)
        out.append(round(float(stamp.read_text()) - t0, 3))
    return out


def requeue_to_restart(cluster, tmp: Path, timeout_s: float = 600) -> float:
    """Seconds from ``scontrol requeue`` of a running job until it runs again on its own."""
    starts = tmp / "requeue_starts.txt"
    job = cluster.run("sbatch", "--parsable", "--cpus-per-task=1", "--output=/dev/null",
                      "--wrap", f"date +%s.%N >> {starts}; sleep 600").stdout.strip()
    while not starts.is_file():
        time.sleep(0.05)
    t0 = time.time()
    cluster.run("scontrol", "requeue", job)
    deadline = time.monotonic() + timeout_s
    while len(starts.read_text().split()) < 2:
        if time.monotonic() > deadline:
            raise TimeoutError(f"the requeued job {job} did not restart within {timeout_s:.0f} s")
        time.sleep(0.2)
    cluster.run("scancel", job)
    return round(float(starts.read_text().split()[1]) - t0, 1)


def noop_jobs(cluster, executor: str, folder: Path, repeats: int) -> list[float]:
    """Seconds of ``repeats`` one-job runs of ``int("0")`` through the executor's map, each on the idle node."""
    from lfbench.utils.executor import ClusterOptions, executor_for

    options = ClusterOptions(executor, cpus_per_job=1, timeout_min=10)
    out = []
    for k in range(repeats):
        cluster.wait_idle()
        results: list = []
        start = time.perf_counter()
        executor_for(options, folder=folder / executor).map(int, ["0"], labels=[f"no-op {k}"], threads=1,
                                                            on_done=results.append)
        out.append(round(time.perf_counter() - start, 2))
        assert results == [0]
    return out


def ablate(env: dict, spec: Path, out: Path, args: list[str]) -> float:
    start = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "lfbench", "ablate", str(spec), "--out", str(out), "--no-progress",
                           *args], env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"lfbench ablate {' '.join(args)} failed:\n{proc.stderr[-2000:]}")
    return round(time.perf_counter() - start, 1)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", type=Path, required=True, help="folder for slurm_overhead.json and .md")
    p.add_argument("--repeats", type=int, default=10, help="empty jobs timed for the submit-to-start latency and "
                                                               "no-op jobs per executor")
    p.add_argument("--ablate-repeats", type=int, default=2, help="runs of each ablate mode (the best is kept)")
    p.add_argument("--table-from", type=Path, default=None, metavar="JSON",
                   help="only rewrite OUT/slurm_overhead.md from a stored slurm_overhead.json")
    args = p.parse_args(argv)
    if args.table_from is not None:
        print(write_table(json.loads(args.table_from.read_text()), args.out / "slurm_overhead.md"))
        return 0
    with tempfile.TemporaryDirectory(prefix="lfslurm-bench-") as tmp_name:
        tmp = Path(tmp_name)
        src, _, env = install_example_plugin(tmp / "plugin")
        (src / "grid.toml").write_text(example_grid())
        record: dict = {"host": platform.node(), "cpus": os.cpu_count(), "python": platform.python_version(),
                        "command": "python benchmarks/slurm_overhead.py " + " ".join(argv or sys.argv[1:]),
                        "load_before": load()}
        with running_cluster(tmp / "cluster") as cluster:
            env = {**env, "SLURM_CONF": cluster.env["SLURM_CONF"]}
            record["slurm"] = cluster.run("sinfo", "--version").stdout.strip()
            record["cluster_start_s"] = round(cluster.started_s, 2)
            lat = submit_to_start(cluster, tmp, args.repeats)
            record["submit_to_start_s"] = {"all": lat, "median": statistics.median(lat), "max": max(lat)}
            record["requeue_to_restart_s"] = requeue_to_restart(cluster, tmp)
            cluster.wait_idle()
            os.environ["SLURM_CONF"] = cluster.env["SLURM_CONF"]  # for the executor's jobs in this process
            jobs = {ex: noop_jobs(cluster, ex, tmp / "noop", args.repeats) for ex in ("slurm", "local")}
            record["job_s"] = {ex: {"all": v, "median": statistics.median(v)} for ex, v in jobs.items()}
            runs: dict[str, list[float]] = {mode: [] for mode in MODES}
            for r in range(args.ablate_repeats):
                for mode, flags in MODES.items():
                    runs[mode].append(ablate(env, src / "grid.toml", tmp / f"{mode.replace(' ', '_')}_{r}", flags))
            walls = {mode: min(v) for mode, v in runs.items()}
        record["ablate"] = {"cells": 4, "wall_s": walls, "all_s": runs}
        record["load_after"] = load()
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "slurm_overhead.json").write_text(json.dumps(record, indent=2) + "\n")
    print(write_table(record, args.out / "slurm_overhead.md"))
    return 0


def write_table(record: dict, path: Path) -> str:
    """The Markdown table of a record (``--table-from`` rewrites it from a stored slurm_overhead.json)."""
    lat, jobs, walls = record["submit_to_start_s"], record["job_s"], record["ablate"]["all_s"]
    rows = [f"| cluster start (munged -> node idle) | {record['cluster_start_s']:.1f} |",
            f"| sbatch -> the job starts on the idle node (median / max of {len(lat['all'])}) | "
            f"{lat['median']:.1f} / {lat['max']:.1f} |",
            f"| scontrol requeue -> the job runs again | {record['requeue_to_restart_s']:.0f} |"]
    for ex in ("local", "slurm"):
        rows.append(f"| a no-op job through lfbench's submit-and-wait, executor {ex} (median, range of "
                    f"{len(jobs[ex]['all'])}; the wait polls every 1 s) | {jobs[ex]['median']:.1f} "
                    f"({min(jobs[ex]['all']):.1f} - {max(jobs[ex]['all']):.1f}) |")
    rows += [f"| lfbench ablate, 4 tiny cells, {mode} (best of {len(v)}) | {min(v):.1f} |" for mode, v in walls.items()]
    text = (f"# SLURM overhead on the test cluster ({record['slurm']}, {record['host']}, {record['cpus']} CPUs, load "
            f"{record['load_before']} -> {record['load_after']})\n\n`{record['command']}`\n\n"
            "| what | seconds |\n|---|---|\n" + "\n".join(rows) + "\n")
    path.write_text(text)
    return text


if __name__ == "__main__":
    sys.exit(main())
