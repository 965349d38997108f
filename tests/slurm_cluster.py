"""A throwaway single-node SLURM cluster for the tests (and for trying the README's cluster recipe by hand):
munged, slurmctld and slurmd of this host, started as child processes with every file they write (key,
socket, configuration, state, spool, logs) in one folder, stopped and removed at the end.

    python tests/slurm_cluster.py -- sbatch --wait --wrap hostname    # start, run the command, stop

The client commands (sbatch, squeue, srun, scancel, scontrol, sinfo) find the cluster through
``SLURM_CONF`` (:attr:`SlurmCluster.env`); nothing system-wide is read or written except what the
packages install (the binaries, /etc/munge/munge.key, which is not used: munged gets its own key and
socket, and SLURM's ``AuthInfo=socket=...`` points at that socket). The configuration (:func:`slurm_conf`):
this host's name and CPU count, its memory from /proc/meminfo, one partition, ``SlurmUser`` = the current
user (root where the tests run), ``ProctrackType=proctrack/linuxproc`` and ``TaskPlugin=task/none`` (no
cgroups: containers rarely allow them), ``select/cons_tres`` with ``CR_CPU`` so that 1-CPU jobs share the
node, no accounting database (``sacct`` does not work; finished jobs are written one line each to
``jobcomp.txt`` by ``jobcomp/filetxt``), free TCP ports for the daemons, ``KillWait=5``.

Needs slurm-wlm and munge (Debian: ``apt-get install slurm-wlm munge``; checked with slurm-wlm 22.05 on
Debian 12, also inside gVisor). Where they are missing or the daemons do not come up,
:func:`start_cluster` raises :class:`ClusterUnavailable` with the reason (the ``slurm_cluster`` fixture
skips with it; with ``LFBENCH_REQUIRE_SLURM=1``, as CI sets after installing the packages, it fails).
As root (CI) the daemons run as root; as another user they run as that user (``SlurmUser``), which runs
that user's own jobs (checked on Debian 12 as an unprivileged user: sinfo, srun and sbatch work).
"""

from __future__ import annotations

import contextlib
import getpass
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

#: Binaries the cluster needs (daemons and the client commands the tests and submitit call).
BINARIES = ("munged", "slurmctld", "slurmd", "sinfo", "sbatch", "srun", "squeue", "scancel", "scontrol")
PARTITION = "lfbench"
#: Job states after which a job runs no more (squeue --states=all shows them for MinJobAge seconds).
FINAL_STATES = frozenset({"COMPLETED", "CANCELLED", "FAILED", "TIMEOUT", "NODE_FAIL", "OUT_OF_MEMORY", "BOOT_FAIL",
                          "DEADLINE", "PREEMPTED"})


class ClusterUnavailable(RuntimeError):
    """The cluster cannot run here; the message says why (missing binaries, a daemon that did not start)."""


def memory_mb() -> int:
    """This host's memory in MiB as slurmd counts it (MemTotal of /proc/meminfo)."""
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemTotal:"):
            return int(line.split()[1]) // 1024
    raise ClusterUnavailable("/proc/meminfo has no MemTotal line")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def slurm_conf(root: Path, *, node: str, cpus: int, memory: int, user: str, ports: tuple[int, int],
               munge_socket: Path) -> str:
    """slurm.conf of a one-node cluster whose state, spool, logs and pid files are under ``root``."""
    return "\n".join([
        "# A throwaway test cluster written by tests/slurm_cluster.py",
        "ClusterName=lfbenchtest",
        f"SlurmctldHost={node}(127.0.0.1)",
        f"SlurmctldPort={ports[0]}",
        f"SlurmdPort={ports[1]}",
        f"SlurmUser={user}",
        f"SlurmdUser={user}",
        "AuthType=auth/munge",
        "CredType=cred/munge",
        f"AuthInfo=socket={munge_socket}",
        f"StateSaveLocation={root / 'state'}",
        f"SlurmdSpoolDir={root / 'spool'}",
        f"SlurmctldPidFile={root / 'slurmctld.pid'}",
        f"SlurmdPidFile={root / 'slurmd.pid'}",
        f"SlurmctldLogFile={root / 'log' / 'slurmctld.log'}",
        f"SlurmdLogFile={root / 'log' / 'slurmd.log'}",
        f"PlugStackConfig={root / 'plugstack.conf'}",
        "ProctrackType=proctrack/linuxproc",
        "TaskPlugin=task/none",
        "JobAcctGatherType=jobacct_gather/none",
        "AccountingStorageType=accounting_storage/none",
        "JobCompType=jobcomp/filetxt",
        f"JobCompLoc={root / 'log' / 'jobcomp.txt'}",
        "SchedulerType=sched/backfill",
        "SelectType=select/cons_tres",
        "SelectTypeParameters=CR_CPU",
        "MpiDefault=none",
        "ReturnToService=2",
        "KillWait=5",
        "InactiveLimit=0",
        "MinJobAge=300",
        f"NodeName={node} NodeAddr=127.0.0.1 CPUs={cpus} RealMemory={memory} State=UNKNOWN",
        f"PartitionName={PARTITION} Nodes={node} Default=YES MaxTime=INFINITE State=UP",
        "",
    ])


def _die_with_parent() -> None:
    """In the child before exec: receive SIGTERM when the process that started it dies (Linux), so that a
    killed pytest leaves no daemons behind."""
    with contextlib.suppress(Exception):
        import ctypes

        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG


@dataclass
class SlurmCluster:
    """A running one-node cluster. ``env``: this process's environment without any SLURM_* job variables,
    with SLURM_CONF naming the cluster's configuration (give it to every command that talks to it)."""

    root: Path
    node: str
    cpus: int
    env: dict[str, str]
    started_s: float = 0.0  # seconds from starting munged to the node being idle
    _daemons: dict[str, subprocess.Popen] = field(default_factory=dict, repr=False)

    @property
    def conf(self) -> Path:
        return self.root / "slurm.conf"

    @property
    def jobcomp(self) -> Path:
        return self.root / "log" / "jobcomp.txt"

    def run(self, *args: str, check: bool = True, timeout: float = 60) -> subprocess.CompletedProcess:
        """A client command (sinfo, squeue, scontrol, ...) against this cluster."""
        proc = subprocess.run(list(args), env=self.env, capture_output=True, text=True, timeout=timeout)
        if check and proc.returncode != 0:
            raise RuntimeError(f"{' '.join(args)}: exit {proc.returncode}: {proc.stderr.strip()}")
        return proc

    def jobs(self) -> dict[str, dict[str, str]]:
        """The jobs the controller knows (running, pending and finished in the last MinJobAge seconds), one per
        array task: job id (``123`` or ``123_4``) -> {"raw": the task's own job id (as jobcomp.txt names it),
        "name", "state", "reason"}."""
        out = self.run("squeue", "--noheader", "--array", "--states=all", "--format=%i|%A|%j|%T|%r").stdout
        jobs = {}
        for line in out.splitlines():
            job_id, raw, name, state, reason = line.split("|", 4)
            jobs[job_id] = {"raw": raw, "name": name, "state": state, "reason": reason}
        return jobs

    def batch(self, *args: str, timeout_s: float = 600) -> tuple[str, str]:
        """``sbatch ARGS``, then wait for the job to end (polling squeue every 0.2 s: ``sbatch --wait`` polls
        every 10 s). Returns (job id, final state)."""
        job = self.run("sbatch", "--parsable", *args).stdout.strip().split(";")[0]
        deadline = time.monotonic() + timeout_s
        while (state := self.jobs().get(job, {}).get("state", "")) not in FINAL_STATES:
            if time.monotonic() > deadline:
                raise TimeoutError(f"job {job} still {state or 'unknown'} after {timeout_s:.0f} s")
            time.sleep(0.2)
        return job, state

    def completed(self) -> list[dict[str, str]]:
        """The job completion log (jobcomp/filetxt): one dict of its KEY=VALUE fields per finished job run."""
        if not self.jobcomp.is_file():
            return []
        return [dict(f.split("=", 1) for f in line.split() if "=" in f)
                for line in self.jobcomp.read_text().splitlines() if line.strip()]

    def node_state(self) -> str:
        return self.run("sinfo", "--noheader", "--Node", "--format=%T", check=False).stdout.strip()

    def wait_idle(self, timeout_s: float = 60) -> None:
        """Wait until no job of the cluster is pending or running and the node is idle."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            active = [j for j, info in self.jobs().items() if info["state"] not in FINAL_STATES]
            if not active and self.node_state() == "idle":
                return
            time.sleep(0.5)
        raise TimeoutError(f"the test cluster is not idle after {timeout_s:.0f} s: {self.jobs()}")

    def log_tail(self, lines: int = 15) -> str:
        parts = []
        for log in sorted((self.root / "log").glob("*.log")):
            tail = log.read_text(errors="replace").splitlines()[-lines:]
            parts.append(f"--- {log.name}\n" + "\n".join(tail))
        return "\n".join(parts)

    def stop(self) -> None:
        """Cancel every job, shut the daemons down (scontrol shutdown, then SIGTERM, then SIGKILL) and stop munged."""
        if {"slurmctld", "slurmd"} & {n for n, p in self._daemons.items() if p.poll() is None}:
            with contextlib.suppress(Exception):
                self.run("scancel", f"--user={getpass.getuser()}", check=False, timeout=20)
                self.wait_idle(20)
            with contextlib.suppress(Exception):
                self.run("scontrol", "shutdown", check=False, timeout=20)
        for name in ("slurmd", "slurmctld", "munged"):
            proc = self._daemons.get(name)
            if proc is None:
                continue
            if name != "munged":  # scontrol shutdown stops the SLURM daemons; munged needs SIGTERM
                with contextlib.suppress(subprocess.TimeoutExpired):
                    proc.wait(10)
            if proc.poll() is None:
                proc.terminate()
                try:
                    proc.wait(10)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        self._daemons.clear()


def missing_binaries() -> list[str]:
    return [b for b in BINARIES if shutil.which(b, path=os.environ.get("PATH", "") + ":/usr/sbin:/sbin") is None]


def _which(name: str) -> str:
    found = shutil.which(name, path=os.environ.get("PATH", "") + ":/usr/sbin:/sbin")
    assert found is not None
    return found


def start_cluster(root: Path, *, timeout_s: float = 90) -> SlurmCluster:
    """Write the configuration and a fresh munge key under ``root``, start munged, slurmctld and slurmd, and
    wait (up to ``timeout_s``) until ``sinfo`` shows the node idle. ClusterUnavailable says why it could not."""
    missing = missing_binaries()
    if missing:
        raise ClusterUnavailable(f"SLURM is not installed (no {', '.join(missing)}; on Debian: apt-get install "
                                 "slurm-wlm munge)")
    root = Path(root)
    munge_dir = root / "munge"
    socket_path = munge_dir / "munge.socket.2"
    if len(str(socket_path)) > 100:
        raise ClusterUnavailable(f"the munge socket path {socket_path} is too long for a UNIX socket")
    for sub in ("state", "spool", "log"):
        (root / sub).mkdir(parents=True, exist_ok=True)
    munge_dir.mkdir(mode=0o711, exist_ok=True)
    key = munge_dir / "munge.key"
    key.write_bytes(os.urandom(1024))
    key.chmod(0o400)
    (root / "plugstack.conf").write_text("")  # no SPANK plugins (not the system's /etc/slurm/plugstack.conf)
    node = socket.gethostname().split(".")[0]
    cpus = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    user = getpass.getuser()
    (root / "slurm.conf").write_text(slurm_conf(root, node=node, cpus=cpus, memory=memory_mb(), user=user,
                                                ports=(free_port(), free_port()), munge_socket=socket_path))
    env = {k: v for k, v in os.environ.items() if not k.startswith(("SLURM_", "SBATCH_", "SRUN_", "SALLOC_"))}
    env["SLURM_CONF"] = str(root / "slurm.conf")
    cluster = SlurmCluster(root=root, node=node, cpus=cpus, env=env)
    start = time.monotonic()
    commands = {
        "munged": [_which("munged"), "--foreground", "--force", f"--socket={socket_path}", f"--key-file={key}",
                   f"--log-file={root / 'log' / 'munged.log'}", f"--pid-file={munge_dir / 'munged.pid'}",
                   f"--seed-file={munge_dir / 'munged.seed'}"],
        "slurmctld": [_which("slurmctld"), "-D", "-i", "-f", str(cluster.conf)],
        "slurmd": [_which("slurmd"), "-D", "-f", str(cluster.conf), "-N", node],
    }
    try:
        for name, cmd in commands.items():
            out = open(root / "log" / f"{name}.out", "wb")  # noqa: SIM115 - the daemon keeps it
            cluster._daemons[name] = subprocess.Popen(cmd, env=env, stdout=out, stderr=subprocess.STDOUT,
                                                      stdin=subprocess.DEVNULL, preexec_fn=_die_with_parent)
            out.close()
            if name == "munged":
                _wait_for(lambda: socket_path.exists(), cluster, name, 15)
        deadline = time.monotonic() + timeout_s
        while cluster.node_state() != "idle":
            for name, proc in cluster._daemons.items():
                if proc.poll() is not None:
                    raise ClusterUnavailable(f"{name} exited with code {proc.returncode}:\n{cluster.log_tail()}")
            if time.monotonic() > deadline:
                raise ClusterUnavailable(f"the node is not idle after {timeout_s:.0f} s (sinfo: "
                                         f"{cluster.node_state() or 'no answer'}):\n{cluster.log_tail()}")
            time.sleep(0.25)
    except BaseException:
        cluster.stop()
        raise
    cluster.started_s = time.monotonic() - start
    return cluster


def _wait_for(ready, cluster: SlurmCluster, name: str, timeout_s: float) -> None:
    deadline = time.monotonic() + timeout_s
    while not ready():
        proc = cluster._daemons[name]
        if proc.poll() is not None or time.monotonic() > deadline:
            raise ClusterUnavailable(f"{name} did not start (exit code {proc.poll()}):\n{cluster.log_tail()}")
        time.sleep(0.1)


@contextlib.contextmanager
def running_cluster(root: Path | None = None) -> Iterator[SlurmCluster]:
    """A started cluster for the block (files in ``root``, else a temporary folder removed afterwards)."""
    tmp = None
    if root is None:
        root = Path(tmp := tempfile.mkdtemp(prefix="lfslurm-"))
    cluster = start_cluster(root)
    try:
        yield cluster
    finally:
        cluster.stop()
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


def main(argv: list[str]) -> int:
    if not argv:
        print(__doc__.split("\n\n")[1])
        return 2
    try:
        with running_cluster() as cluster:
            print(f"test cluster up in {cluster.started_s:.1f} s: SLURM_CONF={cluster.env['SLURM_CONF']}",
                  file=sys.stderr)
            return subprocess.run(argv, env=cluster.env).returncode
    except ClusterUnavailable as exc:
        print(f"slurm_cluster: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:] if sys.argv[1:2] != ["--"] else sys.argv[2:]))
