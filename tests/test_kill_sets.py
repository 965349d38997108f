"""Old set or new set, never a mix (issue 20.3): every command that writes a set is stopped at every
point where it changes its folder (tests/killpoints.py: the folder as a kill there leaves it, and real
SIGKILLs at the commit and a sample of other points), and its folder must then hold the previous run's
files or the new run's (once the next run has finished a cut commit, which readers refuse meanwhile);
the next run must give the new set. The same on a small tmpfs that fills up: one line naming the file,
the old set intact.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import uuid
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers import assert_one_error_line, run_cli, write_scene
from killpoints import check_writer, visible

SIZE = 32  # px: 2 px scored inside the 15 px border (a border that leaves none is refused)

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="the kill points run the command in a forked child")


def _data(work: Path) -> None:
    for i in range(2):
        write_scene(work / "data", f"s{i}", "training", size=SIZE, seed=i, view_disparity=i)


def _evaluate(work: Path, *extra, value: float = 0.5) -> list:
    return ["evaluate", "--data", work / "data", "--method", "gt", "--method", f"constant:value={value}", "--out",
            work / "out", "--no-progress", *extra]


def _assert_counts(counts: dict[str, int]) -> None:
    """Points on both sides of the commit point, cut commits among them, and real kills."""
    assert counts["old"] >= 1 and counts["new"] >= 2 and counts["cut"] >= 5 and counts["kills"] >= 3, counts


@pytest.mark.parametrize(("first", "second"), [
    (("--figures", "--ci", "--ci-resamples", "5"), ("--scenes", "s0")),  # ci, figures: dropped by the new set
    (("--html",), ("--html",)),  # the constant method's value differs: every number, map and page
    (("--scenes", "s1"), ("--html", "--save-maps")),  # a site appears where there was none
], ids=["evaluate", "evaluate-html", "evaluate-adds-html"])
def test_evaluate_killed_anywhere_leaves_the_old_set_or_the_new(tmp_path, first, second):
    _assert_counts(check_writer(tmp_path, "out", lambda w: _evaluate(w, *first),
                                lambda w: _evaluate(w, *second, value=0.25), setup=_data))


def _reports(work: Path) -> None:
    _data(work)
    from lfbench.cli import main

    for name, scenes in (("r1", "s0,s1"), ("r2", "s1")):
        assert main(["-q", "evaluate", "--data", str(work / "data"), "--method", "gt", "--method",
                     "constant:value=0.5", "--scenes", scenes, "--out", str(work / name), "--save-maps",
                     "--figures", "--no-progress"]) == 0


@pytest.fixture(scope="module")
def reports(tmp_path_factory) -> Callable[[Path], None]:
    """A setup that copies two results folders of :func:`_reports` into a work folder (made once per module: the
    report tests only read them)."""
    made = tmp_path_factory.mktemp("reports")
    _reports(made)

    def setup(work: Path) -> None:
        shutil.copytree(made, work, symlinks=True, dirs_exist_ok=True)

    return setup


@pytest.mark.parametrize("extra", [(), ("--html", "--maps", "maps")], ids=["report", "report-html"])
def test_report_killed_anywhere_leaves_the_old_set_or_the_new(tmp_path, extra, reports):
    def report(results: str):  # with --maps: overviews and the toolkit's figures too
        return lambda w: ["report", w / results, "--out", w / "rep",
                          *(w / results / x if x == "maps" else x for x in extra)]

    _assert_counts(check_writer(tmp_path, "rep", report("r1"), report("r2"), setup=reports))


def test_demo_killed_anywhere_leaves_the_old_set_or_the_new(tmp_path):
    def demo(methods: str):
        return lambda w: ["demo", "--out", w / "demo", "--size", "32", "--scenes", "1", "--methods", methods,
                          "--no-progress"]

    _assert_counts(check_writer(tmp_path, "demo", demo("gt"), demo("gt,constant:value=0.5"), ignore={"data"}))


ABLATION = """
title = "kill"
table = "table4"
[base.data]
train = ["synthetic"]
patch = 16
strides = [1]
stride_weights = [1]
[[base.data.synthetic]]
category = "synthetic"
seed = 1
size = 48
scenes = 1
[base.augment]
enabled = false
[base.model]
width = 2
[base.training]
batch_size = 1
device = "cpu"
prefetch = 0
[[base.stages]]
name = "l1"
loss = "l1"
lr = 1e-3
steps = 1
[budget]
threads = 1
[evaluation]
synthetic = { seed = 5, size = 32, scenes = 1 }
time_size = 16
time_repeats = 1
threads = 1
[[grid]]
interval = [1.0]
interpolation = ["bilinear"]
"""


@pytest.mark.slow
def test_ablate_killed_anywhere_leaves_the_old_set_or_the_new(tmp_path):
    """The cell is trained once (by ``first``, in its own interpreter); the killed runs re-tabulate it with
    one more extra method (the zero map), which changes results.json, every table, the figures and the
    site, and use no torch (the cell's scores and test time are cached)."""
    def setup(work: Path) -> None:
        (work / "a.toml").write_text(ABLATION, encoding="utf-8")
        (work / "b.toml").write_text(ABLATION + '[[methods]]\nlabel = "zero"\nspec = "constant:value=0"\n',
                                     encoding="utf-8")

    def ablate(spec: str):
        return lambda w: ["-q", "ablate", w / spec, "--out", w / "ab", "--html", "--no-progress"]

    _assert_counts(check_writer(tmp_path, "ab", ablate("a.toml"), ablate("b.toml"), setup=setup, first_apart=True,
                                ignore={"cells", "data", "eval_data", "methods", "stage1"}))


# --------------------------------------------------------------------------- a disk that fills up

@pytest.fixture()
def small_disk(tmp_path):
    """A 32 MiB tmpfs (root only: `mount -t tmpfs`); skipped with the reason elsewhere."""
    mnt = tmp_path / f"tmpfs-{uuid.uuid4().hex[:6]}"
    mnt.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("a small tmpfs needs root (mount -t tmpfs); the kill points above cover the same commits")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=32m", "tmpfs", str(mnt)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {done.stderr.decode(errors='replace').strip()}")
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def _fill(mnt: Path, leave: int) -> Path:
    """Fill the tmpfs up to ``leave`` bytes free (a ballast file the test removes again)."""
    ballast = mnt / "ballast"
    st = os.statvfs(mnt)
    free = st.f_bavail * st.f_frsize
    with open(ballast, "ab") as f:
        try:
            f.write(b"\0" * max(0, free - leave))
        except OSError as exc:
            assert exc.errno == errno.ENOSPC
    return ballast


@pytest.mark.parametrize("writer", ["evaluate", "evaluate-html", "report", "report-html", "demo",
                                    pytest.param("ablate", marks=pytest.mark.slow)])
def test_a_full_disk_is_one_line_naming_the_file_and_keeps_the_old_set(tmp_path, capsys, small_disk, writer,
                                                                     reports):
    data = tmp_path / "in"
    (reports if writer.startswith("report") else _data)(data)
    (data / "a.toml").write_text(ABLATION, encoding="utf-8")
    (data / "b.toml").write_text(ABLATION + '[[methods]]\nlabel = "zero"\nspec = "constant:value=0"\n',
                                 encoding="utf-8")
    out = small_disk / "out"
    commands = {
        "evaluate": (_evaluate(data, "--figures", "--out", out), _evaluate(data, "--scenes", "s0", "--out", out)),
        "evaluate-html": (_evaluate(data, "--html", "--out", out), _evaluate(data, "--html", "--scenes", "s0",
                                                                              "--out", out)),
        "report": (["report", data / "r1", "--out", out], ["report", data / "r2", "--out", out]),
        "report-html": (["report", data / "r1", "--out", out, "--html"], ["report", data / "r2", "--out", out,
                                                                           "--html"]),
        "ablate": (["-q", "ablate", data / "a.toml", "--out", out, "--html", "--no-progress"],
                   ["-q", "ablate", data / "b.toml", "--out", out, "--html", "--no-progress"]),
        "demo": (["-q", "demo", "--out", out, "--size", "32", "--scenes", "1", "--methods", "gt", "--no-progress"],
                 ["-q", "demo", "--out", out, "--size", "32", "--scenes", "1", "--methods", "gt,constant:value=0.5",
                  "--no-progress"]),
    }
    first, second = commands[writer]
    ignore = {"cells", "data", "eval_data", "methods", "stage1"}  # not part of a set (generated data, caches)
    rc, _, err = run_cli(capsys, *first)
    assert rc == 0, err
    old = visible(out, ignore)
    failed = []
    for leave in (0, 4096, 16384, 65536, 196608):  # bytes left free: the run fails at different files
        ballast = _fill(small_disk, leave)
        rc, _, err = run_cli(capsys, *second)
        if rc != 0:
            line = assert_one_error_line(rc, err, "No space left on device", str(out))
            failed.append(line)
            assert visible(out, ignore) == old, f"{leave} bytes free: the old set is not whole"
        ballast.unlink()
        if rc == 0:  # it fitted: the new set; the next round starts from it
            old = visible(out, ignore)
    assert len(failed) >= 2, failed
    named = [line.split(": ")[2] for line in failed]  # lfbench CMD: error: PATH: cannot write: ...
    assert any(Path(n).is_relative_to(out) and Path(n) != out for n in named), named  # a file, not just OUT
    assert not [n for n in named if "/." in n[len(str(out)):]], named  # where it lands, not a temporary's name
    rc, _, err = run_cli(capsys, *second)  # with room again the next run works
    assert rc == 0, err
    assert not [p for p in out.iterdir() if p.name.startswith(".lfbench-stage")]
