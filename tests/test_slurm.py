"""`lfbench ablate --executor slurm` and `lfbench train` under `srun` against a real one-node SLURM cluster
(the ``slurm_cluster`` fixture, tests/slurm_cluster.py): every command runs as a user runs it, in a fresh
process through the CLI, on the example plugin's tiny network (seconds per cell). They skip where the
cluster cannot run (see the fixture); ``pytest -m slurm`` runs just them."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
import time
from collections import defaultdict
from pathlib import Path

import pytest
import torch
from helpers import example_copy, example_grid

# The example plugin's ablation over channels, each cell once per seed: 4 cells of 25 training steps.
GRID = example_grid()

# Two cells long enough (800 steps, a checkpoint every 25) to be cancelled or requeued while they train.
LONG = GRID.replace("seeds = [1, 2]\n", "").replace("steps = [20, 5]", "steps = [800, 5]") + """
[set]
"training.checkpoint_every" = 25
"""

# A cell whose learning rate makes the loss NaN after 21 steps, beside one that trains for 405; no threads in
# the budget (the cells get --cpus-per-job).
FAILING = GRID.replace("seeds = [1, 2]\n", "").replace("threads = 1\n\n", "\n")
FAILING = FAILING.replace("channels = [4, 8]", """lr = [1e30]
[[grid]]
lr = [1e-3]
"stages.1.steps" = [400]""")


@pytest.fixture(scope="module")
def plugin(slurm_cluster, example_plugin, tmp_path_factory):
    """(the example plugin's folder, with the specs of these tests; the environment whose PYTHONPATH holds it
    and whose SLURM_CONF names the test cluster)."""
    _, env = example_plugin
    src = example_copy(tmp_path_factory.mktemp("slurm_plugin") / "src")
    for name, text in (("grid.toml", GRID), ("long.toml", LONG), ("failing.toml", FAILING)):
        (src / name).write_text(text)
    return src, {**env, "SLURM_CONF": slurm_cluster.env["SLURM_CONF"]}


def lfbench(env: dict, *args, timeout: float = 600) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lfbench", *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=timeout)


def ok(proc: subprocess.CompletedProcess) -> str:
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stderr


def records(out: Path) -> dict:
    data = json.loads((out / "results.json").read_text())
    return {(r["method"], r["scene"], r["metric"]): r["value"] for r in data["records"]}


def weights(cell: Path) -> dict[str, torch.Tensor]:
    return torch.load(cell / "final.pt", map_location="cpu", weights_only=True)["state_dict"]


def same_weights(a: Path, b: Path) -> bool:
    wa, wb = weights(a), weights(b)
    return wa.keys() == wb.keys() and all(torch.equal(wa[k], wb[k]) for k in wa)


class QueueWatch:
    """Polls squeue in a thread while a command runs: every state each job was seen in, and its own job id."""

    def __init__(self, cluster, every_s: float = 0.2) -> None:
        self.cluster, self.every_s = cluster, every_s
        self.seen: dict[str, set[str]] = defaultdict(set)
        self.raw: dict[str, str] = {}
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _run(self) -> None:
        while not self._stop.is_set():
            for job, info in self.cluster.jobs().items():
                self.seen[job].add(info["state"])
                self.raw[job] = info["raw"]
            self._stop.wait(self.every_s)

    def __enter__(self) -> QueueWatch:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()


def test_the_cluster_runs_a_job_on_every_cpu(slurm_cluster, tmp_path):
    """The fixture's cluster: one idle node with this host's CPUs, and a batch job runs on it."""
    info = slurm_cluster.run("sinfo", "--noheader", "--Node", "--format=%N|%c|%T").stdout.split()
    assert info == [f"{slurm_cluster.node}|{slurm_cluster.cpus}|idle"]
    out = tmp_path / "job.out"
    job, state = slurm_cluster.batch("--cpus-per-task=1", f"--output={out}",
                                     "--wrap", "echo $SLURM_JOB_ID $SLURM_CPUS_PER_TASK $SLURM_JOB_PARTITION")
    job_id, cpus, partition = out.read_text().split()
    assert state == "COMPLETED" and job_id == job and cpus == "1" and partition == "lfbench"
    assert any(r["JobId"] == job_id and r["JobState"] == "COMPLETED" for r in slurm_cluster.completed())


@pytest.mark.slow
def test_ablation_through_sbatch_gives_the_jobs_1_results(slurm_cluster, plugin, tmp_path):
    src, env = plugin
    spec = src / "grid.toml"
    with QueueWatch(slurm_cluster) as watch:
        log = ok(lfbench(env, "ablate", spec, "--out", tmp_path / "slurm", "--executor", "slurm", "--cpus-per-job",
                         "1", "--max-parallel", "2", "--no-progress"))
    assert "sacct" not in log  # job states come from squeue: this cluster, like many, has no accounting database
    # (submitit's local executor against --jobs 1: test_ablate.py's
    # test_submitit_local_executor_and_merged_cells_runs_give_the_jobs_1_results, in-process)
    ok(lfbench(env, "ablate", spec, "--out", tmp_path / "jobs1", "--jobs", "1", "--no-progress"))

    cells = sorted(p.name for p in (tmp_path / "jobs1" / "cells").iterdir())
    assert cells == ["channels=4_seed=1", "channels=4_seed=2", "channels=8_seed=1", "channels=8_seed=2"]
    for cell in cells:  # bit-identical training on the CPU, whichever way the cell ran
        assert same_weights(tmp_path / "slurm" / "cells" / cell, tmp_path / "jobs1" / "cells" / cell), cell
    assert records(tmp_path / "slurm") == records(tmp_path / "jobs1")

    # one job per cell (one array task each) went through the controller: squeue saw each one run, and
    # SLURM's job completion log has each one COMPLETED
    jobs = dict(re.findall(r"cell (\S+): job (\S+), log", log))
    assert sorted(jobs) == cells and len(set(jobs.values())) == len(cells), log
    completed = {r["JobId"]: r["JobState"] for r in slurm_cluster.completed()}
    for cell, job in jobs.items():
        assert "RUNNING" in watch.seen[job], (cell, job, dict(watch.seen))
        assert completed[watch.raw[job]] == "COMPLETED", (cell, job, completed)
    # one sbatch: an array of the 4 cells, at most 2 running at once, 1 CPU each
    cells_job = jobs[cells[0]].split("_")[0]
    script = (tmp_path / "slurm" / "submitit" / f"{cells_job}_submission.sh").read_text().splitlines()
    assert {"#SBATCH --array=0-3%2", "#SBATCH --cpus-per-task=1"} <= set(script)
    # then the test times, measured one cell after the other in one more job (on a cell's resources, not on
    # the machine that submitted the jobs)
    (timing_job,) = re.findall(r"test time: job (\S+), log", log)
    assert "RUNNING" in watch.seen[timing_job] and completed[watch.raw[timing_job]] == "COMPLETED"
    for cell in cells:
        timing = json.loads((tmp_path / "slurm" / "cells" / cell / "timing.json").read_text())
        assert timing["slurm_job_id"] == watch.raw[timing_job] and timing["threads"] == 1, timing
    # the jobs' logs are in OUT/submitit/, one pair per cell, each naming its job
    for cell, job in jobs.items():
        for stream in ("out", "err"):
            assert (tmp_path / "slurm" / "submitit" / f"{job}_0_log.{stream}").is_file(), (cell, job, stream)
        text = (tmp_path / "slurm" / "submitit" / f"{job}_0_log.out").read_text()
        text += (tmp_path / "slurm" / "submitit" / f"{job}_0_log.err").read_text()
        assert f"job_id={job}" in text, text[-2000:]


# --------------------------------------------------------------------------- faults

def wait_until(condition, timeout_s: float = 120, what: str = "") -> None:
    deadline = time.monotonic() + timeout_s
    while not condition():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out after {timeout_s:.0f} s waiting for {what}")
        time.sleep(0.1)


class Background:
    """`lfbench ARGS` running in the background, its stderr in a file (read while it runs)."""

    def __init__(self, env: dict, log: Path, *args) -> None:
        self.log = log
        with open(log, "w") as err:
            self.proc = subprocess.Popen([sys.executable, "-m", "lfbench", *map(str, args)], env=env,
                                         stdout=subprocess.DEVNULL, stderr=err, text=True)

    def job_of(self, cell: str) -> str:
        """The job id the command logged for the cell (waits for the line)."""
        found: list[str] = []

        def logged() -> bool:
            found[:] = re.findall(rf"cell {re.escape(cell)}: job (\S+), log", self.log.read_text())
            return bool(found)

        wait_until(logged, what=f"the job of cell {cell}")
        return found[0]

    def finish(self, timeout_s: float = 300) -> tuple[int, str]:
        return self.proc.wait(timeout_s), self.log.read_text()


def checkpoint_step(cell: Path) -> int:
    from lfbench.training import checkpoint as ckpt

    return int(ckpt.load(cell / "checkpoint.pt", ckpt.CHECKPOINT_FORMAT)["global_step"])


def running_with_checkpoint(cluster, job: str, cell: Path):
    return lambda: (cell / "checkpoint.pt").is_file() and cluster.jobs().get(job, {}).get("state") == "RUNNING"


@pytest.fixture(scope="module")
def long_reference(plugin, tmp_path_factory) -> Path:
    """The long spec's cells trained without interruption, one after the other in one process (--jobs 1)."""
    src, env = plugin
    out = tmp_path_factory.mktemp("long_reference") / "out"
    ok(lfbench(env, "ablate", src / "long.toml", "--out", out, "--jobs", "1", "--no-progress"))
    return out


@pytest.mark.slow
def test_a_cancelled_cell_resumes_from_its_checkpoint_when_the_command_runs_again(slurm_cluster, plugin,
                                                                                   long_reference, tmp_path):
    src, env = plugin
    out = tmp_path / "out"
    args = ("ablate", src / "long.toml", "--out", out, "--executor", "slurm", "--no-progress")
    cell = out / "cells" / "channels=4"
    run = Background(env, tmp_path / "first.log", *args)
    job = run.job_of("channels=4")
    wait_until(running_with_checkpoint(slurm_cluster, job, cell), what="the cell's first checkpoint")
    slurm_cluster.run("scancel", job)
    rc, err = run.finish()
    # the other cell finished; the command then ended with one line naming the cancelled cell and its log
    assert rc == 2, err[-3000:]
    last = err.strip().splitlines()[-1]
    log = out / "submitit" / f"{job}_0_log.err"
    assert last.startswith(f"lfbench ablate: error: 1 of 2 job(s) did not finish: cell channels=4 (job {job}) "
                           "ended CANCELLED without a result"), last
    assert f"its log: {log})" in last and log.is_file()
    assert "stopped at stage 1 step" in log.read_text()  # SIGTERM: the cell wrote a checkpoint and stopped
    assert (out / "cells" / "channels=8" / "cell.json").is_file() and not (cell / "cell.json").exists()
    step = checkpoint_step(cell)
    assert 0 < step < 800

    again = ok(lfbench(env, *args))
    assert "cell channels=8: finished earlier, skipped" in again
    assert [c for c, _ in re.findall(r"cell (\S+): job (\S+), log", again)] == ["channels=4"]  # only it resubmitted
    assert f"resuming from {cell / 'checkpoint.pt'}" in (cell / "log.txt").read_text()
    assert f"(global step {step})" in (cell / "log.txt").read_text()
    for name in ("channels=4", "channels=8"):  # the same weights as an uninterrupted run
        assert same_weights(out / "cells" / name, long_reference / "cells" / name), name
    assert records(out) == records(long_reference)


@pytest.mark.slow
def test_a_job_requeued_by_slurm_resumes_from_its_checkpoint(slurm_cluster, plugin, long_reference, tmp_path):
    src, env = plugin
    out = tmp_path / "out"
    cell = out / "cells" / "channels=8"
    run = Background(env, tmp_path / "run.log", "ablate", src / "long.toml", "--out", out, "--executor", "slurm",
                     "--no-progress", "--cells", "channels=8")
    job = run.job_of("channels=8")
    wait_until(running_with_checkpoint(slurm_cluster, job, cell), what="the cell's first checkpoint")
    slurm_cluster.run("scontrol", "requeue", job)
    # SLURM holds a requeued batch job back for a while (BeginTime); let it start again now
    wait_until(lambda: slurm_cluster.jobs()[job]["state"] == "PENDING", what="the requeued job")
    step = checkpoint_step(cell)
    slurm_cluster.run("scontrol", "update", f"JobId={job}", "StartTime=now")
    rc, err = run.finish()
    assert rc == 0, err[-3000:]
    text = (cell / "log.txt").read_text()
    assert f"resuming from {cell / 'checkpoint.pt'}" in text and f"(global step {step})" in text and step > 0
    starts = (out / "submitit" / f"{job}_0_log.out").read_text().count(f"Starting with JobEnvironment(job_id={job},")
    assert starts == 2  # one job, run twice
    assert same_weights(cell, long_reference / "cells" / "channels=8")


@pytest.mark.slow
def test_the_time_limit_warning_stops_a_cell_at_a_checkpoint(slurm_cluster, plugin, tmp_path):
    """SIGUSR2, which the job script asks SLURM for 90 s before the time limit: the cell writes a checkpoint and
    its job ends without a result, named on one line (submitit's own handler would end the cell with an error,
    without a checkpoint: "timed-out and not checkpointable")."""
    src, env = plugin
    out = tmp_path / "out"
    cell = out / "cells" / "channels=4"
    run = Background(env, tmp_path / "run.log", "ablate", src / "long.toml", "--out", out, "--executor", "slurm",
                     "--no-progress", "--cells", "channels=4", "--timeout-min", "5")
    job = run.job_of("channels=4")
    wait_until(running_with_checkpoint(slurm_cluster, job, cell), what="the cell's first checkpoint")
    slurm_cluster.run("scancel", "--signal=USR2", job)
    rc, err = run.finish()
    assert rc == 2, err[-3000:]
    log = out / "submitit" / f"{job}_0_log.err"
    assert err.strip().splitlines()[-1] == (
        f"lfbench ablate: error: 1 of 1 job(s) did not finish: cell channels=4 (job {job}) ended FAILED without a "
        f"result (cancelled, timed out, pre-empted or killed; its log: {log}); run the same command again to resume "
        "them")
    step = checkpoint_step(cell)
    assert f"cell channels=4: stopped at stage 1 step {step}; checkpoint written" in log.read_text()
    assert 0 < step < 800 and not (cell / "cell.json").exists()


@pytest.mark.slow
def test_a_failing_cell_is_one_line_naming_it_and_its_log_after_the_others_finish(slurm_cluster, plugin, tmp_path):
    src, env = plugin
    out = tmp_path / "out"
    proc = lfbench(env, "ablate", src / "failing.toml", "--out", out, "--executor", "slurm", "--cpus-per-job", "1",
                   "--no-progress")
    assert proc.returncode == 2, proc.stderr[-3000:]
    lines = proc.stderr.strip().splitlines()
    job = dict(re.findall(r"cell (\S+): job (\S+), log", proc.stderr))["lr=1e+30"]
    log = out / "submitit" / f"{job}_0_log.err"
    reason = (r"the loss became (nan|inf) at stage 2 step \d+; lower the learning rate \(the last checkpoint is "
              + re.escape(str(out / "cells" / "lr=1e+30" / "checkpoint.pt")) + r"\)")
    expected = (re.escape(f"lfbench ablate: error: 1 of 2 job(s) did not finish: cell lr=1e+30 (job {job}) "
                          "failed: ") + reason
                + re.escape(f" (its log: {log}); run the same command again to resume them"))
    assert re.fullmatch(expected, lines[-1]), lines[-1]
    assert "Traceback" in log.read_text() and "the loss became" in log.read_text()
    # the other cell ran to its end before the command stopped (it trains 405 steps; the NaN came at step 22)
    good = "lr=0.001_stages.1.steps=400"
    assert (out / "cells" / good / "cell.json").is_file()
    assert any(line.startswith(f"cell {good}: trained 405 steps") for line in lines[:-1])
    # each cell trained with the CPUs of its job (--cpus-per-job 1), not with the submitting machine's cores
    assert "threads = 1\n" in (out / "cells" / good / "train.toml").read_text()
    assert "(1 threads)" in (out / "cells" / good / "log.txt").read_text().splitlines()[0]


def test_executor_slurm_without_sbatch_is_one_line_before_any_work(tmp_path):
    """No SLURM commands on PATH: one line, exit 2, and nothing written (no data generated, nothing submitted)."""
    spec = Path(__file__).resolve().parent.parent / "ablations" / "table4_cpu.toml"
    empty = tmp_path / "bin"
    empty.mkdir()
    proc = subprocess.run([sys.executable, "-m", "lfbench", "ablate", str(spec), "--out", str(tmp_path / "out"),
                           "--executor", "slurm"], env={**__import__("os").environ, "PATH": str(empty)},
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == ["lfbench ablate: error: --executor slurm: no sbatch, srun, squeue on PATH; "
                                        "run lfbench ablate where SLURM's commands are (e.g. a login node), or use "
                                        "--executor local or --jobs N"]
    assert not (tmp_path / "out").exists()


def test_a_partition_sbatch_refuses_is_one_line(slurm_cluster, plugin, tmp_path):
    src, env = plugin
    proc = lfbench(env, "ablate", src / "grid.toml", "--out", tmp_path / "out", "--executor", "slurm",
                   "--partition", "nosuch", "--no-progress")
    assert proc.returncode == 2
    last = proc.stderr.strip().splitlines()[-1]  # sbatch's own words, e.g. "Invalid partition name specified"
    assert last.startswith("lfbench ablate: error: submitting the jobs failed: sbatch: error: ") and \
        "partition" in last, last
    assert "Traceback" not in proc.stderr


# --------------------------------------------------------------------------- training under srun

@pytest.mark.slow
def test_train_under_srun_takes_its_ranks_from_slurm_and_matches_torchrun(slurm_cluster, plugin, tmp_path):
    """`srun --ntasks 2 lfbench train` (no torchrun: rank, world size and local rank from SLURM_PROCID,
    SLURM_NTASKS and SLURM_LOCALID; MASTER_ADDR / MASTER_PORT from the job script, as the README says) trains
    the same weights as `torchrun --nproc-per-node 2`, bit for bit: both are gloo on the CPU, with the
    same ranks, the same batches per rank and the same all-reduce."""
    from slurm_cluster import free_port

    src, env = plugin
    text = (src / "train_tiny.toml").read_text().replace("batch_size = 4", "batch_size = 2")
    config = tmp_path / "ddp.toml"
    config.write_text(text.replace("steps = 150", "steps = 20").replace("steps = 10", "steps = 4"))
    script = tmp_path / "train.sh"
    script.write_text(f"""#!/bin/bash
#SBATCH --ntasks=2
#SBATCH --cpus-per-task=1
#SBATCH --output={tmp_path / 'srun.out'}
export MASTER_ADDR=$(scontrol show hostnames "$SLURM_JOB_NODELIST" | head -n 1)
export MASTER_PORT={free_port()}
env | grep -E '^(WORLD_SIZE|RANK|LOCAL_RANK)=' && exit 3   # no torchrun variables
srun {sys.executable} -m lfbench train {config} --out {tmp_path / 'srun'} --no-progress
""")
    _, state = slurm_cluster.batch(f"--export=ALL,PYTHONPATH={env['PYTHONPATH']},OMP_NUM_THREADS=1", str(script))
    assert state == "COMPLETED", (tmp_path / "srun.out").read_text()[-3000:]
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
                           "-m", "lfbench", "train", str(config), "--out", str(tmp_path / "torchrun"),
                           "--no-progress"], env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    srun = torch.load(tmp_path / "srun" / "final.pt", map_location="cpu", weights_only=True)
    assert srun["training"]["world_size"] == 2 and srun["training"]["steps"] == 24
    digests = srun["training"]["rank_parameters_sha256"]
    assert len(digests) == 2 and digests[0] == digests[1]  # two ranks that stayed in step
    assert same_weights(tmp_path / "srun", tmp_path / "torchrun")
