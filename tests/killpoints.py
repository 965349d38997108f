"""Kill an ``lfbench`` command at any point, as ``kill -9`` or a power cut would, and check its folder.

:func:`run` forks a child that runs the command in-process (no interpreter start: a run costs the
command's own work only). Every file-system change the child makes is a *point*: each call of
os.replace, os.rename, os.unlink, os.rmdir, os.mkdir, os.fsync and shutil.rmtree (a write goes through
lfbench.utils.atomic: a temporary, fsync, a rename). With ``kill_at=k`` the child SIGKILLs itself just
before its k-th point: nothing of the point, nor any clean-up or ``finally``, runs. With ``snapshots``
it copies the output folder just before every point instead: what a kill there would leave (a killed
process leaves exactly the files it has written; the commands write through atomic_open, which flushes
before it renames). The child's clocks that reach the outputs (a method's runtime, results.json's
``created``) are fixed, so that two uninterrupted runs give byte-identical folders.

:func:`check_writer` is the whole check for one set writer: the old set (command ``first``), the new
set (``second``), then the folder as ``second`` leaves it at every point: once a cut commit is finished
as the next run does it (readers refuse the folder meanwhile), it must be the old set or the new one.
At a sample of the points ``second`` is really killed: the folder must be what the snapshot there
showed, and the next run must give the new set.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Collection, Sequence
from pathlib import Path

POINTS = (("os", "replace"), ("os", "rename"), ("os", "unlink"), ("os", "rmdir"), ("os", "mkdir"), ("os", "fsync"),
          ("shutil", "rmtree"))
HIDDEN_TEMPORARIES = (".lfbench-stage.", ".data.", ".figures.", ".html.", ".maps.")
CHILD_TIMEOUT_S = int(os.environ.get('KILLPOINTS_TIMEOUT_S', '300'))


def warm() -> None:
    """Import what the commands import, once in this process, so that each forked child starts at once;
    stop tqdm's monitor thread (a child forked while it holds tqdm's lock would wait for it forever)."""
    import importlib

    import tqdm

    from lfbench.cli import build_parser
    from lfbench.method.registry import list_methods

    tqdm.tqdm.monitor_interval = 0
    if tqdm.tqdm.monitor is not None:
        tqdm.tqdm.monitor.exit()
        tqdm.tqdm.monitor = None
    build_parser()
    list_methods()
    for name in ("lfbench.runs.folder", "lfbench.runs.demo", "lfbench.reports.html", "lfbench.reports.from_results",
                 "lfbench.reports.toolkit_figures", "lfbench.scoring.stats", "lfbench.scoring.region_metrics",
                 "lfbench.ablation.runner", "lfbench.ablation.report", "jinja2", "filelock"):
        importlib.import_module(name)
    from lfbench.reports.plotting import pyplot

    pyplot()


def _child(argv: Sequence[str], kill_at: int | None, log: Path, cwd: Path | None,
           snapshots: tuple[Path, Path, Collection[str]] | None) -> None:
    """In the forked child: patch, run, report the points, exit (never returns)."""
    rc = 99
    try:
        if cwd is not None:
            os.chdir(cwd)
        fd = os.open(log, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        import faulthandler

        faulthandler.dump_traceback_later(CHILD_TIMEOUT_S - 10, exit=False)  # a hang shows where, in the log
        import datetime as dt

        import lfbench.method.base as base
        import lfbench.results as results

        class FixedNow(dt.datetime):
            @classmethod
            def now(cls, tz=None):
                return dt.datetime(2030, 1, 2, 3, 4, 5, tzinfo=tz)

        ticks = iter(range(10**12))
        base.time = type("Clock", (), {"perf_counter": staticmethod(lambda: next(ticks) * 1e-3)})
        results.datetime = FixedNow
        seen: list[str] = []
        busy = []  # set while a snapshot is copied: its own file operations are not points
        copytree = shutil.copytree

        def snapshot() -> None:
            folder, into, ignore = snapshots
            busy.append(1)
            try:
                target = into / str(len(seen))
                if folder.is_dir():  # hard links: cheap, and exact (every write makes a new file and renames it)
                    copytree(folder, target / "out", symlinks=True, copy_function=os.link,
                             ignore=lambda d, names: [n for n in names if Path(d) == folder and n in ignore])
                else:
                    target.mkdir(parents=True)
            finally:
                busy.pop()

        dirty = [True]  # whether the last point may have changed what a kill leaves (see shows())

        def wrap(kind: str, fn: Callable) -> Callable:
            def point(*args, **kwargs):
                if busy:
                    return fn(*args, **kwargs)
                paths = [str(a) for a in args if isinstance(a, str | os.PathLike)]
                seen.append(" ".join([kind, *paths]))
                if kill_at is not None and len(seen) == kill_at:
                    os.kill(os.getpid(), signal.SIGKILL)
                if snapshots is not None and dirty[0]:
                    snapshot()
                dirty[0] = snapshots is not None and shows(snapshots[0], paths)
                return fn(*args, **kwargs)
            return point

        for module_name, attr in POINTS:
            module = os if module_name == "os" else shutil
            setattr(module, attr, wrap(attr, getattr(module, attr)))
        from lfbench.cli import main

        rc = main([str(a) for a in argv])
        Path(f"{log}.points").write_text(json.dumps(seen))
    except BaseException as exc:  # noqa: BLE001 - reported through the exit code and the log
        with open(log, "a") as f:
            f.write(f"\nchild failed: {type(exc).__name__}: {exc}\n")
    finally:
        os._exit(rc if isinstance(rc, int) else 98)


def shows(folder: Path, paths: Sequence[str]) -> bool:
    """Whether a change of ``paths`` can change what a kill leaves in ``folder``: a path in it outside its
    hidden temporaries, or a journal or manifest. A change inside a staging folder cannot: before the
    journal is written the staging folder is dropped by the next run, and after it the staging folder
    only loses entries, each by a rename that also touches a path in the folder."""
    top = os.path.abspath(folder)
    for path in paths:
        rel = os.path.relpath(os.path.abspath(path), top)
        if rel == "." or rel.startswith(".."):
            continue
        first = rel.split(os.sep, 1)[0]
        if not first.startswith(".") or first.startswith((".lfbench-commit", ".lfbench-outputs")):
            return True
    return False


def run(argv: Sequence[str], log: Path, kill_at: int | None = None, cwd: Path | None = None,
        snapshots: tuple[Path, Path, Collection[str]] | None = None) -> tuple[int, list[str]]:
    """(exit status, the points passed) of ``lfbench ARGV`` run in ``cwd`` in a forked child; -9 when it
    was killed. ``snapshots`` = (folder, into, ignore): copy ``folder`` (without its entries named in
    ``ignore``) to into/<k>/out before the k-th point (into/<k> empty: the folder was not there)."""
    points = Path(f"{log}.points")
    points.unlink(missing_ok=True)
    pid = os.fork()
    if pid == 0:
        _child(argv, kill_at, log, cwd, snapshots)
    deadline = time.monotonic() + CHILD_TIMEOUT_S
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            os.waitpid(pid, 0)
            raise AssertionError(f"lfbench {' '.join(map(str, argv))} did not finish in {CHILD_TIMEOUT_S} s: "
                                 f"{log.read_text()[-3000:]}")
        time.sleep(0.01)
    code = -os.WTERMSIG(status) if os.WIFSIGNALED(status) else os.WEXITSTATUS(status)
    return code, json.loads(points.read_text()) if points.is_file() else []


def visible(folder: Path, ignore: Collection[str] = ()) -> dict[str, object]:
    """What a reader of ``folder`` sees: every file's bytes, every folder, every link (not followed), with
    the hidden temporaries of runs (staging folders, .tmp), lock files and the top-level ``ignore`` left out."""
    out: dict[str, object] = {}
    for root, dirs, files in os.walk(folder):
        if root == str(folder):
            dirs[:] = [d for d in dirs if not d.startswith(HIDDEN_TEMPORARIES) and d not in ignore]
            files = [f for f in files if f not in ignore]
        for name in dirs + files:
            path = Path(root) / name
            if name.endswith(".lock") or (name.startswith(".") and name.endswith(".tmp")):
                continue
            rel = str(path.relative_to(folder))
            if path.is_symlink():
                out[rel] = ("link", os.readlink(path))
            elif path.is_dir():
                out[rel] = "dir"
            else:
                out[rel] = path.read_bytes()
    return out


def describe(a: dict[str, object], b: dict[str, object]) -> str:
    """The paths where two snapshots differ (for a failure message)."""
    diff = sorted(k for k in set(a) | set(b) if a.get(k) != b.get(k))
    return ", ".join(diff[:12]) + (f" ... ({len(diff)} in all)" if len(diff) > 12 else "")


def pending_journals(folder: Path) -> list[str]:
    """The journals of cut commits in ``folder`` (.lfbench-commit.json, .lfbench-commit.<set>.json)."""
    return sorted(p.name for p in folder.iterdir() if re.fullmatch(r"\.lfbench-commit(\.[a-z0-9_]+)?\.json", p.name))


def settle(folder: Path) -> bool:
    """Check that readers refuse a folder with a cut commit, then finish it as the next run does. Returns
    whether a commit was cut."""
    from lfbench.utils.errors import DataError
    from lfbench.utils.outputs import check_complete, recover

    if not folder.is_dir() or not pending_journals(folder):
        return False
    try:
        check_complete(folder)
    except DataError:
        recover(folder)
        return True
    raise AssertionError(f"{folder}: a cut commit is not refused by readers")


def sample(points: Sequence[str], folder: str, spread: int) -> list[int]:
    """Points (1-based) for real kills: the journal's write (the commit point), the first entry moved into
    ``folder``, the last point, and ``spread`` points spread over the staging."""
    into = [k for k, p in enumerate(points, 1) if p.startswith("replace") and p.split(" ")[-1].startswith(
        f"{folder}/") and "/." not in p.split(" ")[-1][len(folder):]]
    journal = [k for k, p in enumerate(points, 1) if p.startswith("replace") and p.endswith(".lfbench-commit.json")]
    staging = list(range(1, min(journal + [len(points)])))
    spread_points = staging[len(staging) // (spread + 1)::len(staging) // (spread + 1) or 1][:spread]
    return sorted({*journal[-1:], *into[:1], len(points), *spread_points})


def check_writer(tmp: Path, folder: str, first: Callable[[Path], Sequence], second: Callable[[Path], Sequence],
                 setup: Callable[[Path], None] | None = None, kills: int = 1,
                 ignore: Collection[str] = (), first_apart: bool = False) -> dict[str, int]:
    """The kill check of one set writer (see the module docstring). ``first``/``second``: argv given the
    work folder W, run inside W (given as '.', so that the paths they record are the same in every copy
    of W); they write W/``folder``. ``setup(W)`` prepares inputs in W before ``first``. ``kills``: real
    kills spread over the staging, besides those at the commit. ``ignore``: top-level entries of the
    folder that are not part of its set (e.g. generated data). Returns counts: points, real kills, and
    of all the points those that left the old set, the new set, and a cut commit. ``first_apart``: run
    ``first`` in a new interpreter instead of a forked child (training: torch's thread pool, once used by
    this process, does not survive a fork)."""
    warm()
    here = Path(".")
    base = tmp / "base"
    base.mkdir()
    if setup is not None:
        setup(base)
    if first_apart:
        done = subprocess.run([sys.executable, "-m", "lfbench", *map(str, first(here))], cwd=base,
                              capture_output=True, text=True, timeout=CHILD_TIMEOUT_S)
        assert done.returncode == 0, done.stderr[-3000:]
    else:
        rc, _ = run(first(here), tmp / "first.log", cwd=base)
        assert rc == 0, (tmp / "first.log").read_text()
    old = visible(base / folder, ignore)
    ref = tmp / "ref"
    shutil.copytree(base, ref, symlinks=True)
    snaps = tmp / "snapshots"
    rc, points = run(second(here), tmp / "ref.log", cwd=ref, snapshots=(Path(folder), snaps, ignore))
    assert rc == 0, (tmp / "ref.log").read_text()
    new = visible(ref / folder, ignore)
    assert new != old, "the two runs must write different sets"
    assert not pending_journals(ref / folder)
    counts = {"points": len(points), "snapshots": 0, "kills": 0, "old": 0, "new": 0, "cut": 0}
    left: dict[int, dict[str, object]] = {}
    for k in sorted(int(p.name) for p in snaps.iterdir()):  # points after a hidden change share the one before
        snap = snaps / str(k) / "out"
        counts["cut"] += settle(snap)
        seen = visible(snap, ignore)
        assert seen in (old, new), (f"point {k} ({points[k - 1]}): the folder mixes two runs: differs from the old "
                                    f"set in {describe(seen, old)}; from the new set in {describe(seen, new)}")
        counts["snapshots"] += 1
        counts["old" if seen == old else "new"] += 1
        left[k] = seen
    for k in sample(points, folder, kills):
        work = tmp / f"k{k}"
        shutil.copytree(base, work, symlinks=True)
        rc, _ = run(second(here), tmp / f"k{k}.log", kill_at=k, cwd=work)
        assert rc == -signal.SIGKILL, f"point {k} ({points[k - 1]}): not killed, exit {rc}"
        counts["kills"] += 1
        cut = settle(work / folder)
        seen = visible(work / folder, ignore)
        expected = left[max(j for j in left if j <= k)]
        assert seen == expected, f"point {k}: a real kill left {describe(seen, expected)} unlike the snapshot"
        if cut or points[k - 1].endswith(f"{folder}/.lfbench-commit.json"):  # after a cut commit, before one
            rc, _ = run(second(here), tmp / f"k{k}.rerun.log", cwd=work)
            assert rc == 0, (tmp / f"k{k}.rerun.log").read_text()
            after = visible(work / folder, ignore)
            assert after == new, f"point {k}: the next run does not give the new set ({describe(after, new)})"
            assert not [p for p in (work / folder).iterdir() if p.name.startswith(HIDDEN_TEMPORARIES)], k
    return counts
