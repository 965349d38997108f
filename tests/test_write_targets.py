"""Every write replaces a regular file or nothing (issue 31, class 2): a file a command is told to write
(``regress --update GOLD``, ``predict --out``, ``convert-keras OUT``, ``bench --json`` / ``--table``) and what an
output folder holds where a command writes its set (``evaluate``, ``report``, ``ablate``, ``train``, ``synth
--force``) is refused before any work when it is a device (a copy of /dev/null made with mknod), a FIFO or a socket:
one line naming it, exit 2, the node left as it was. A named file that is a symbolic link is followed (its target
must be a regular file or new; the link stays); inside an output folder a link is replaced, never followed."""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Callable
from pathlib import Path

import pytest
from helpers import assert_one_error_line, run_cli, write_scene

from lfbench.utils.errors import DataError

RESULTS = '{"records": [{"method": "m", "scene": "s", "metric": "mse_x100", "value": 1.0, "resolution": "lowres"}]}'
TRAIN = '[data]\nroots = ["{root}"]\n[model]\nwidth = 2\n[[stages]]\nloss = "l1"\nlr = 1e-3\nsteps = 1\n'
ABLATION = ('title = "t"\n[base.data]\ntrain = ["synthetic"]\n[[base.data.synthetic]]\ncategory = "synthetic"\n'
            'seed = 1\nsize = 48\nscenes = 1\n[base.model]\nwidth = 2\n[[base.stages]]\nname = "l1"\n'
            'loss = "l1"\nlr = 1e-3\nsteps = 1\n[evaluation]\nsynthetic = { seed = 5, size = 48, scenes = 1 }\n'
            '[[grid]]\ninterval = [1.0]\n')


def _file(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text, encoding="utf-8")
    return path


def _scene(t: Path) -> Path:
    return write_scene(t / "data", "tiny", "training", size=32)


# name -> (the path the command writes, relative to tmp_path; argv given tmp_path). Every command that writes a
# file it is named, or a set into an output folder (demo refuses a folder that is not its own: test_demo).
COMMANDS: dict[str, tuple[str, Callable[[Path], list]]] = {
    "regress-update": ("golden.json", lambda t: ["regress", "--update", t / "golden.json",
                                                 _file(t / "r.json", RESULTS)]),
    "predict-out": ("o.pfm", lambda t: ["predict", "--method", "gt", "--input", _scene(t), "--out", t / "o.pfm"]),
    "predict-extras": ("o.uncertainty.npy", lambda t: ["predict", "--method", "gt", "--input", _scene(t), "--out",
                                                       t / "o.pfm", "--extras"]),
    "convert-keras": ("o.pt", lambda t: ["convert-keras", t / "authors.hdf5", t / "o.pt"]),
    "bench-json": ("b.json", lambda t: ["bench", "inference", "--size", "16", "--json", t / "b.json"]),
    "bench-table": ("b.md", lambda t: ["bench", "inference", "--size", "16", "--table", t / "b.md"]),
    "evaluate": ("out/results.json", lambda t: ["evaluate", "--data", _scene(t), "--method", "gt", "--out", t / "out"]),
    "report": ("rep/table_average.md", lambda t: ["report", _file(t / "r.json", RESULTS), "--out", t / "rep"]),
    "ablate": ("ab/results.json", lambda t: ["ablate", _file(t / "a.toml", ABLATION), "--out", t / "ab"]),
    "train": ("run/final.pt", lambda t: ["-q", "train", _file(t / "c.toml", TRAIN.format(root=_scene(t).parent.parent)),
                                         "--out", t / "run"]),
    "synth-force": ("s/synthetic/synth_0_0", lambda t: ["synth", "--out", t / "s", "--size", "16", "--scenes", "1",
                                                           "--seed", "0", "--force"]),
}
NAMED = ("regress-update", "predict-out", "predict-extras", "convert-keras", "bench-json", "bench-table")


def _node(path: Path, kind: str) -> None:
    """A FIFO, or a character device of /dev/null's numbers (root only: skip elsewhere), at ``path``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    if kind == "fifo":
        os.mkfifo(path)
        return
    try:
        os.mknod(path, stat.S_IFCHR | 0o644, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("mknod is not permitted here (not root): the character-device case needs it")


def _is(path: Path, kind: str) -> bool:
    mode = os.lstat(path).st_mode
    return stat.S_ISFIFO(mode) if kind == "fifo" else stat.S_ISCHR(mode)


WHAT = {"fifo": "is a FIFO", "chardev": "is a character device"}


@pytest.mark.parametrize("kind", ["fifo", "chardev"])
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_device_or_fifo_where_a_command_writes_is_refused_before_the_work(tmp_path, capsys, command, kind):
    target, build = COMMANDS[command]
    _node(tmp_path / target, kind)
    argv = build(tmp_path)
    before = {p for p in tmp_path.rglob("*")}
    rc, out, err = run_cli(capsys, *argv)
    line = assert_one_error_line(rc, err, str(tmp_path / target), WHAT[kind])
    assert line.startswith("lfbench ")
    assert _is(tmp_path / target, kind)  # not replaced
    written = {p for p in tmp_path.rglob("*")} - before
    assert not [p for p in written if p.is_file()], written  # no work done, nothing written


@pytest.mark.parametrize("command", NAMED)
def test_a_named_file_that_links_to_a_device_is_refused(tmp_path, capsys, command):
    target, build = COMMANDS[command]
    _node(tmp_path / "elsewhere" / "node", "fifo")
    (tmp_path / target).symlink_to(tmp_path / "elsewhere" / "node")
    rc, _, err = run_cli(capsys, *build(tmp_path))
    assert_one_error_line(rc, err, str(tmp_path / target), f"symbolic link to {tmp_path / 'elsewhere' / 'node'}",
                          "which is a FIFO")
    assert (tmp_path / target).is_symlink() and _is(tmp_path / "elsewhere" / "node", "fifo")


def test_a_named_file_that_is_a_link_is_written_through(tmp_path, capsys):
    """regress --update and predict --out write the file a link leads to; the link stays a link."""
    real = tmp_path / "shared" / "golden.json"
    real.parent.mkdir()
    real.write_text("[]\n")
    (tmp_path / "golden.json").symlink_to(real)
    rc, out, err = run_cli(capsys, *COMMANDS["regress-update"][1](tmp_path))
    assert rc == 0, err
    assert (tmp_path / "golden.json").is_symlink() and json.loads(real.read_text())[0]["metric"] == "mse_x100"
    (tmp_path / "o.pfm").symlink_to(tmp_path / "shared" / "new.pfm")  # a link to a file not there yet
    rc, out, err = run_cli(capsys, *COMMANDS["predict-out"][1](tmp_path))
    assert rc == 0, err
    assert (tmp_path / "o.pfm").is_symlink() and (tmp_path / "shared" / "new.pfm").read_bytes().startswith(b"Pf\n")


def test_the_writers_themselves_never_replace_a_device_and_replace_a_link_not_its_target(tmp_path):
    from lfbench.utils.atomic import atomic_open, check_replaceable, write_text
    from lfbench.utils.outputs import check_output_file

    fifo = tmp_path / "f"
    os.mkfifo(fifo)
    for write in (lambda p: write_text(p, "x"), lambda p: atomic_open(p).__enter__()):
        with pytest.raises(DataError, match="is a FIFO, not a regular file"):
            write(fifo)
        assert _is(fifo, "fifo")
    folder = tmp_path / "d"
    folder.mkdir()
    with pytest.raises(DataError, match="is a folder"):
        check_replaceable(folder)
    # inside an output folder a link is replaced as a link: its target is never written
    (tmp_path / "victim.txt").write_text("keep")
    (tmp_path / "link").symlink_to(tmp_path / "victim.txt")
    write_text(tmp_path / "link", "new")
    assert not (tmp_path / "link").is_symlink() and (tmp_path / "victim.txt").read_text() == "keep"
    # check_output_file (named files) follows the link instead, and returns where to write
    (tmp_path / "named").symlink_to(tmp_path / "victim.txt")
    assert check_output_file(tmp_path / "named") == tmp_path / "victim.txt"
    (tmp_path / "loop").symlink_to(tmp_path / "loop")
    with pytest.raises(DataError, match="loop"):
        check_output_file(tmp_path / "loop")
