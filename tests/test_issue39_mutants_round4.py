"""Tests that must fail (issue 39 item 6, fourth round): the rest of the four files the third round mutated in part.

lfbench/utils/outputs.py (the output sets: staging, the journal, the commit and its roll forward, the checks of
what is read back), lfbench/ablation/cell.py (the cell's config, data links, stage-1 seed, evaluation, timing and
run), lfbench/utils/executor.py (the labels, the GPUs of the workers, the in-process executor, the pool's map with
a pool that runs in this process, the registry) and lfbench/training/checkpoint.py (the RNG state, save, the
digests, the export). Each test names the class of mutants it kills; every expected value is written out (exact
error lines, which files exist and what they hold). In-process only: no subprocess, no process pool (a pool's fork
deadlocks mutmut's children), no sleep, no training. Results: results/mutation/issue39/README.md, "Fourth round".
"""

from __future__ import annotations

import dataclasses
import errno
import hashlib
import json
import logging
import os
import random
import signal
import tempfile
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from lfbench.ablation import cell
from lfbench.ablation.spec import Evaluation
from lfbench.training import checkpoint as tck
from lfbench.utils import executor, outputs
from lfbench.utils.errors import DataError, LFBenchError, RunFailed, SpecError
from lfbench.utils.threads import torch_threads

STAGE = outputs.STAGE_PREFIX
NOT_LFBENCH = (": not a file lfbench wrote; nothing was changed (remove it if this folder is yours and the run that "
               "wrote it is not running)")


def _files(folder: Path) -> dict[str, str]:
    """Every file under ``folder`` (links as ``-> target``), by relative path."""
    out = {}
    for p in sorted(folder.rglob("*")):
        rel = str(p.relative_to(folder))
        if p.is_symlink():
            out[rel] = f"-> {os.readlink(p)}"
        elif p.is_file():
            out[rel] = p.read_text()
    return out


def _manifest(*entries: str) -> str:
    return json.dumps({"entries": sorted(entries)}, indent=1) + "\n"


def _refusal(path: Path, why: str) -> str:
    return f"{path}: {why}{NOT_LFBENCH}"


# --------------------------------------------------------------------------- outputs.py: names


def test_journal_and_manifest_names_of_a_set():
    """Mutants of journal_name / manifest_name / _check_set_name / _SET_NAME: the main set's names, a named set's,
    the longest name (32 characters) and the names refused in one ValueError line."""
    assert (outputs.journal_name(), outputs.manifest_name()) == (".lfbench-commit.json", ".lfbench-outputs.json")
    assert outputs.journal_name("cell_2") == ".lfbench-commit.cell_2.json"
    assert outputs.manifest_name("cell_2") == ".lfbench-outputs.cell_2.json"
    longest = "a" + "0" * 31
    assert outputs.manifest_name(longest) == f".lfbench-outputs.{longest}.json"
    for bad in ("", "Cell", "2a", "a-b", "ab!", longest + "0"):
        with pytest.raises(ValueError) as info:
            outputs.journal_name(bad)
        assert str(info.value) == f"not a set name: {bad!r}"
        with pytest.raises(ValueError):
            outputs.manifest_name(bad)


@pytest.mark.parametrize(("name", "ok"), [
    ("a", True), ("x" * 255, True), ("é" * 127, True), ("é" * 128, False), ("x" * 256, False), ("", False),
    (".hidden", False), ("a/b", False), ("a\\b", False), ("a\0b", False), (5, False), (None, False),
    ("a.b", True), ("\udcff", True), ("X", True), ("aXb", True)])
def test_an_entry_name_is_plain_top_level_and_at_most_255_bytes(name, ok):
    """Mutants of _is_entry_name: the type, the byte length (UTF-8, surrogates escaped), the hidden and separator
    checks."""
    assert outputs._is_entry_name(name) is ok


def test_names_are_a_list_of_distinct_entry_names():
    """Mutants of _names: a list (not a tuple), every name plain, no duplicate."""
    assert outputs._names([]) is True
    assert outputs._names(["a", "b"]) is True
    assert outputs._names(("a", "b")) is False
    assert outputs._names(["a", "a"]) is False
    assert outputs._names(["a", ".b"]) is False
    assert outputs._names("ab") is False


@pytest.mark.parametrize(("name", "ok"), [("x", True), ("", False), (".", False), ("..", False), ("a/b", False),
                                          ("a\\b", False), ("a\0", False), ("x" * 255, True), ("x" * 256, False),
                                          ("...", True), ("X", True)])
def test_a_staging_folder_name_is_plain(name, ok):
    """Mutants of _is_plain."""
    assert outputs._is_plain(name) is ok


# --------------------------------------------------------------------------- outputs.py: a whole commit


def test_a_set_is_staged_and_committed_as_one(tmp_path):
    """Mutants of OutputSet.__init__ / final / commit / commit_written and of _roll_forward: the staging folder's
    name and place, the manifest (entries and kept ones, sorted), the previous set's entries dropped except those
    kept, nothing left behind (no staging folder, no journal)."""
    out = tmp_path / "out"
    first = outputs.OutputSet(out)
    assert first.created is True and first.committed is False and first.name is None and first.out == out
    assert first.stage.parent == out and first.stage.is_dir()
    assert first.stage.name.startswith(f"{STAGE}{os.getpid()}.")
    for name in ("a.txt", "b.txt", "c.txt"):
        (first.stage / name).write_text(name)
    (first.stage / "maps").mkdir()
    (first.stage / "maps" / "m.txt").write_text("m")
    assert first.final(first.stage / "maps" / "m.txt") == out / "maps" / "m.txt"
    assert first.final(str(first.stage / "a.txt")) == out / "a.txt"
    landed = first.commit_written([first.stage / "maps" / "m.txt", first.stage / "c.txt", str(first.stage / "b.txt"),
                                   first.stage / "a.txt"])
    assert landed == [out / "maps" / "m.txt", out / "c.txt", out / "b.txt", out / "a.txt"]
    assert first.committed is True
    assert _files(out) == {".lfbench-outputs.json": _manifest("a.txt", "b.txt", "c.txt", "maps"),
                           "a.txt": "a.txt", "b.txt": "b.txt", "c.txt": "c.txt", "maps/m.txt": "m"}

    second = outputs.OutputSet(out)
    assert second.created is False
    (second.stage / "b.txt").write_text("new b")
    (second.stage / "d.txt").write_text("d")
    second.commit(["d.txt", "b.txt", "d.txt"], keep=["c.txt", "b.txt", "gone.txt", "c.txt"])
    assert _files(out) == {".lfbench-outputs.json": _manifest("b.txt", "c.txt", "d.txt"),
                           "b.txt": "new b", "c.txt": "c.txt", "d.txt": "d"}


def test_a_kept_name_stays_only_when_it_was_in_the_set_and_is_there(tmp_path):
    """Mutants of commit's `kept`: a name of the previous set that is gone, or a file not in the set, is not kept
    (`and` for `or`, `in` for `not in`)."""
    out = tmp_path / "out"
    out.mkdir()
    (out / ".lfbench-outputs.json").write_text(_manifest("a", "b"))
    (out / "a").write_text("a")
    (out / "stray").write_text("s")
    outputs_set = outputs.OutputSet(out)
    (outputs_set.stage / "c").write_text("c")
    outputs_set.commit(["c"], keep=["a", "b", "stray"])
    assert _files(out) == {".lfbench-outputs.json": _manifest("a", "c"), "a": "a", "c": "c", "stray": "s"}


def test_the_journal_is_the_commit_point(tmp_path, monkeypatch):
    """Mutants of commit's journal (its keys, its text, which set's file) and of the staged manifest: what a kill
    right after the commit point leaves, word for word."""
    out = tmp_path / "out"
    out.mkdir()
    (out / ".lfbench-outputs.cell.json").write_text(_manifest("old", "keep", "b"))
    for name in ("old", "keep", "b"):
        (out / name).write_text(f"old {name}")
    seen = []
    monkeypatch.setattr(outputs, "_roll_forward", lambda where, journal: seen.append((where, journal)))
    outputs_set = outputs.OutputSet(out, "cell")
    (outputs_set.stage / "b").write_text("b")
    (outputs_set.stage / "a").write_text("a")
    outputs_set.commit(["b", "a"], keep=["keep"])
    stage = outputs_set.stage.name
    assert (out / ".lfbench-commit.cell.json").read_text() == (
        json.dumps({"stage": stage, "entries": ["a", "b"], "remove": ["old"]}, indent=1) + "\n")
    assert not (out / ".lfbench-commit.json").exists()
    assert (outputs_set.stage / ".lfbench-outputs.cell.json").read_text() == _manifest("a", "b", "keep")
    assert (outputs_set.stage / ".trash").is_dir()
    assert seen == [(out, outputs._Journal(stage, ("a", "b"), ("old",), ".lfbench-commit.cell.json",
                                           ".lfbench-outputs.cell.json"))]
    assert outputs_set.committed is True
    outputs_set.abort()  # past the commit point: everything stays for the next run
    assert outputs_set.stage.is_dir() and (out / ".lfbench-commit.cell.json").is_file()
    with pytest.raises(DataError) as info:
        outputs.check_complete(out)
    assert str(info.value) == (f"{out}: an interrupted run left this folder half updated (.lfbench-commit.cell.json);"
                               " run the command again to finish it")
    monkeypatch.undo()
    outputs.recover(out)  # rolled forward
    assert _files(out) == {".lfbench-outputs.cell.json": _manifest("a", "b", "keep"), "a": "a", "b": "b",
                           "keep": "old keep"}
    outputs.check_complete(out)


def test_commit_refuses_bad_or_missing_entries(tmp_path):
    """Mutants of commit's check: the names refused (hidden, a path) and the ones not staged, in one line."""
    outputs_set = outputs.OutputSet(tmp_path / "out")
    (outputs_set.stage / "a").write_text("a")
    with pytest.raises(RuntimeError) as info:
        outputs_set.commit(["a", ".h", "missing", "x/y"])
    assert str(info.value) == "staged outputs not valid: ['.h', 'x/y', '.h', 'missing', 'x/y']"
    with pytest.raises(RuntimeError) as info:
        outputs_set.commit(["missing"])
    assert str(info.value) == "staged outputs not valid: ['missing']"
    with pytest.raises(RuntimeError) as info:
        outputs_set.commit([".h"])
    assert str(info.value) == "staged outputs not valid: ['.h', '.h']"
    assert not (tmp_path / "out" / ".lfbench-commit.json").exists()
    outputs_set.commit(["a"])
    assert _files(tmp_path / "out") == {".lfbench-outputs.json": _manifest("a"), "a": "a"}


def test_a_staged_link_is_refused_before_the_commit_point(tmp_path):
    """Mutants of _check_staged: a staged entry that is a link, or holds one (in a folder or a sub-folder), and a
    trash that is no folder, each in its line naming the journal to be."""
    out = tmp_path / "out"
    outputs_set = outputs.OutputSet(out)
    stage = outputs_set.stage
    (stage / "link").symlink_to(tmp_path)
    (stage / "maps" / "deep").mkdir(parents=True)
    (stage / "maps" / "deep" / "inner").symlink_to(tmp_path)
    (stage / "dirs" / "sub").mkdir(parents=True)
    (stage / "dirs" / "lnk").symlink_to(tmp_path / "out")
    journal = out / ".lfbench-commit.json"
    for entries, why in (
            (["link"], f"commit journal: staged entry {stage / 'link'} is a symbolic link"),
            (["maps"], f"commit journal: staged entry {stage / 'maps'} holds a symbolic link "
                       f"({stage / 'maps' / 'deep' / 'inner'})"),
            (["dirs"], f"commit journal: staged entry {stage / 'dirs'} holds a symbolic link "
                       f"({stage / 'dirs' / 'lnk'})")):
        with pytest.raises(DataError) as info:
            outputs_set.commit(entries)
        assert str(info.value) == _refusal(journal, why)
    (stage / ".trash").write_text("x")
    (stage / "ok").write_text("ok")
    with pytest.raises(DataError) as info:
        outputs._check_staged(stage, ["ok"], journal)
    assert str(info.value) == _refusal(journal, f"commit journal: {stage / '.trash'} is not a folder")
    (stage / ".trash").unlink()
    (stage / ".trash").symlink_to(tmp_path)
    with pytest.raises(DataError):
        outputs._check_staged(stage, [], journal)
    assert not journal.exists()


def test_abort_removes_the_staging_folder_and_a_folder_it_made(tmp_path):
    """Mutants of abort: the staging folder removed; OUT removed only when this run made it and it is empty."""
    made = outputs.OutputSet(tmp_path / "made")
    (made.stage / "x").write_text("x")
    made.abort()
    assert not (tmp_path / "made").exists()
    (tmp_path / "there").mkdir()
    there = outputs.OutputSet(tmp_path / "there")
    there.abort()
    assert (tmp_path / "there").is_dir() and list((tmp_path / "there").iterdir()) == []
    other = outputs.OutputSet(tmp_path / "other")
    (tmp_path / "other" / "theirs").write_text("t")
    other.abort()
    assert _files(tmp_path / "other") == {"theirs": "t"}


def test_an_output_set_checks_its_folder_before_the_work(tmp_path, monkeypatch):
    """Mutants of OutputSet.__init__: the folder prepared and checked (a FIFO in it refused), dead runs' staging
    folders cleaned, a manifest that is not lfbench's refused, an uncreatable staging folder in one line (with its
    words, or the error itself when it has none)."""
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / "fifo")
    with pytest.raises(DataError) as info:
        outputs.OutputSet(out)
    assert str(info.value).startswith(f"{out / 'fifo'}: is a FIFO")
    (out / "fifo").unlink()
    (out / f"{STAGE}999999999.x").mkdir()
    (out / ".lfbench-outputs.cell.json").write_text("[]")
    outputs.OutputSet(out, "other").abort()
    assert sorted(p.name for p in out.iterdir()) == [".lfbench-outputs.cell.json"]
    with pytest.raises(DataError) as info:
        outputs.OutputSet(out, "cell")
    assert str(info.value) == _refusal(out / ".lfbench-outputs.cell.json",
                                       "output manifest must list plain top-level names (no path, not hidden)")
    assert sorted(p.name for p in out.iterdir()) == [".lfbench-outputs.cell.json"]

    def no_room(**kw):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(outputs.tempfile, "mkdtemp", no_room)
    with pytest.raises(DataError) as info:
        outputs.OutputSet(out)
    assert str(info.value) == f"{out}: cannot write into the output folder: No space left on device"
    monkeypatch.setattr(outputs.tempfile, "mkdtemp", lambda **kw: (_ for _ in ()).throw(OSError("wordless")))
    with pytest.raises(DataError) as info:
        outputs.OutputSet(out)
    assert str(info.value) == f"{out}: cannot write into the output folder: wordless"


# --------------------------------------------------------------------------- outputs.py: staged_outputs


def test_staged_outputs_names_a_write_error_where_it_lands(tmp_path):
    """Mutants of staged_outputs: an OSError while staging is one LFBenchError naming the file where it would land
    (or OUT without a file name, or the file itself outside the staging folder) and saying nothing was written;
    the staging folder is removed."""
    out = tmp_path / "out"
    with pytest.raises(LFBenchError) as info, outputs.staged_outputs(out) as staged:
        raise OSError(errno.ENOSPC, "No space left on device", str(staged.stage / "maps" / "a.pfm"))
    assert type(info.value) is LFBenchError
    assert str(info.value) == (f"{out / 'maps' / 'a.pfm'}: cannot write: No space left on device (nothing written "
                               f"to {out})")
    assert not out.exists()
    out.mkdir()
    with pytest.raises(LFBenchError) as info, outputs.staged_outputs(out):
        raise OSError("no words")
    assert str(info.value) == f"{out}: cannot write: no words (nothing written to {out})"
    with pytest.raises(LFBenchError) as info, outputs.staged_outputs(out):
        raise OSError(errno.EACCES, "Permission denied", str(tmp_path / "elsewhere"))
    assert str(info.value) == f"{tmp_path / 'elsewhere'}: cannot write: Permission denied (nothing written to {out})"
    assert list(out.iterdir()) == []


def test_staged_outputs_after_the_commit_point_says_the_next_run_finishes(tmp_path, monkeypatch):
    """Mutants of staged_outputs' committed branch: the line, and the staging folder and journal left."""
    out = tmp_path / "out"

    def cut(where, journal):
        raise OSError(errno.EIO, "Input/output error", str(where / journal.stage / "a"))

    monkeypatch.setattr(outputs, "_roll_forward", cut)
    with pytest.raises(LFBenchError) as info, outputs.staged_outputs(out) as staged:
        (staged.stage / "a").write_text("a")
        staged.commit(["a"])
    assert str(info.value) == (f"{out / 'a'}: cannot finish the commit: Input/output error (the next run into {out} "
                               "finishes it)")
    assert (out / ".lfbench-commit.json").is_file() and staged.stage.is_dir()


def test_staged_outputs_aborts_on_any_other_exception(tmp_path):
    """Mutants of staged_outputs' `except BaseException`: the error passes as it is, the staging folder goes."""
    out = tmp_path / "out"
    out.mkdir()
    with pytest.raises(KeyError), outputs.staged_outputs(out, "cell") as staged:
        assert staged.name == "cell"
        raise KeyError("x")
    assert list(out.iterdir()) == []
    with outputs.staged_outputs(out) as staged:
        (staged.stage / "a").write_text("a")
        staged.commit(["a"])
    assert _files(out) == {".lfbench-outputs.json": _manifest("a"), "a": "a"}


# --------------------------------------------------------------------------- outputs.py: recover


def test_recover_cleans_dead_runs_and_old_temporaries_only(tmp_path):
    """Mutants of recover: dead runs' staging folders and files, the temporaries of earlier versions (.tmp, .old)
    and of journals (.tmp) removed; a live run's staging folder and everything else kept."""
    out = tmp_path / "out"
    out.mkdir()
    removed = [f"{STAGE}999999999.a", f"{STAGE}x.b", ".data.1.tmp", ".figures.2.old", ".html.3.tmp", ".maps.4.old",
               ".lfbench-commit.json.5.tmp", ".lfbench-outputs.cell.json.6.tmp"]
    kept = [f"{STAGE}{os.getpid()}.c", ".data.7", "data.tmp", ".maps.8.new", ".lfbench-outputs.json.9.old",
            ".other.tmp", "x.old"]
    for name in removed + kept:
        if name.startswith(STAGE):
            (out / name).mkdir()
            (out / name / "f").write_text("f")
        else:
            (out / name).write_text(name)
    (out / ".maps.10.tmp").mkdir()
    (out / ".maps.10.tmp" / "inner").write_text("i")
    (out / ".data.11.tmp").symlink_to(tmp_path / "keep_me")
    (tmp_path / "keep_me").write_text("k")
    outputs.recover(out)
    assert sorted(p.name for p in out.iterdir()) == sorted(kept)
    assert (tmp_path / "keep_me").read_text() == "k"
    outputs.recover(tmp_path / "absent")
    (tmp_path / "file").write_text("f")
    outputs.recover(tmp_path / "file")


def test_recover_rolls_every_journal_forward_after_checking_all(tmp_path):
    """Mutants of recover's journals (each set's), _roll_forward (old entries to the trash, new ones in, the
    manifest, the journal and staging folder gone) and _read_journal's set name: two sets finished, then a bad
    journal stops everything before anything moves."""
    out = tmp_path / "out"
    out.mkdir()
    for journal, stage, name, manifest in ((".lfbench-commit.json", f"{STAGE}1.a", "a", ".lfbench-outputs.json"),
                                           (".lfbench-commit.cell.json", f"{STAGE}1.b", "b",
                                            ".lfbench-outputs.cell.json")):
        (out / stage / ".trash").mkdir(parents=True)
        (out / stage / name).write_text(f"new {name}")
        (out / stage / manifest).write_text(_manifest(name))
        (out / journal).write_text(json.dumps({"stage": stage, "entries": [name], "remove": [f"old_{name}"]}))
        (out / name).write_text(f"old {name}")
        (out / f"old_{name}").write_text("x")
    outputs.recover(out)
    assert _files(out) == {".lfbench-outputs.cell.json": _manifest("b"), ".lfbench-outputs.json": _manifest("a"),
                           "a": "new a", "b": "new b"}

    (out / f"{STAGE}1.c").mkdir()
    (out / f"{STAGE}1.c" / "c").write_text("c")
    (out / ".lfbench-commit.json").write_text(json.dumps({"stage": f"{STAGE}1.c", "entries": ["c"], "remove": []}))
    (out / ".lfbench-commit.zz.json").write_text("{}")
    with pytest.raises(DataError) as info:
        outputs.recover(out)
    assert str(info.value) == _refusal(out / ".lfbench-commit.zz.json",
                                       "commit journal must hold exactly stage, entries and remove")
    assert not (out / "c").exists() and (out / f"{STAGE}1.c" / "c").is_file()


def test_a_journal_of_an_earlier_version_writes_the_manifest(tmp_path):
    """Mutants of _roll_forward's branches: no trash made before (made now), no staged manifest (written unless the
    one there lists the entries already), an entry moved before the kill (not moved again), a name in the trash
    already (moved beside it)."""
    out = tmp_path / "out"
    (out / f"{STAGE}1.s" / ".trash" / "a").mkdir(parents=True)
    (out / f"{STAGE}1.s" / "a").write_text("new a")
    (out / "a").write_text("old a")
    (out / "b").write_text("b moved before the kill")
    journal = outputs._Journal(f"{STAGE}1.s", ("a", "b"), (), ".lfbench-commit.json", ".lfbench-outputs.json")
    (out / ".lfbench-commit.json").write_text("{}")
    outputs._roll_forward(out, journal)
    assert _files(out) == {".lfbench-outputs.json": _manifest("a", "b"), "a": "new a",
                           "b": "b moved before the kill"}
    (out / f"{STAGE}1.t").mkdir()
    (out / ".lfbench-outputs.json").write_text(json.dumps({"entries": ["b", "a"]}))
    outputs._roll_forward(out, dataclasses.replace(journal, stage=f"{STAGE}1.t"))
    assert (out / ".lfbench-outputs.json").read_text() == json.dumps({"entries": ["b", "a"]})
    assert sorted(p.name for p in out.iterdir()) == [".lfbench-outputs.json", "a", "b"]


def test_move_aside_never_overwrites_the_trash(tmp_path):
    """Mutants of _move_aside: an absent path is nothing to do; a name already in the trash goes into a new
    folder beside it; a link is moved, not its target."""
    trash = tmp_path / "trash"
    trash.mkdir()
    outputs._move_aside(tmp_path / "absent", trash)
    (tmp_path / "f").write_text("first")
    outputs._move_aside(tmp_path / "f", trash)
    (tmp_path / "f").write_text("second")
    outputs._move_aside(tmp_path / "f", trash)
    (tmp_path / "target").write_text("t")
    (tmp_path / "link").symlink_to(tmp_path / "target")
    outputs._move_aside(tmp_path / "link", trash)
    files = _files(trash)
    assert files.pop("f") == "first" and files.pop("link") == f"-> {tmp_path / 'target'}"
    [(where, text)] = files.items()
    assert text == "second" and Path(where).name == "f" and Path(where).parent.parent == Path(".")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["target", "trash"]


def test_remove_deletes_a_link_never_its_target(tmp_path):
    """Mutants of _remove: a folder with its content, a file, a link to a folder (the link only), an absent path."""
    (tmp_path / "d" / "e").mkdir(parents=True)
    (tmp_path / "f").write_text("f")
    (tmp_path / "keep").mkdir()
    (tmp_path / "keep" / "k").write_text("k")
    (tmp_path / "l").symlink_to(tmp_path / "keep")
    for name in ("d", "f", "l", "absent"):
        outputs._remove(tmp_path / name)
    assert _files(tmp_path) == {"keep/k": "k"}


def test_alive_reads_the_pid_of_a_staging_folder(monkeypatch):
    """Mutants of _alive: the pid after the prefix, this process, a dead one, one not ours (PermissionError), a
    pid the kernel cannot take."""
    assert outputs._alive(f"{STAGE}{os.getpid()}.x") is True
    assert outputs._alive(f"{STAGE}{os.getpid()}") is True
    assert outputs._alive(f"{STAGE}{os.getpid()}.a.b") is True
    assert outputs._alive(f"{STAGE}x.{os.getpid()}") is False
    assert outputs._alive(f"{STAGE}99999999999999999999999.x") is False
    calls = []

    def kill(pid, sig):
        calls.append((pid, sig))
        raise {1: ProcessLookupError, 2: PermissionError, 3: OverflowError, 4: ValueError}[pid]()

    monkeypatch.setattr(outputs.os, "kill", kill)
    assert [outputs._alive(f"{STAGE}{pid}.x") for pid in (1, 2, 3, 4)] == [False, True, False, False]
    assert calls == [(1, 0), (2, 0), (3, 0), (4, 0)]
    monkeypatch.setattr(outputs.os, "kill", lambda pid, sig: None)
    assert outputs._alive(f"{STAGE}5.x") is True


# --------------------------------------------------------------------------- outputs.py: what is read back


def test_check_within_follows_links(tmp_path):
    """Mutants of check_within: inside (through a link too), outside (the default and a given `what`), a dangling
    link or a loop."""
    folder = tmp_path / "res"
    (folder / "sub").mkdir(parents=True)
    (folder / "sub" / "f").write_text("f")
    (folder / "in").symlink_to(folder / "sub" / "f")
    (folder / "out").symlink_to(tmp_path)
    (folder / "dangling").symlink_to(folder / "nowhere")
    (folder / "loop").symlink_to(folder / "loop")
    outputs.check_within(folder / "in", folder)
    outputs.check_within(str(folder / "sub" / "f"), str(folder))
    with pytest.raises(DataError) as info:
        outputs.check_within(folder / "out", folder)
    assert str(info.value) == (f"{folder / 'out'}: symbolic link leading out of the folder it was read from "
                               "(not allowed)")
    with pytest.raises(DataError) as info:
        outputs.check_within(folder / "out", folder, "the results folder")
    assert str(info.value) == f"{folder / 'out'}: symbolic link leading out of the results folder (not allowed)"
    for name in ("dangling", "loop"):
        with pytest.raises(DataError) as info:
            outputs.check_within(folder / name, folder)
        assert str(info.value) == f"{folder / name}: broken symbolic link or unreadable path"
    with pytest.raises(DataError) as info:
        outputs.check_within(folder / "sub" / "f", tmp_path / "absent")
    assert str(info.value) == f"{folder / 'sub' / 'f'}: broken symbolic link or unreadable path"


def test_check_complete_of_a_folder_without_journal(tmp_path):
    """Mutants of check_complete: no journal (only look-alikes), no folder: no error; the first pending journal
    by name."""
    (tmp_path / ".lfbench-commit.json.tmp").write_text("x")
    (tmp_path / ".lfbench-commit.Bad.json").write_text("x")
    outputs.check_complete(tmp_path)
    outputs.check_complete(tmp_path / "absent")
    (tmp_path / ".lfbench-commit.zz.json").write_text("x")
    (tmp_path / ".lfbench-commit.json").write_text("x")
    with pytest.raises(DataError) as info:
        outputs.check_complete(tmp_path)
    assert str(info.value) == (f"{tmp_path}: an interrupted run left this folder half updated (.lfbench-commit.json);"
                               " run the command again to finish it")


def test_read_manifest_of_each_set(tmp_path):
    """Mutants of read_manifest and _manifest_entries: absent (also a str folder), each set's entries, a dangling
    link is refused (not taken as absent), exactly one key `entries`."""
    assert outputs.read_manifest(tmp_path) == []
    (tmp_path / ".lfbench-outputs.json").write_text(json.dumps({"entries": ["b", "a"]}))
    (tmp_path / ".lfbench-outputs.cell.json").write_text(json.dumps({"entries": ["c"]}))
    assert outputs.read_manifest(tmp_path) == ["b", "a"]
    assert outputs.read_manifest(str(tmp_path), "cell") == ["c"]
    assert outputs.read_manifest(tmp_path, "other") == []
    (tmp_path / ".lfbench-outputs.other.json").symlink_to(tmp_path / "nowhere")
    with pytest.raises(DataError) as info:
        outputs.read_manifest(tmp_path, "other")
    assert str(info.value) == _refusal(tmp_path / ".lfbench-outputs.other.json",
                                       "output manifest is not a regular file")
    for text in (json.dumps({"entries": ["a"], "more": 1}), json.dumps(["a"]), json.dumps({"entries": [".a"]}),
                 json.dumps({"entries": "a"})):
        (tmp_path / ".lfbench-outputs.json").write_text(text)
        with pytest.raises(DataError) as info:
            outputs.read_manifest(tmp_path)
        assert str(info.value) == _refusal(tmp_path / ".lfbench-outputs.json",
                                           "output manifest must list plain top-level names (no path, not hidden)")


def test_a_book_is_a_regular_file_of_utf8_json_under_1_mib(tmp_path, monkeypatch):
    """Mutants of _read_book: not a regular file (a folder), over 1 MiB (exactly 1 MiB is read), not UTF-8, not
    JSON, an unreadable file with its words or without."""
    path = tmp_path / "book.json"
    path.mkdir()
    with pytest.raises(DataError) as info:
        outputs._read_book(path, "commit journal")
    assert str(info.value) == _refusal(path, "commit journal is not a regular file")
    path.rmdir()
    path.write_text("[1]" + " " * (1024**2 - 3))
    assert outputs._read_book(path, "x") == [1]
    path.write_text("[1]" + " " * (1024**2 - 2))
    with pytest.raises(DataError) as info:
        outputs._read_book(path, "output manifest")
    assert str(info.value) == _refusal(path, "output manifest is larger than 1024 KiB")
    for raw in (b'{"entries": ["\xff"]}', b"{", b'{"a": 1, "a": 2}'):
        path.write_bytes(raw)
        with pytest.raises(DataError) as info:
            outputs._read_book(path, "the book")
        assert str(info.value) == _refusal(path, "the book is not valid UTF-8 JSON")
    path.write_text('{"entries": ["é"]}')
    assert outputs._read_book(path, "x") == {"entries": ["é"]}

    def unreadable(self):
        raise OSError(errno.EACCES, "Permission denied")

    monkeypatch.setattr(Path, "read_bytes", unreadable)
    with pytest.raises(DataError) as info:
        outputs._read_book(path, "commit journal")
    assert str(info.value) == f"{path}: cannot read commit journal: Permission denied"
    monkeypatch.setattr(Path, "read_bytes", lambda self: (_ for _ in ()).throw(OSError("wordless")))
    with pytest.raises(DataError) as info:
        outputs._read_book(path, "commit journal")
    assert str(info.value) == f"{path}: cannot read commit journal: wordless"


def _journal(out: Path, data, name: str = ".lfbench-commit.json") -> str:
    (out / name).write_text(json.dumps(data))
    with pytest.raises(DataError) as info:
        outputs._read_journal(out, name)
    return str(info.value)


def test_a_journal_is_checked_name_by_name(tmp_path):
    """Mutants of _read_journal: every refusal word for word (keys, the staging folder's name, kind and
    presence, the entries and names to remove, both at once, the staged manifest disagreeing), and the journal
    read when right (its set's manifest)."""
    out = tmp_path
    path = out / ".lfbench-commit.json"
    stage = f"{STAGE}1.s"
    good = {"stage": stage, "entries": ["a"], "remove": ["b"]}

    def refused(why: str) -> str:
        return _refusal(path, why)

    assert _journal(out, {**good, "x": 1}) == refused("commit journal must hold exactly stage, entries and remove")
    assert _journal(out, ["a"]) == refused("commit journal must hold exactly stage, entries and remove")
    stage_why = f"commit journal: stage must be a folder {STAGE}* in the output folder"
    for bad in (1, "stage.x", f"{STAGE}1/x", f"{STAGE}1\\x", STAGE + "x" * 241):
        assert _journal(out, {**good, "stage": bad}) == refused(stage_why), bad
    assert _journal(out, {**good, "entries": [".a"]}) == refused(
        "commit journal: entries must list plain top-level names (no path, not hidden)")
    assert _journal(out, {**good, "remove": ["a/b"]}) == refused(
        "commit journal: remove must list plain top-level names (no path, not hidden)")
    assert _journal(out, {**good, "remove": ["a"]}) == refused(
        "commit journal: a name is both an entry and to be removed")
    assert _journal(out, good) == (f"{path}: commit journal: its staging folder {stage} is gone, so the interrupted "
                                   "commit cannot be finished; nothing was changed (remove the journal to keep the "
                                   "folder as it is)")
    (out / stage).write_text("x")
    assert _journal(out, good) == refused(f"commit journal: the staging folder {stage} is not a folder (or a "
                                          "symbolic link)")
    (out / stage).unlink()
    (out / stage).symlink_to(tmp_path)
    assert _journal(out, good) == refused(f"commit journal: the staging folder {stage} is not a folder (or a "
                                          "symbolic link)")
    (out / stage).unlink()
    (out / stage).mkdir()
    (out / stage / "a").symlink_to(tmp_path)
    assert _journal(out, good) == refused(f"commit journal: staged entry {out / stage / 'a'} is a symbolic link")
    (out / stage / "a").unlink()
    (out / stage / "a").write_text("a")
    assert outputs._read_journal(out, ".lfbench-commit.json") == outputs._Journal(
        stage, ("a",), ("b",), ".lfbench-commit.json", ".lfbench-outputs.json")
    for listed in (["c"], ["a", "b"]):
        (out / stage / ".lfbench-outputs.json").write_text(json.dumps({"entries": listed}))
        assert _journal(out, good) == refused("commit journal and its staged manifest disagree"), listed
    (out / stage / ".lfbench-outputs.json").write_text(json.dumps({"entries": ["a", "c"]}))
    assert outputs._read_journal(out, ".lfbench-commit.json").entries == ("a",)
    (out / stage / ".lfbench-outputs.json").write_text(json.dumps({"entries": ["a"], "x": 1}))
    assert _journal(out, good) == _refusal(out / stage / ".lfbench-outputs.json", "staged output manifest must list "
                                           "plain top-level names (no path, not hidden)")
    (out / stage / ".lfbench-outputs.cell.json").write_text(json.dumps({"entries": ["z"]}))
    (out / ".lfbench-commit.cell.json").write_text(json.dumps(good))
    with pytest.raises(DataError):
        outputs._read_journal(out, ".lfbench-commit.cell.json")
    (out / stage / ".lfbench-outputs.cell.json").write_text(json.dumps({"entries": ["a"]}))
    assert outputs._read_journal(out, ".lfbench-commit.cell.json") == outputs._Journal(
        stage, ("a",), ("b",), ".lfbench-commit.cell.json", ".lfbench-outputs.cell.json")


def test_manifest_lists_compares_sorted_and_is_false_for_a_bad_manifest(tmp_path):
    """Mutants of _manifest_lists and _manifest_text."""
    path = tmp_path / "m.json"
    assert outputs._manifest_text(["b", "a"]) == '{\n "entries": [\n  "a",\n  "b"\n ]\n}\n'
    path.write_text(outputs._manifest_text(["b", "a"]))
    assert outputs._manifest_lists(path, ("b", "a")) is True
    assert outputs._manifest_lists(path, ["a"]) is False
    path.write_text("{")
    assert outputs._manifest_lists(path, ["a"]) is False
    assert outputs._manifest_lists(tmp_path / "absent", []) is False


# --------------------------------------------------------------------------- executor.py


def test_labelled_pairs_items_with_their_labels_lazily():
    """Mutants of labelled: a function of the item, a list (its count checked), one item pulled at a time."""
    pulled = []

    def items():
        for i in range(3):
            pulled.append(i)
            yield i

    pairs = executor.labelled(items(), lambda i: f"item {i}")
    assert pulled == []
    assert next(pairs) == ("item 0", 0) and pulled == [0]
    assert list(pairs) == [("item 1", 1), ("item 2", 2)]
    assert list(executor.labelled(["a", "b"], ["A", "B"])) == [("A", "a"), ("B", "b")]
    with pytest.raises(ValueError):
        list(executor.labelled(["a", "b"], ["A"]))
    with pytest.raises(ValueError):
        list(executor.labelled(["a"], ["A", "B"]))


def test_visible_gpus_follow_cuda_visible_devices(monkeypatch):
    """Mutants of visible_gpus: none without CUDA, the listed entries (stripped, empty ones dropped) up to the
    count, else 0 .. count - 1."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "3")
    assert executor.visible_gpus() == []
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", " 3, GPU-ab ,,7")
    assert executor.visible_gpus() == ["3", "GPU-ab"]
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "5")
    assert executor.visible_gpus() == ["5"]
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", " , ")
    assert executor.visible_gpus() == ["0", "1"]
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES")
    assert executor.visible_gpus() == ["0", "1"]


def test_worker_gpus_round_robin():
    """Mutants of worker_gpus."""
    assert executor.worker_gpus(3, []) == [None, None, None]
    assert executor.worker_gpus(5, ["a", "b"]) == ["a", "b", "a", "b", "a"]
    assert executor.worker_gpus(1, ["a", "b"]) == ["a"]
    assert executor.worker_gpus(0, ["a"]) == []


def test_a_worker_stopped_by_the_pool_removes_its_mark_then_stops(tmp_path, monkeypatch):
    """Mutants of _stopped_by_pool: the mark of this pid removed (another's kept), SIGTERM's default restored, then
    SIGTERM sent to itself; no marks folder: no error."""
    calls = []
    monkeypatch.setattr(executor.signal, "signal", lambda *a: calls.append(("signal", *a)))
    monkeypatch.setattr(executor.os, "kill", lambda *a: calls.append(("kill", *a)))
    (tmp_path / str(os.getpid())).write_text("mine")
    (tmp_path / "1").write_text("other")
    monkeypatch.setattr(executor, "_marks", tmp_path)
    executor._stopped_by_pool(15, None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["1"]
    executor._stopped_by_pool(15, None)  # the mark already gone
    monkeypatch.setattr(executor, "_marks", None)
    executor._stopped_by_pool(15, None)
    step = [("signal", signal.SIGTERM, signal.SIG_DFL), ("kill", os.getpid(), signal.SIGTERM)]
    assert calls == step * 3


class _Executor(executor.Executor):
    def map(self, *args, **kwargs) -> None:
        raise AssertionError


class _Jobs(_Executor):
    submits_jobs = True


def test_executor_defaults():
    """Mutants of Executor.__init__ / check / runs_here / cpus_per_item and of the executors' help: an executor
    that submits jobs gives each item --cpus-per-job, one that does not, none of its own."""
    options = executor.ClusterOptions("pool", cpus_per_job=6)
    log = [].append
    base = _Executor(options, jobs=3, folder=Path("f"), log=log)
    assert (base.options, base.jobs, base.folder, base.log) == (options, 3, Path("f"), log)
    default = _Executor(options)
    assert (default.jobs, default.folder, default.log) == (1, None, executor._log.info)
    assert base.check() is None and base.runs_here(1) is False and base.runs_here(None) is False
    assert base.cpus_per_item == 0 and _Jobs(options).cpus_per_item == 6
    assert _Executor.help == "" and _Executor.submits_jobs is False
    assert executor.InProcess.help == "one cell after the other in this process"
    assert executor.ProcessPool.help == ("--jobs N worker processes on this machine, each with its own GPU "
                                         "(the default)")


def test_in_process_runs_one_item_after_the_other():
    """Mutants of InProcess: check (one job only, its line), runs_here, map (on_start then fn then on_done, in
    order; no on_start given: none called)."""
    inline = executor.InProcess(executor.ClusterOptions("inline"), jobs=1)
    inline.check()
    assert inline.runs_here(None) is True and inline.runs_here(5) is True
    events = []
    inline.map(lambda i: i * 10, [1, 2], labels=["one", "two"], threads=None, on_done=lambda r: events.append(r),
               on_start=lambda label: events.append(label))
    assert events == ["one", 10, "two", 20]
    inline.map(lambda i: i + 1, iter([5]), labels=str, threads=2, on_done=events.append)
    assert events[4:] == [6]
    with pytest.raises(SpecError) as info:
        executor.InProcess(executor.ClusterOptions("local"), jobs=2).check()
    assert str(info.value) == "--executor local runs one cell at a time: --jobs 2 needs --executor pool"


def test_executor_for_and_the_registry():
    """Mutants of executor_for: None is the pool with one job; the options' executor with jobs, folder and log."""
    log = [].append
    chosen = executor.executor_for(None)
    assert type(chosen) is executor.ProcessPool and chosen.options == executor.ClusterOptions("pool")
    assert (chosen.jobs, chosen.folder, chosen.log) == (1, None, executor._log.info)
    chosen = executor.executor_for(executor.ClusterOptions("inline"), jobs=4, folder=Path("x"), log=log)
    assert type(chosen) is executor.InProcess and (chosen.jobs, chosen.folder, chosen.log) == (4, Path("x"), log)
    assert sorted(executor.EXECUTORS.names()) == ["inline", "local", "pool", "slurm"]


class _FakePool:
    """A pool that runs a submitted call in this process when _wait lets it finish (first submitted, first
    done); records what it was asked."""

    def __init__(self, events: list, broken_at: int | None = None) -> None:
        self.events, self.broken_at, self.pending, self.submitted = events, broken_at, [], 0

    def submit(self, fn, *args):
        from concurrent.futures import Future
        from concurrent.futures.process import BrokenProcessPool

        if self.broken_at == self.submitted:
            raise BrokenProcessPool("gone")
        self.submitted += 1
        self.events.append(("submit", args[1]))
        fut = Future()
        self.pending.append((fut, fn, args))
        return fut

    def shutdown(self, wait: bool, cancel_futures: bool) -> None:
        self.events.append(("shutdown", wait, cancel_futures))


def _fake_wait(pool: _FakePool):
    def wait(running, return_when):
        assert return_when == executor.FIRST_COMPLETED
        assert len(running) == len(pool.pending)
        fut, fn, args = pool.pending.pop(0)
        try:
            fut.set_result(fn(*args))
        except BaseException as exc:  # noqa: BLE001 (handed to the map as a worker would)
            fut.set_exception(exc)
        return {fut}, set(running) - {fut}

    return wait


@pytest.fixture
def pool_map(tmp_path, monkeypatch):
    """ProcessPool(jobs=2).map with _FakePool for the pool: returns (run, events, marks)."""
    events: list = []
    marks = tmp_path / "marks"

    def run(items, *, jobs=2, broken_at=None, **kw):
        pool = _FakePool(events, broken_at)
        marks.mkdir(exist_ok=True)

        def start(threads):
            events.append(("start", threads))
            return pool, marks

        monkeypatch.setattr(executor, "wait", _fake_wait(pool))
        chosen = executor.ProcessPool(executor.ClusterOptions("pool"), jobs=jobs)
        monkeypatch.setattr(chosen, "_start", start)
        kw.setdefault("labels", lambda i: f"L{i}")
        chosen.map(kw.pop("fn", lambda i: i * 10), items, threads=kw.pop("threads", 1),
                   on_done=lambda r: events.append(("done", r)), **kw)

    return run, events, marks


def test_the_pool_hands_out_jobs_items_at_a_time_pulled_as_needed(pool_map):
    """Mutants of ProcessPool.map: the first item before the pool starts, at most `jobs` handed out, the next
    pulled only after those (one ahead), each result as it comes, then the pool shut down and the marks
    folder removed."""
    run, events, marks = pool_map

    def items():
        for i in range(4):
            events.append(("pull", i))
            yield i

    run(items(), threads=3)
    assert events == [("pull", 0), ("start", 3), ("submit", "L0"), ("pull", 1), ("submit", "L1"), ("pull", 2),
                      ("done", 0), ("submit", "L2"), ("pull", 3), ("done", 10), ("submit", "L3"), ("done", 20),
                      ("done", 30), ("shutdown", True, True)]
    assert not marks.exists()


def test_the_pool_starts_the_longest_items_of_a_sequence_first(pool_map):
    """Mutants of map's cost order: a sequence by cost, longest first, ties in their order; an iterator as it
    comes; labels given as a list follow their items."""
    run, events, _ = pool_map
    run([1, 3, 2, 3], labels=["a", "b", "c", "d"], cost=lambda i: i, jobs=3)
    assert [e[1] for e in events if e[0] == "submit"] == ["b", "d", "c", "a"]
    events.clear()
    run(iter([1, 3, 2]), cost=lambda i: i)
    assert [e[1] for e in events if e[0] == "submit"] == ["L1", "L3", "L2"]
    events.clear()
    run([2, 1], cost=None)
    assert [e[1] for e in events if e[0] == "submit"] == ["L2", "L1"]


def test_the_pool_runs_here_for_one_job_or_one_item(pool_map):
    """Mutants of ProcessPool.runs_here and map's inline branch (on_start passed on, no pool started); no item
    at all starts no pool."""
    run, events, _ = pool_map
    pool = executor.ProcessPool(executor.ClusterOptions("pool"), jobs=2)
    assert pool.runs_here(1) is True and pool.runs_here(0) is True
    assert pool.runs_here(2) is False and pool.runs_here(None) is False
    assert executor.ProcessPool(executor.ClusterOptions("pool"), jobs=1).runs_here(None) is True
    run([7], on_start=lambda label: events.append(("start item", label)))
    run([8, 9], jobs=1)
    assert events == [("start item", "L7"), ("done", 70), ("done", 80), ("done", 90)]
    events.clear()
    run(iter([]))
    assert events == []


def test_a_failed_item_stops_the_pool(pool_map):
    """Mutants of map's `finally`: an item's error passes as it is, the pool is shut down and the marks folder
    removed; no later item starts."""
    run, events, marks = pool_map

    def fn(i):
        if i == 1:
            raise KeyError("bad item")
        return i

    with pytest.raises(KeyError):
        run([1, 2, 3], fn=fn, jobs=1 + 1)
    assert events == [("start", 1), ("submit", "L1"), ("submit", "L2"), ("shutdown", True, True)]
    assert not marks.exists()


@pytest.mark.parametrize("marked", [True, False])
def test_a_dead_worker_stops_the_pool_naming_its_item(pool_map, marked):
    """Mutants of map's BrokenProcessPool handling (a result, a submit): RunFailed with the `died` line naming the
    marks left, or the label that saw it."""
    from concurrent.futures.process import BrokenProcessPool

    run, events, marks = pool_map

    def fn(i):
        if i == 2:
            if marked:
                (marks / "4242").write_text("the item")
            raise BrokenProcessPool("gone")
        return i

    with pytest.raises(RunFailed) as info:
        run([1, 2, 3], fn=fn, died="died: {names}")
    assert str(info.value) == ("died: 'the item'" if marked else "died: 'L2'")
    assert events[-2:] == [("shutdown", True, True), ("shutdown", True, True)]
    events.clear()

    def mark(i):
        if marked:
            (marks / "4343").write_text("the item")
        return i * 10

    with pytest.raises(RunFailed) as info:
        run([1, 2, 3], fn=mark, broken_at=2)
    assert str(info.value) == executor.WORKER_DIED.format(names="'the item'" if marked else "'L3'")
    assert ("done", 10) in events and not marks.exists()


def test_the_pool_starts_spawned_workers_with_their_gpus(monkeypatch):
    """Mutants of ProcessPool._start: the spawn context, one GPU per worker through a queue (logged when there
    are GPUs), none without threads, the marks folder, the pool's size, initializer and its arguments."""
    made = {}

    class Queue(list):
        def put(self, item):
            self.append(item)

    class Context:
        def __init__(self, name):
            made["context"] = name

        def Queue(self):  # noqa: N802 (multiprocessing's name)
            made["queue"] = Queue()
            return made["queue"]

    class Pool:
        def __init__(self, **kw):
            made["pool"] = kw

    import multiprocessing

    monkeypatch.setattr(multiprocessing, "get_context", Context)
    monkeypatch.setattr(executor, "ProcessPoolExecutor", Pool)
    monkeypatch.setattr(executor, "visible_gpus", lambda: ["0", "1"])
    lines = []
    pool = executor.ProcessPool(executor.ClusterOptions("pool"), jobs=3, log=lines.append)
    started, marks = pool._start(4)
    try:
        assert type(started) is Pool and marks.is_dir() and marks.name.startswith("lfbench-pool-")
        assert marks.parent == Path(tempfile.gettempdir())
        assert made["context"] == "spawn" and made["queue"] == ["0", "1", "0"]
        assert made["pool"] == {"max_workers": 3, "mp_context": made["pool"]["mp_context"],
                                "initializer": executor.init_worker, "initargs": (4, made["queue"], str(marks))}
        assert type(made["pool"]["mp_context"]) is Context
        assert lines == ["3 worker(s) on GPU(s) 0, 1, 0 (round-robin)"]
    finally:
        marks.rmdir()
    monkeypatch.setattr(executor, "visible_gpus", lambda: [])
    made.clear()
    _, marks = pool._start(2)
    marks.rmdir()
    assert made["queue"] == [None, None, None] and lines == ["3 worker(s) on GPU(s) 0, 1, 0 (round-robin)"]
    made.clear()
    _, marks = pool._start(None)
    marks.rmdir()
    assert "queue" not in made and made["pool"]["initargs"] == (None, None, str(marks))


# --------------------------------------------------------------------------- training/checkpoint.py


def test_rng_state_is_weights_only_loadable_and_restores_every_generator(tmp_path, monkeypatch):
    """Mutants of rng_state / set_rng_state: each generator's state in its types (int64 tensors, plain ints and
    float), saved and read back weights-only, then restored: the same draws again (CUDA's: the next test)."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    random.seed(3)
    np.random.seed(4)
    torch.manual_seed(5)
    np.random.standard_normal()  # a cached gaussian in numpy's state
    random.gauss(0, 1)
    state = tck.rng_state()
    assert sorted(state) == ["numpy", "python", "torch"]
    version, internal, gauss = state["python"]
    assert version == 3 and internal.dtype == torch.int64 and internal.shape == (625,) and isinstance(gauss, float)
    kind, keys, pos, has_gauss, cached = state["numpy"]
    assert kind == "MT19937" and keys.dtype == torch.int64 and keys.shape == (624,)
    assert (type(pos), type(has_gauss), type(cached)) == (int, int, float) and has_gauss == 1
    tck.save(tmp_path / "rng.pt", {"rng": state})
    state = tck.load(tmp_path / "rng.pt")["rng"]
    draws = (random.random(), random.gauss(0, 1), np.random.random(), np.random.standard_normal(), torch.rand(2))
    random.seed(0)
    np.random.seed(0)
    torch.manual_seed(0)
    tck.set_rng_state(state)
    again = (random.random(), random.gauss(0, 1), np.random.random(), np.random.standard_normal(), torch.rand(2))
    assert draws[:4] == again[:4] and torch.equal(draws[4], again[4])


def test_rng_state_of_cuda_only_with_the_same_devices(monkeypatch):
    """Mutants of the CUDA branches: saved when CUDA is there, restored only when it is and the device count is
    the one saved."""
    restored = []
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "get_rng_state_all", lambda: ["g0", "g1"])
    monkeypatch.setattr(torch.cuda, "set_rng_state_all", restored.append)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    state = tck.rng_state()
    assert state["cuda"] == ["g0", "g1"]
    tck.set_rng_state(state)
    assert restored == [["g0", "g1"]]
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    tck.set_rng_state(state)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    tck.set_rng_state(state)
    assert "cuda" not in tck.rng_state()
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    tck.set_rng_state({k: v for k, v in state.items() if k != "cuda"})
    assert restored == [["g0", "g1"]]


def test_save_names_a_failed_write_and_keeps_the_old_file(tmp_path, monkeypatch):
    """Mutants of save: atomic (the old file stays), an OSError by its words, a RuntimeError (torch's failed zip
    write) or a wordless OSError squashed to one line of at most 120 characters."""
    path = tmp_path / "ck.pt"
    tck.save(path, {"format": "x", "a": torch.arange(3)})
    assert torch.equal(tck.load(path, "x")["a"], torch.arange(3))
    old = path.read_bytes()
    for exc, reason in ((OSError(errno.ENOSPC, "No space left on device"), "No space left on device"),
                        (RuntimeError("  zip\n  write failed " + "x" * 200), ("zip write failed " + "x" * 200)[:120]),
                        (OSError("no\twords"), "no words")):
        monkeypatch.setattr(tck.torch, "save", lambda payload, f, exc=exc: (_ for _ in ()).throw(exc))
        with pytest.raises(LFBenchError) as info:
            tck.save(str(path), {"a": 1})
        assert str(info.value) == f"{path}: cannot write checkpoint: {reason} (the previous one is kept)"
        assert type(info.value) is LFBenchError
    monkeypatch.setattr(tck.torch, "save", lambda payload, f: (_ for _ in ()).throw(ValueError("other")))
    with pytest.raises(ValueError):
        tck.save(path, {"a": 1})
    assert path.read_bytes() == old and sorted(p.name for p in tmp_path.iterdir()) == ["ck.pt"]


def test_state_and_parameter_digests():
    """Mutants of state_sha256 / parameters_sha256: names and bytes in order (a transposed tensor by its values,
    contiguous), the parameters without buffers."""
    state = {"w": torch.tensor([[1.0, 2.0], [3.0, 4.0]]).t(), "b": torch.tensor([7], dtype=torch.int32)}
    assert tck.state_sha256(state) == "43df1d4499c3521ac9ebc9bbed68ba68f64a32aac3b019f85fbf8aa602d14dfc"
    assert tck.state_sha256({"b": state["b"], "w": state["w"]}) != tck.state_sha256(state)
    assert tck.state_sha256({}) == "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855"
    module = torch.nn.BatchNorm1d(2)
    with torch.no_grad():
        module.weight.copy_(torch.tensor([1.0, 3.0]))
        module.bias.copy_(torch.tensor([2.0, 4.0]))
    params = {"weight": torch.tensor([1.0, 3.0]), "bias": torch.tensor([2.0, 4.0])}
    assert tck.parameters_sha256(module) == tck.state_sha256(params)
    assert tck.parameters_sha256(module) != tck.state_sha256(module.state_dict())


class _Net(torch.nn.Linear):
    def config(self) -> dict:
        return {"net": "linear"}


def test_export_weights_writes_the_inference_format(tmp_path):
    """Mutants of export_weights: every key, the state dict detached on the CPU, the config (given, the network's,
    none) and the training record (given or empty)."""
    torch.manual_seed(0)
    net = _Net(2, 1)
    tck.export_weights(tmp_path / "w.pt", net, {"steps": 5}, "epinet", {"given": 1})
    payload = tck.load(tmp_path / "w.pt", "lfbench.weights")
    assert sorted(payload) == ["config", "format", "method", "state_dict", "training", "version"]
    assert (payload["format"], payload["version"], payload["method"]) == ("lfbench.weights", 1, "epinet")
    assert payload["config"] == {"given": 1} and payload["training"] == {"steps": 5}
    assert list(payload["state_dict"]) == ["weight", "bias"]
    assert all(torch.equal(payload["state_dict"][k], v) for k, v in net.state_dict().items())
    assert not payload["state_dict"]["weight"].requires_grad
    tck.export_weights(str(tmp_path / "d.pt"), net)
    payload = tck.load(tmp_path / "d.pt")
    assert (payload["method"], payload["config"], payload["training"]) == ("", {"net": "linear"}, {})
    tck.export_weights(tmp_path / "p.pt", torch.nn.Linear(1, 1), training={})
    assert tck.load(tmp_path / "p.pt")["config"] == {}


# --------------------------------------------------------------------------- ablation/cell.py

CONFIG = {"data": {"roots": ["/scenes"]}, "stages": [{"name": "s1", "loss": "l1", "steps": 1},
                                                      {"name": "s2", "loss": "l1", "steps": 2}]}


def _task(tmp_path: Path, **kw) -> cell.CellTask:
    from lfbench.training.config import TrainConfig

    values = {"cell_id": "c1", "values": {"lr": 1}, "config": TrainConfig.from_dict(CONFIG).to_dict(),
              "fingerprint": "f", "eval_fingerprint": "e", "cell_dir": str(tmp_path / "c1"), "data_links": {},
              "stage1_dir": None, "scenes": (), "evaluation": Evaluation(), "threads": 3}
    return cell.CellTask(**{**values, **kw})


def test_a_cell_task_names_its_folder_and_network(tmp_path):
    """Mutants of CellTask.path / network: the folder, the configured network or the default one."""
    task = _task(tmp_path)
    assert task.path == tmp_path / "c1" and task.network == "subfocal"
    assert _task(tmp_path, config={"method": "epinet"}).network == "epinet"


def test_write_train_config_writes_once_and_refuses_another(tmp_path):
    """Mutants of write_train_config: the header (the command that reproduces the cell), the TOML, the same config
    (or one differing only in what a resume may change) written again, another one refused in its line."""
    task = _task(tmp_path)
    task.path.mkdir()
    path = cell.write_train_config(task)
    assert path == task.path / "train.toml"
    text = path.read_text()
    assert text.startswith(f"# Ablation cell c1: written by lfbench ablate.\n# Reproduce: lfbench train {path} --out "
                           f"{task.path}\nseed = 42\n\n[[stages]]\nname = \"s1\"\n")
    from lfbench.training.config import TrainConfig

    assert TrainConfig.from_toml(path).to_dict() == task.config
    resumed = {**task.config, "training": {**task.config["training"], "threads": 7}}
    assert cell.write_train_config(_task(tmp_path, config=resumed)) == path
    assert "threads = 7" in path.read_text()
    other = {**task.config, "seed": 1}
    with pytest.raises(SpecError) as info:
        cell.write_train_config(_task(tmp_path, config=other, cell_id="c9"))
    assert str(info.value) == f"cell c9: {path} holds another config; use another --out folder"
    assert "threads = 7" in path.read_text() and "seed = 42" in path.read_text()


def test_link_data_links_every_category(tmp_path):
    """Mutants of link_data: CELL/data/<category> for each shared folder, relative."""
    for name in ("a", "b"):
        (tmp_path / "shared" / name).mkdir(parents=True)
    shared = tmp_path / "shared"
    task = _task(tmp_path, data_links={"cat_a": str(shared / "a"), "cat_b": str(shared / "b")})
    cell.link_data(task)
    assert _files(task.path) == {"data/cat_a": "-> ../../shared/a", "data/cat_b": "-> ../../shared/b"}


def _stage1(folder: Path, stage: int = 1, step: int = 0, fmt: str = tck.CHECKPOINT_FORMAT) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    tck.save(folder / "checkpoint.pt", {"format": fmt, "stage": stage, "step": step, "elapsed_s": 12.5,
                                        "model": {"w": torch.tensor([1.0, 2.0])}, "config": {"old": 1}})


def test_seed_from_stage1_copies_the_shared_run_in(tmp_path):
    """Mutants of seed_from_stage1: the shared checkpoint (its format) read, the shared stages' weights, best.pt
    and the metrics copied, the checkpoint written last with the cell's config; a seeded cell is left as it is;
    the stage-1 seconds returned."""
    src = tmp_path / "stage1"
    _stage1(src)
    (src / "stage1_s1.pt").write_bytes(b"w1")
    (src / "best.pt").write_bytes(b"best")
    (src / "metrics.jsonl").write_bytes(b"{}\n")
    (src / "stage2_s2.pt").write_bytes(b"not shared")
    task = _task(tmp_path, stage1_dir=str(src))
    assert cell.seed_from_stage1(task) == 12.5
    assert sorted(p.name for p in task.path.iterdir()) == ["best.pt", "checkpoint.pt", "metrics.jsonl", "stage1_s1.pt"]
    assert [(task.path / n).read_bytes() for n in ("best.pt", "metrics.jsonl", "stage1_s1.pt")] == [b"best", b"{}\n",
                                                                                                      b"w1"]
    state = tck.load(task.path / "checkpoint.pt", tck.CHECKPOINT_FORMAT)
    assert state["config"] == task.config and (state["stage"], state["step"], state["elapsed_s"]) == (1, 0, 12.5)
    assert torch.equal(state["model"]["w"], torch.tensor([1.0, 2.0]))
    (src / "best.pt").write_bytes(b"newer")
    _stage1(src)
    assert cell.seed_from_stage1(task) == 12.5
    assert (task.path / "best.pt").read_bytes() == b"best"
    (src / "best.pt").unlink()
    (src / "metrics.jsonl").unlink()
    (src / "metrics.jsonl").mkdir()
    second = _task(tmp_path, stage1_dir=str(src), cell_dir=str(tmp_path / "c2"))
    cell.seed_from_stage1(second)
    assert sorted(p.name for p in second.path.iterdir()) == ["checkpoint.pt", "stage1_s1.pt"]


@pytest.mark.parametrize(("stage", "step"), [(0, 0), (1, 3), (2, 0)])
def test_seed_from_stage1_refuses_an_unfinished_shared_run(tmp_path, stage, step):
    """Mutants of seed_from_stage1's check: the shared stages done (stage = stages - 1) at step 0, word for
    word; nothing copied."""
    src = tmp_path / "stage1"
    _stage1(src, stage, step)
    task = _task(tmp_path, stage1_dir=str(src))
    with pytest.raises(DataError) as info:
        cell.seed_from_stage1(task)
    assert str(info.value) == (f"{src / 'checkpoint.pt'}: the shared stage-1 run is not finished (stage {stage}, "
                               f"step {step})")
    assert not task.path.exists()


def test_stage1_digest_and_format(tmp_path):
    """Mutants of stage1_digest and of the format both stage-1 readers expect."""
    _stage1(tmp_path / "s")
    assert cell.stage1_digest(str(tmp_path / "s")) == tck.state_sha256({"w": torch.tensor([1.0, 2.0])})
    _stage1(tmp_path / "w", fmt="lfbench.weights")
    line = f"{tmp_path / 'w' / 'checkpoint.pt'}: not a lfbench.train.checkpoint file (format 'lfbench.weights')"
    with pytest.raises(DataError) as info:
        cell.stage1_digest(tmp_path / "w")
    assert str(info.value) == line
    with pytest.raises(DataError) as info:
        cell.seed_from_stage1(_task(tmp_path, stage1_dir=str(tmp_path / "w")))
    assert str(info.value) == line
    with pytest.raises(AssertionError):
        cell.seed_from_stage1(_task(tmp_path))


def test_resolve_device_names_the_device_as_the_tables_do(monkeypatch):
    """Mutants of resolve_device: auto and cuda by their type, cuda:K and cpu as they are."""
    import lfbench.utils.hardware as hardware

    assert cell.resolve_device("cpu") == "cpu"
    monkeypatch.setattr(hardware, "resolve_device", lambda name: torch.device("cuda", 1))
    assert [cell.resolve_device(n) for n in ("auto", "cuda", "cuda:1")] == ["cuda", "cuda", "cuda:1"]


def test_make_method_passes_the_evaluation_settings(monkeypatch):
    """Mutants of make_method: every argument of network_runner."""
    import lfbench.method.registry as registry

    calls = []
    monkeypatch.setattr(registry, "network_runner", lambda *a, **kw: calls.append((a, kw)) or "method")
    ev = Evaluation(tile=8, max_memory_gb=2.5, precision="bf16")
    assert cell.make_method(Path("w.pt"), ev, 5, "epinet") == "method"
    cell.make_method(Path("v.pt"), Evaluation(), 1)
    assert calls == [(("epinet", Path("w.pt")), {"device": "cpu", "threads": 5, "tile": 8, "max_memory_gb": 2.5,
                                                   "precision": "bf16"}),
                     (("subfocal", Path("v.pt")), {"device": "cpu", "threads": 1, "tile": 0, "max_memory_gb": 4.0,
                                                   "precision": "fp32"})]


class _Timed:
    def __init__(self, events):
        self.events = events

    def predict(self, lf):
        self.events.append(("predict", lf.name, lf.views.shape, lf.views.dtype, float(lf.views[0, 0, 0, 0])))


def test_time_whole_scene_times_each_repeat_after_the_warmup(monkeypatch):
    """Mutants of time_whole_scene: random float32 views of the seed (V, U, size, size), the warmup untimed, each
    repeat timed from before the prediction to after the device synchronised."""
    events = []
    clock = iter([1.0, 1.5, 10.0, 12.25])
    monkeypatch.setattr(cell.time, "perf_counter", lambda: events.append("clock") or next(clock))
    monkeypatch.setattr(cell, "_sync", lambda: events.append("sync"))
    times = cell.time_whole_scene(_Timed(events), 4, 2, 1, seed=7, angular=(3, 5))
    assert times == [0.5, 2.25]
    first = float(np.random.default_rng(7).random((3, 5, 4, 4), dtype=np.float32)[0, 0, 0, 0])
    predict = ("predict", "timing_4px", (3, 5, 4, 4), np.float32, first)
    assert events == [predict, "clock", predict, "sync", "clock", "clock", predict, "sync", "clock"]
    events.clear()
    clock = iter([0.0, 1.0])
    assert cell.time_whole_scene(_Timed(events), 2, 1, 0) == [1.0]
    first = float(np.random.default_rng(0).random((9, 9, 2, 2), dtype=np.float32)[0, 0, 0, 0])
    assert events == ["clock", ("predict", "timing_2px", (9, 9, 2, 2), np.float32, first), "sync", "clock"]


def test_sync_waits_for_cuda_only_when_there_is_one(monkeypatch):
    """Mutants of _sync."""
    calls = []
    monkeypatch.setattr(torch.cuda, "synchronize", lambda: calls.append("sync"))
    monkeypatch.setattr(torch.cuda, "is_available", lambda: False)
    cell._sync()
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    cell._sync()
    assert calls == ["sync"]


class _Dataset:
    name = "hci"

    def __init__(self, protocol, calls):
        self.protocol, self.calls = protocol, calls

    def protocol_for(self, data):
        self.calls.append(("protocol_for", data))
        return self.protocol


def test_scenes_and_datasets_of_an_evaluation(tmp_path, monkeypatch):
    """Mutants of open_generated / load_scenes / evaluation_dataset: generated scenes by the generated layout's
    adapter (the first scene of the folder), those under the data root by its dataset (given or detected)."""
    import lfbench.data.dataset as dataset

    calls = []

    class Adapter:
        def open(self, folder):
            calls.append(("open", folder))
            return SimpleNamespace(scenes=[f"generated {folder.name}", "second"])

    real_get = dataset.DATASETS.get
    monkeypatch.setattr(dataset.DATASETS, "get", lambda name: calls.append(("get", name)) or Adapter())
    assert cell.open_generated(str(tmp_path / "g1")) == "generated g1"
    assert calls == [("get", cell.GENERATED_LAYOUT), ("open", tmp_path / "g1")]
    assert cell.GENERATED_LAYOUT == real_get(cell.GENERATED_LAYOUT).name
    calls.clear()
    data = tmp_path / "data"
    scene = SimpleNamespace(path=data / "s1")
    monkeypatch.setattr(dataset, "open_dataset", lambda root, name: calls.append(("dataset", root, name)) or (
        None, SimpleNamespace(scenes=[scene])))
    pairs = ((str(data / "s1"), "cat"), (str(tmp_path / "g2"), None))
    assert cell.load_scenes(pairs, Evaluation(data=data, dataset="hci")) == [scene, "generated g2"]
    assert calls == [("dataset", data, "hci"), ("get", cell.GENERATED_LAYOUT), ("open", tmp_path / "g2")]
    calls.clear()
    assert cell.load_scenes(pairs[1:]) == ["generated g2"]
    assert cell.load_scenes(pairs[1:], Evaluation()) == ["generated g2"]
    assert [c[0] for c in calls] == ["get", "open", "get", "open"]
    monkeypatch.setattr(dataset, "dataset_of", lambda root, name: ("dataset of", root, name))
    assert cell.evaluation_dataset(Evaluation()) is None
    assert cell.evaluation_dataset(Evaluation(data=data)) == ("dataset of", data, None)
    assert cell.evaluation_dataset(Evaluation(data=data, dataset="x")) == ("dataset of", data, "x")


def test_scoring_of_the_generated_scenes_or_the_dataset(tmp_path, monkeypatch):
    """Mutants of scoring_of / scoring_kwargs / results_meta: the generated layout's protocol (or the dataset's
    protocol for its data root), high resolution unless lowres_only, and what the results record of it."""
    import lfbench.data.dataset as dataset

    metrics = ["badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100"]
    scoring = cell.scoring_of(Evaluation())
    assert scoring.protocol is dataset.DATASETS.get(cell.GENERATED_LAYOUT).protocol
    assert (scoring.rules.allow_highres, scoring.rules.toolkit, scoring.rules.border_px) == (True, False, 15)
    assert cell.scoring_of(Evaluation(lowres_only=True)).rules.allow_highres is False
    kwargs = cell.scoring_kwargs(Evaluation())
    assert sorted(kwargs) == ["meta", "metrics", "rules"] and kwargs["rules"] == scoring.rules
    assert [m.id for m in kwargs["metrics"]] == metrics and isinstance(kwargs["metrics"], list)
    protocol_meta = {"metrics": metrics, "disparity_range": [-4.0, 4.0]}
    assert kwargs["meta"] == {"protocol_metrics": metrics, "protocol": protocol_meta}
    assert cell.results_meta(Evaluation()) == {
        "protocol_metrics": metrics, "protocol": protocol_meta,
        "scoring": {"border_px": 15, "toolkit_nonfinite": False, "highres_scenes": ["backgammon", "dots", "stripes"]}}
    calls = []
    protocol = dataclasses.replace(scoring.protocol, metrics=("mse_x100",), disparity_range=(-1.0, 2.0))
    monkeypatch.setattr(dataset, "dataset_of", lambda root, name: _Dataset(protocol, calls))
    ev = Evaluation(data=tmp_path)
    assert cell.scoring_of(ev).protocol is protocol and calls == [("protocol_for", tmp_path)]
    assert list(cell.scoring_kwargs(ev)["meta"].items()) == [
        ("dataset", "hci"), ("protocol_metrics", ["mse_x100"]),
        ("protocol", {"metrics": ["mse_x100"], "disparity_range": [-1.0, 2.0]})]


def test_evaluate_weights_scores_into_the_cell_folder(tmp_path, monkeypatch):
    """Mutants of evaluate_weights: the method of the weights, the scenes, the folder, the label, the maps writer
    (the cell's maps with their uncertainty, in one folder) only with save_maps, no progress bar, the scoring."""
    import lfbench.runs.folder as folder

    calls = []
    monkeypatch.setattr(folder, "evaluate_to_folder", lambda *a, **kw: calls.append((a, kw)) or "results")
    monkeypatch.setattr(cell, "make_method", lambda *a: ("method", *a))
    monkeypatch.setattr(cell, "scoring_kwargs", lambda ev: {"rules": "R", "metrics": ["m"], "meta": {"k": ev}})
    ev = Evaluation()
    assert cell.evaluate_weights("c1", Path("w.pt"), ev, ["s"], 3, tmp_path, network="epinet") == "results"
    cell.evaluate_weights("c2", Path("v.pt"), ev, ["t"], 2, tmp_path, save_maps=False)
    (args, kw), (args2, kw2) = calls
    assert args == ([("method", Path("w.pt"), ev, 3, "epinet")], ["s"], tmp_path)
    [maps] = kw.pop("writers")
    assert type(maps).__name__ == "Maps" and (maps.folder, maps.per_method, maps.uncertainty) == ("maps", False, True)
    assert kw == {"label": "c1", "progress": False, "rules": "R", "metrics": ["m"], "meta": {"k": ev}}
    assert args2 == ([("method", Path("v.pt"), ev, 2, "subfocal")], ["t"], tmp_path)
    assert kw2 == {"label": "c2", "writers": [], "progress": False, "rules": "R", "metrics": ["m"], "meta": {"k": ev}}


def test_timing_key_holds_every_setting_of_the_timing():
    """Mutants of timing_key."""
    ev = Evaluation(time_size=64, time_repeats=3, time_warmup=2, tile=16, max_memory_gb=1.5, precision="bf16")
    assert cell.timing_key(ev, 4, (5, 7)) == {"time_size": 64, "angular": [5, 7], "repeats": 3, "warmup": 2,
                                              "threads": 4, "device": "cpu", "tile": 16, "max_memory_gb": 1.5,
                                              "precision": "bf16"}
    assert cell.timing_key(Evaluation(), 1)["angular"] == [9, 9]


def _weights(cell_dir: Path, marker: dict | None = None) -> str:
    cell_dir.mkdir(parents=True, exist_ok=True)
    tck.save(cell_dir / "final.pt", {"format": "lfbench.weights", "state_dict": {"w": torch.tensor([3.0])}})
    digest = tck.state_sha256({"w": torch.tensor([3.0])})
    (cell_dir / "cell.json").write_text(json.dumps({"final_sha256": digest} if marker is None else marker))
    return digest


def test_time_cell_times_the_recorded_weights_once(tmp_path, monkeypatch):
    """Mutants of time_cell: the weights checked against the marker, the timing (median, every time, settings,
    host, SLURM job) written and re-used while its key is the same, the torch threads restored."""
    digest = _weights(tmp_path / "c")
    calls = []
    monkeypatch.setattr(cell, "make_method", lambda *a: calls.append(("make", *a)) or torch.set_num_threads(1)
                        or "method")
    monkeypatch.setattr(cell, "time_whole_scene", lambda *a, **kw: calls.append(("time", *a, kw)) or [3.0, 1.0, 2.5])
    monkeypatch.setattr(cell.socket, "gethostname", lambda: "node7")
    monkeypatch.setenv("SLURM_JOB_ID", "77")
    ev = Evaluation(time_size=32, time_repeats=3, time_warmup=1)
    threads = torch.get_num_threads()
    with torch_threads(2):
        out = cell.time_cell(str(tmp_path / "c"), ev, 4, "epinet", (5, 5))
        assert torch.get_num_threads() == 2
    assert torch.get_num_threads() == threads
    key = {**cell.timing_key(ev, 4, (5, 5)), "final_sha256": digest}
    assert out == {"key": key, "test_s": 2.5, "test_s_all": [3.0, 1.0, 2.5], "time_size": 32, "time_angular": [5, 5],
                   "threads": 4, "device": "cpu", "host": "node7", "slurm_job_id": "77"}
    assert calls == [("make", tmp_path / "c" / "final.pt", ev, 4, "epinet"),
                     ("time", "method", 32, 3, 1, {"angular": (5, 5)})]
    assert (tmp_path / "c" / "timing.json").read_text() == json.dumps(out, indent=2, sort_keys=True) + "\n"
    calls.clear()
    assert cell.time_cell(tmp_path / "c", ev, 4, "epinet", (5, 5)) == out
    assert calls == []
    monkeypatch.delenv("SLURM_JOB_ID")
    again = cell.time_cell(tmp_path / "c", ev, 2)
    assert again["slurm_job_id"] is None and again["key"]["threads"] == 2 and again["time_angular"] == [9, 9]
    assert calls[0] == ("make", tmp_path / "c" / "final.pt", ev, 2, "subfocal")
    (tmp_path / "c" / "timing.json").write_text("[]")
    calls.clear()
    cell.time_cell(tmp_path / "c", ev, 2)
    assert len(calls) == 2


@pytest.mark.parametrize("marker", [{"final_sha256": "0" * 64}, {}, None])
def test_time_cell_refuses_weights_the_cell_did_not_record(tmp_path, marker):
    """Mutants of time_cell's check: other weights, no digest, no marker."""
    _weights(tmp_path / "c", marker or {})
    if marker is None:
        (tmp_path / "c" / "cell.json").unlink()
    with pytest.raises(DataError) as info:
        cell.time_cell(tmp_path / "c", Evaluation(), 1)
    assert str(info.value) == (f"{tmp_path / 'c' / 'final.pt'}: not the weights the cell recorded (final_sha256 of its "
                               "cell.json); run lfbench ablate again to re-make the cell")
    assert not (tmp_path / "c" / "timing.json").exists()


def test_run_cell_skips_a_finished_cell_and_runs_the_others_with_their_threads(tmp_path, monkeypatch):
    """Mutants of run_cell: the folder made, the lock, a finished cell's marker returned without a run, an
    unfinished one run with the cell's torch threads (restored after)."""
    task = _task(tmp_path, threads=2, cell_dir=str(tmp_path / "cells" / "c1"))
    threads = torch.get_num_threads()
    seen = []
    monkeypatch.setattr(cell, "_run", lambda t: seen.append((t, torch.get_num_threads())) or {"ran": 1})
    assert cell.run_cell(task) == {"ran": 1}
    assert seen == [(task, 2)] and torch.get_num_threads() == threads
    assert sorted(p.name for p in task.path.iterdir()) == ["cell.lock"]
    monkeypatch.setattr(cell, "is_done", lambda t: True)
    (task.path / "cell.json").write_text(json.dumps({"id": "c1"}))
    assert cell.run_cell(task) == {"id": "c1"}
    (task.path / "cell.json").write_text("[]")
    assert cell.run_cell(task) == {}
    assert len(seen) == 1


class _Results:
    def __init__(self, runs, scenes):
        self.runs, self.scenes, self.meta = runs, scenes, {"k": 1}

    def write(self, folder):
        (folder / "results.json").write_text(json.dumps(self.meta, sort_keys=True))


def test_run_trains_scores_and_marks_the_cell(tmp_path, monkeypatch):
    """Mutants of _run: the config written and trained from (its command, the cell's log with its header), the
    data linked, the scores of final.pt on the scenes with the evaluation's threads (else the cell's), and the
    marker (every key) written last, also into the results' meta."""
    import lfbench.training.loop as loop

    calls = []

    def train(cfg, out, command, progress):
        calls.append(("train", cfg.to_dict() == task.config, out, command, progress))
        logging.getLogger("lfbench.training.loop").info("step 1")
        (out / "summary.json").write_text(json.dumps({"elapsed_s": 10.0, "steps": 7}))
        tck.save(out / "final.pt", {"format": "lfbench.weights", "state_dict": {"w": torch.tensor([3.0])}})

    monkeypatch.setattr(loop, "train", train)
    monkeypatch.setattr(cell.time, "strftime", lambda fmt: f"<{fmt}>")
    monkeypatch.setattr(cell, "load_scenes", lambda scenes, ev: calls.append(("scenes", scenes, ev)) or ["S"])
    runs = [SimpleNamespace(runtime_s=1.0), SimpleNamespace(runtime_s=2.0)]
    monkeypatch.setattr(cell, "evaluate_weights", lambda *a: calls.append(("eval", *a)) or _Results(runs, ["s1"]))
    (tmp_path / "shared").mkdir()
    ev = Evaluation(threads=5)
    task = _task(tmp_path, data_links={"syn": str(tmp_path / "shared")}, scenes=(("s1", "cat"),), evaluation=ev,
                 progress=False, cell_dir=str(tmp_path / "cells" / "c1"))
    marker = cell._run(task)
    config = task.path / "train.toml"
    digest = tck.state_sha256({"w": torch.tensor([3.0])})
    assert calls == [("train", True, task.path, f"lfbench train {config} --out {task.path}", False),
                     ("scenes", (("s1", "cat"),), ev),
                     ("eval", "c1", task.path / "final.pt", ev, ["S"], 5, task.path, True, "subfocal")]
    results_sha = hashlib.sha256((task.path / "results.json").read_bytes()).hexdigest()
    expected = {"id": "c1", "values": {"lr": 1}, "fingerprint": "f", "eval_fingerprint": "e", "steps": 7,
                "train_s": 10.0, "own_train_s": 10.0, "stage1_s": 0.0, "stage1_sha256": None, "final_sha256": digest,
                "threads": 3, "device": "cpu", "eval_runtime_s": 1.5, "scenes": ["s1"], "results_sha256": results_sha}
    assert marker == expected
    assert json.loads((task.path / "cell.json").read_text()) == expected
    assert (task.path / "cell.json").read_text() == json.dumps(expected, indent=2, sort_keys=True) + "\n"
    in_results = {k: v for k, v in expected.items() if k not in ("fingerprint", "eval_fingerprint", "results_sha256")}
    assert json.loads((task.path / "results.json").read_text()) == {"k": 1, "cell": in_results}
    assert (task.path / "log.txt").read_text() == "# <%Y-%m-%d %H:%M:%S> cell c1 (3 threads)\nstep 1\n"
    assert os.readlink(task.path / "data" / "syn") == "../../../shared"
    assert cell.is_done(task) is True


def test_run_from_a_shared_stage1_without_runs(tmp_path, monkeypatch):
    """Mutants of _run's stage-1 branch and its defaults: the stage-1 seconds and digest, the cell's own training
    time, the cell's threads when the evaluation gives none, no runtime without runs."""
    import lfbench.training.loop as loop

    def train(cfg, out, command, progress):
        (out / "summary.json").write_text(json.dumps({"elapsed_s": 30.0, "steps": 9}))
        tck.save(out / "final.pt", {"format": "lfbench.weights", "state_dict": {}})

    evaluated = []
    monkeypatch.setattr(loop, "train", train)
    monkeypatch.setattr(cell, "seed_from_stage1", lambda given: 12.5 if given is task else None)
    monkeypatch.setattr(cell, "stage1_digest", lambda folder: f"digest of {folder}")
    monkeypatch.setattr(cell, "load_scenes", lambda scenes, ev: [])
    monkeypatch.setattr(cell, "evaluate_weights", lambda *a: evaluated.append(a[4]) or _Results([], []))
    task = _task(tmp_path, stage1_dir="S1", threads=4)
    task.path.mkdir()
    marker = cell._run(task)
    assert evaluated == [4]
    assert (marker["train_s"], marker["own_train_s"], marker["stage1_s"]) == (30.0, 17.5, 12.5)
    assert (marker["stage1_sha256"], marker["eval_runtime_s"], marker["scenes"]) == ("digest of S1", None, [])


def test_run_names_a_training_summary_it_cannot_read(tmp_path, monkeypatch):
    """Mutants of _run's read of summary.json: its `what` in the error line."""
    import lfbench.training.loop as loop

    monkeypatch.setattr(loop, "train", lambda cfg, out, command, progress: (out / "summary.json").write_text("{"))
    task = _task(tmp_path)
    with pytest.raises(DataError) as info:
        cell._run(task)
    assert str(info.value) == (f"{task.path / 'summary.json'}: training summary is not valid JSON: Expecting property "
                               "name enclosed in double quotes: line 1 column 2 (char 1)")


def test_seed_from_stage1_copies_at_most_max_copy_bytes(tmp_path, monkeypatch):
    """Mutants of seed_from_stage1's read: the file named by its name in the error, the bound MAX_COPY_BYTES."""
    src = tmp_path / "stage1"
    _stage1(src)
    (src / "best.pt").write_bytes(b"abcd")
    monkeypatch.setattr(cell, "MAX_COPY_BYTES", 3)
    with pytest.raises(DataError) as info:
        cell.seed_from_stage1(_task(tmp_path, stage1_dir=str(src)))
    assert str(info.value) == f"{src / 'best.pt'}: best.pt is larger than 3 bytes, more than lfbench reads"


def test_cluster_options_name_a_bad_value_by_its_flag():
    """Mutants of ClusterOptions.__post_init__: the flag's name in the line."""
    with pytest.raises(SpecError) as info:
        executor.ClusterOptions("pool", gpus_per_job=-1)
    assert str(info.value) == "--gpus-per-job: must be >= 0, got -1"
    with pytest.raises(SpecError) as info:
        executor.ClusterOptions("nowhere")
    assert str(info.value).startswith("Unknown executor 'nowhere'")


def test_one_worker_on_a_gpu(monkeypatch):
    """Mutants of _start's GPU line: the first worker's GPU decides (one worker has only that one)."""
    import multiprocessing

    class Context:
        def Queue(self):  # noqa: N802 (multiprocessing's name)
            return SimpleNamespace(put=lambda item: None)

    monkeypatch.setattr(multiprocessing, "get_context", lambda name: Context())
    monkeypatch.setattr(executor, "ProcessPoolExecutor", lambda **kw: None)
    monkeypatch.setattr(executor, "visible_gpus", lambda: ["3"])
    lines = []
    _, marks = executor.ProcessPool(executor.ClusterOptions("pool"), jobs=1, log=lines.append)._start(1)
    marks.rmdir()
    assert lines == ["1 worker(s) on GPU(s) 3 (round-robin)"]


def test_a_named_set_names_its_own_journal_in_a_refusal(tmp_path):
    """Mutants of commit's check of the staged entries: the journal of the set named."""
    outputs_set = outputs.OutputSet(tmp_path / "out", "cell")
    (outputs_set.stage / "link").symlink_to(tmp_path)
    with pytest.raises(DataError) as info:
        outputs_set.commit(["link"])
    assert str(info.value) == _refusal(tmp_path / "out" / ".lfbench-commit.cell.json",
                                       f"commit journal: staged entry {outputs_set.stage / 'link'} is a symbolic link")


def test_commit_written_keeps_what_it_is_told(tmp_path):
    """Mutants of commit_written's `keep`."""
    out = tmp_path / "out"
    first = outputs.OutputSet(out)
    (first.stage / "a").write_text("a")
    first.commit(["a"])
    second = outputs.OutputSet(out)
    (second.stage / "b").write_text("b")
    assert second.commit_written([second.stage / "b"], keep=["a"]) == [out / "b"]
    assert _files(out) == {".lfbench-outputs.json": _manifest("a", "b"), "a": "a", "b": "b"}


def test_abort_when_the_staging_folder_is_gone(tmp_path):
    """Mutants of abort's rmtree (errors ignored): a staging folder someone removed is no error."""
    outputs_set = outputs.OutputSet(tmp_path / "out")
    outputs_set.stage.rmdir()
    outputs_set.abort()
    assert not (tmp_path / "out").exists()


def test_a_journal_that_is_not_json_is_named_as_a_commit_journal(tmp_path):
    """Mutants of _read_journal's `what`."""
    (tmp_path / ".lfbench-commit.json").write_text("{")
    with pytest.raises(DataError) as info:
        outputs.recover(tmp_path)
    assert str(info.value) == _refusal(tmp_path / ".lfbench-commit.json", "commit journal is not valid UTF-8 JSON")


@pytest.fixture
def stuck_files(monkeypatch):
    """Files named ``stuck*`` cannot be removed (a busy file on a network file system); returns the names whose
    removal was tried."""
    tried = []
    unlink = os.unlink

    def stuck_unlink(path, *, dir_fd=None):
        name = os.fsdecode(path)
        if os.path.basename(name).startswith("stuck"):
            tried.append(os.path.basename(name))
            raise PermissionError(errno.EPERM, "Operation not permitted", name)
        return unlink(path, dir_fd=dir_fd)

    monkeypatch.setattr(os, "unlink", stuck_unlink)
    return tried


def test_stale_temporaries_are_removed_as_far_as_they_can_be(tmp_path, stuck_files):
    """Mutants of _remove's rmtree (errors ignored): every file of a stale folder is tried, not only up to the
    first that cannot be removed."""
    (tmp_path / "stale").mkdir()
    for name in ("stuck1", "stuck2", "stuck3"):
        (tmp_path / "stale" / name).write_text(name)
    outputs._remove(tmp_path / "stale")
    assert sorted(stuck_files) == ["stuck1", "stuck2", "stuck3"]


def test_a_roll_forward_ends_even_when_the_staging_folder_cannot_be_removed(tmp_path, stuck_files):
    """Mutants of _roll_forward's rmtree (errors ignored): the commit is done, what is left of the staging folder
    is the next run's to clean."""
    outputs_set = outputs.OutputSet(tmp_path / "out")
    (outputs_set.stage / "a").write_text("a")
    (outputs_set.stage / "stuck").write_text("s")
    outputs_set.commit(["a"])
    assert _files(tmp_path / "out") == {".lfbench-outputs.json": _manifest("a"), "a": "a",
                                        f"{outputs_set.stage.name}/stuck": "s"}
    assert stuck_files == ["stuck"]


def test_the_pool_ends_even_when_a_mark_cannot_be_removed(pool_map, stuck_files):
    """Mutants of map's rmtree of the marks (errors ignored)."""
    run, events, marks = pool_map
    run([1, 2], fn=lambda i: (marks / "stuck").write_text("x") and i)
    assert events[-3:] == [("done", 1), ("done", 2), ("shutdown", True, True)] and stuck_files == ["stuck"]
