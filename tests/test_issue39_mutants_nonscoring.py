"""Tests that must fail (issue 39 item 6, third round): issue 31's changes outside scoring, mutated with mutmut.

The write targets (lfbench/utils/atomic.py, the checks of lfbench/utils/outputs.py), the weights-file checks
(lfbench/method/checkpoint.py, lfbench/training/checkpoint.load), an ablation's re-use of its output folder
(lfbench/ablation/cell.py: the marker, the recorded digests, the data links) and the pool's dead-worker path
(lfbench/utils/executor.py: the marks, the worker's set-up, the error naming what died). Each test names the
class of mutants it kills; every expected value is written out (exact error lines, which files exist, the
modes, the links' text). No subprocess, no process pool (a pool's fork deadlocks mutmut's children), no sleep.
Results: results/mutation/issue39/README.md, "Third round".
"""

from __future__ import annotations

import errno
import hashlib
import json
import logging
import os
import signal
import socket
import stat
import zipfile
from pathlib import Path
from types import SimpleNamespace

import pytest
import torch

from lfbench.ablation import cell
from lfbench.method import checkpoint as mck
from lfbench.training import checkpoint as tck
from lfbench.utils import atomic, executor, outputs
from lfbench.utils.errors import DataError, RunFailed, SpecError

REFUSAL = ", not a regular file: lfbench writes only regular files and does not replace it"


def _fifo(path: Path) -> Path:
    os.mkfifo(path)
    return path


def _fake_lstat(monkeypatch, mode: int) -> None:
    """os.lstat answers ``mode`` (a device without mknod)."""
    monkeypatch.setattr(os, "lstat", lambda p: SimpleNamespace(st_mode=mode))


# --------------------------------------------------------------------------- atomic.py


def test_check_replaceable_lets_absent_files_regular_files_and_links_through(tmp_path):
    """Mutants of the early returns (absent, S_ISREG, S_ISLNK; `and` for `or`): no error for these."""
    regular = tmp_path / "f"
    regular.write_text("x")
    link_to_fifo = tmp_path / "l"
    link_to_fifo.symlink_to(_fifo(tmp_path / "fifo"))
    dangling = tmp_path / "d"
    dangling.symlink_to(tmp_path / "nowhere")
    for path in (tmp_path / "absent", regular, link_to_fifo, dangling, str(regular)):
        assert atomic.check_replaceable(path) is None


@pytest.mark.parametrize("kind", ["folder", "fifo", "socket"])
def test_check_replaceable_refuses_each_kind_in_its_words(tmp_path, kind):
    """Mutants of `_KINDS`' order or of the message: a folder, a FIFO and a socket named as such."""
    path = tmp_path / "entry"
    if kind == "folder":
        path.mkdir()
        word = "a folder"
    elif kind == "fifo":
        _fifo(path)
        word = "a FIFO"
    else:
        sock = socket.socket(socket.AF_UNIX)
        sock.bind(str(path))
        sock.close()
        word = "a socket"
    with pytest.raises(DataError) as info:
        atomic.check_replaceable(path)
    assert str(info.value) == f"{path}: is {word}{REFUSAL}"
    assert info.value.path == path


@pytest.mark.parametrize(("mode", "word"), [(stat.S_IFCHR | 0o666, "a character device"),
                                            (stat.S_IFBLK | 0o660, "a block device"),
                                            (0o644, "not a regular file")])
def test_check_replaceable_names_devices_and_unknown_kinds(tmp_path, monkeypatch, mode, word):
    """Mutants of the device tests and of the fallback word (`next(..., "not a regular file")`)."""
    _fake_lstat(monkeypatch, mode)
    with pytest.raises(DataError) as info:
        atomic.check_replaceable(tmp_path / "dev")
    assert str(info.value) == f"{tmp_path / 'dev'}: is {word}{REFUSAL}"


@pytest.mark.parametrize(("exc", "line"), [(PermissionError(errno.EACCES, "Permission denied"),
                                            "cannot write: Permission denied"),
                                           (OSError("no strerror"), "cannot write: no strerror")])
def test_check_replaceable_names_an_lstat_failure(tmp_path, monkeypatch, exc, line):
    """Mutants of the OSError branch: `exc.strerror or exc`, the message, the path."""
    def fail(path):
        raise exc
    monkeypatch.setattr(os, "lstat", fail)
    with pytest.raises(DataError) as info:
        atomic.check_replaceable(tmp_path / "x")
    assert str(info.value) == f"{tmp_path / 'x'}: {line}"


def test_atomic_open_writes_with_the_default_mode_and_creates_the_folder(tmp_path):
    """Mutants of the mode (FILE_MODE, fchmod), of mkdir(parents=True, exist_ok=True), of the mode string."""
    path = tmp_path / "a" / "b" / "out.bin"
    with atomic.atomic_open(path) as f:
        f.write(b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"
    assert stat.S_IMODE(path.stat().st_mode) == 0o644 == atomic.FILE_MODE
    with atomic.atomic_open(path) as f:  # the folder exists now: exist_ok
        f.write(b"2")
    assert path.read_bytes() == b"2" and sorted(p.name for p in path.parent.iterdir()) == ["out.bin"]


def test_atomic_open_keeps_an_existing_mode_or_takes_the_given_one(tmp_path):
    """Mutants of `file_mode is None`, of the existing file's mode (S_IMODE of path.stat())."""
    path = tmp_path / "f"
    path.write_text("old")
    path.chmod(0o600)
    atomic.write_text(path, "new")
    assert stat.S_IMODE(path.stat().st_mode) == 0o600 and path.read_text() == "new"
    with atomic.atomic_open(path, "w", file_mode=0o640, encoding="utf-8") as f:
        f.write("é")
    assert stat.S_IMODE(path.stat().st_mode) == 0o640 and path.read_bytes() == "é".encode()


def test_atomic_open_writes_beside_the_file_under_a_hidden_temporary_name(tmp_path):
    """Mutants of mkstemp's prefix, suffix and folder: the temporary is `.NAME.<random>.tmp` beside it."""
    path = tmp_path / "out.json"
    with atomic.atomic_open(path, "w") as f:
        names = [p.name for p in tmp_path.iterdir()]
        f.write("{}")
    assert len(names) == 1 and names[0].startswith(".out.json.") and names[0].endswith(".tmp")
    assert [p.name for p in tmp_path.iterdir()] == ["out.json"]


def test_atomic_open_replaces_a_link_not_its_target(tmp_path):
    """Mutants of the replace (os.replace onto the link itself): the link becomes a file, the target stays."""
    target = tmp_path / "target"
    target.write_text("kept")
    link = tmp_path / "link"
    link.symlink_to(target)
    atomic.write_bytes(link, b"new")
    assert not link.is_symlink() and link.read_bytes() == b"new" and target.read_text() == "kept"


def test_atomic_open_refuses_a_fifo_before_anything(tmp_path):
    """Mutants that drop check_replaceable: a FIFO is refused, no temporary left."""
    fifo = _fifo(tmp_path / "fifo")
    with pytest.raises(DataError, match="is a FIFO"):
        atomic.write_bytes(fifo, b"x")
    assert [p.name for p in tmp_path.iterdir()] == ["fifo"]


def test_atomic_open_leaves_the_old_file_and_no_temporary_on_any_error(tmp_path):
    """Mutants of the cleanup (unlink of the temporary) in both except branches."""
    path = tmp_path / "f"
    path.write_text("old")
    for exc in (ValueError("boom"), OSError(errno.ENOSPC, "No space left on device")):
        with pytest.raises(type(exc)), atomic.atomic_open(path, "w") as f:
            f.write("half")
            raise exc
        assert path.read_text() == "old" and [p.name for p in tmp_path.iterdir()] == ["f"]


def test_a_write_that_names_no_file_names_the_target(tmp_path):
    """Mutants of _naming: a full disk names nothing (or the temporary, or the folder): the error names the
    file written, with its errno and words; an error naming another file, or without errno, passes as it is."""
    path = tmp_path / "f"
    with pytest.raises(OSError) as info, atomic.atomic_open(path):
        raise OSError(errno.ENOSPC, "No space left on device")
    assert (type(info.value), info.value.errno, info.value.strerror, info.value.filename) == \
        (OSError, errno.ENOSPC, "No space left on device", str(path))
    with pytest.raises(FileNotFoundError) as info, atomic.atomic_open(path):
        (tmp,) = tmp_path.iterdir()
        raise FileNotFoundError(errno.ENOENT, "No such file", str(tmp))  # the temporary
    assert type(info.value) is FileNotFoundError and info.value.filename == str(path)
    other = FileNotFoundError(errno.ENOENT, "No such file", "/elsewhere")
    with pytest.raises(FileNotFoundError) as info, atomic.atomic_open(path):
        raise other
    assert info.value is other
    plain = OSError("plain")
    assert atomic._naming(plain, path, None) is plain
    folder = OSError(errno.EACCES, "Permission denied", str(tmp_path))
    named = atomic._naming(folder, path, "tmp")
    assert (named.errno, named.strerror, named.filename) == (errno.EACCES, "Permission denied", str(path))


def test_a_temporary_that_cannot_be_made_names_the_target(tmp_path, monkeypatch):
    """Mutants of mkstemp's except: the error names the file to write, not the folder."""
    def full(**kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", kwargs["dir"])
    monkeypatch.setattr(atomic.tempfile, "mkstemp", full)
    with pytest.raises(OSError) as info:
        atomic.write_bytes(tmp_path / "f", b"")
    assert (info.value.errno, info.value.filename) == (errno.ENOSPC, str(tmp_path / "f"))


def test_fresh_dir_names_and_retries(tmp_path, monkeypatch):
    """Mutants of fresh_dir: prefix + 8 hex digits + suffix, an empty new folder, another name on a clash."""
    made = atomic.fresh_dir(tmp_path, ".p.", ".old")
    name = made.name
    assert made.parent == tmp_path and made.is_dir() and not any(made.iterdir())
    assert name.startswith(".p.") and name.endswith(".old") and len(name) == 3 + 8 + 4
    int(name[3:11], 16)
    assert atomic.fresh_dir(str(tmp_path), "q").name.startswith("q") and len(atomic.fresh_dir(tmp_path, "q").name) == 9
    (tmp_path / "xaaaa").mkdir()
    tokens = iter(["aaaa", "bbbb"])
    monkeypatch.setattr(atomic.secrets, "token_hex", lambda n: next(tokens) if n == 4 else "wrong")
    assert atomic.fresh_dir(tmp_path, "x") == tmp_path / "xbbbb"


def test_replace_dir_swaps_and_leaves_nothing_aside(tmp_path):
    """Mutants of replace_dir: an absent target is the renamed folder; an existing one is replaced whole and
    the old one removed (no `.target.*.old` left)."""
    target = tmp_path / "site"
    new = tmp_path / "new1"
    new.mkdir()
    (new / "a").write_text("1")
    atomic.replace_dir(new, target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site"] and (target / "a").read_text() == "1"
    new = tmp_path / "new2"
    new.mkdir()
    (new / "b").write_text("2")
    atomic.replace_dir(new, target)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site"]
    assert sorted(p.name for p in target.iterdir()) == ["b"]


# --------------------------------------------------------------------------- outputs.py


def test_prepare_output_folder_creates_and_refuses_in_one_line(tmp_path, monkeypatch):
    """Mutants of prepare_output_folder: a file refused, a nested folder made, the mkdir failure and an
    unwritable folder named with their words (os.access asked for W_OK | X_OK)."""
    out = tmp_path / "a" / "b"
    outputs.prepare_output_folder(out)
    assert out.is_dir()
    outputs.prepare_output_folder(out)  # exists: fine
    file = tmp_path / "file"
    file.write_text("")
    with pytest.raises(DataError) as info:
        outputs.prepare_output_folder(file)
    assert str(info.value) == f"{file}: output folder is a file"
    with pytest.raises(DataError) as info:
        outputs.prepare_output_folder(file / "sub")
    assert str(info.value) == f"{file / 'sub'}: cannot create the output folder: Not a directory"
    asked = []
    monkeypatch.setattr(os, "access", lambda p, m: asked.append(m) and False)
    with pytest.raises(DataError) as info:
        outputs.prepare_output_folder(out)
    assert str(info.value) == f"{out}: output folder is not writable" and asked == [os.W_OK | os.X_OK]


def test_prepare_output_folder_names_an_mkdir_error_without_words(tmp_path, monkeypatch):
    """Mutant of `exc.strerror or exc`."""
    def fail(self, **kwargs):
        raise OSError("odd")
    monkeypatch.setattr(Path, "mkdir", fail)
    with pytest.raises(DataError) as info:
        outputs.prepare_output_folder(tmp_path / "x")
    assert str(info.value) == f"{tmp_path / 'x'}: cannot create the output folder: odd"


def test_check_output_entries_names_the_first_entry_that_is_no_file(tmp_path):
    """Mutants of check_output_entries: files, folders and links pass, the first FIFO in name order is named;
    a folder that is not there (or a file) is not checked."""
    outputs.check_output_entries(tmp_path / "absent")
    (tmp_path / "file").write_text("")
    outputs.check_output_entries(tmp_path / "file")
    (tmp_path / "dir").mkdir()
    (tmp_path / "link").symlink_to(tmp_path / "dir")
    outputs.check_output_entries(tmp_path)
    _fifo(tmp_path / "z")
    _fifo(tmp_path / "b")
    with pytest.raises(DataError) as info:
        outputs.check_output_entries(tmp_path)
    assert str(info.value) == f"{tmp_path / 'b'}: is a FIFO{REFUSAL}"


def test_check_output_file_returns_where_to_write(tmp_path):
    """Mutants of check_output_file: a plain path itself (its folder made), a link's target (followed)."""
    path = tmp_path / "new" / "out.json"
    assert outputs.check_output_file(str(path)) == path and path.parent.is_dir()
    target = tmp_path / "real.json"
    target.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    assert outputs.check_output_file(link) == target
    dangling = tmp_path / "dangling.json"
    dangling.symlink_to(tmp_path / "sub" / "t.json")
    assert outputs.check_output_file(dangling) == tmp_path / "sub" / "t.json" and (tmp_path / "sub").is_dir()


def test_check_output_file_refusals_word_for_word(tmp_path):
    """Mutants of the refusals: a folder, a FIFO itself (check_replaceable's line as it is), a link to a
    FIFO (naming the link and its target), a loop of links."""
    (tmp_path / "dir").mkdir()
    fifo = _fifo(tmp_path / "fifo")
    link = tmp_path / "link"
    link.symlink_to(fifo)
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    to_dir = tmp_path / "to_dir"
    to_dir.symlink_to(tmp_path / "dir")
    cases = {tmp_path / "dir": f"{tmp_path / 'dir'}: is a folder, expected a file path",
             to_dir: f"{to_dir}: is a folder, expected a file path",
             fifo: f"{fifo}: is a FIFO{REFUSAL}",
             link: f"{link}: symbolic link to {fifo}, which is a FIFO{REFUSAL}",
             loop: f"{loop}: symbolic link that leads nowhere (a loop)"}
    for path, line in cases.items():
        with pytest.raises(DataError) as info:
            outputs.check_output_file(path)
        assert str(info.value) == line


# --------------------------------------------------------------------------- method/checkpoint.py


@pytest.mark.parametrize(("head", "kind"), [
    (b"PK\x03\x04rest", None), (b"\x80\x02}q", None), (b"", "an empty file"),
    (b"\x89HDF\r\n\x1a\n....", "an HDF5 file (a Keras checkpoint? lfbench convert-keras turns SubFocal's, "
                               "LFattNet's and EPINET's into weights)"),
    (b"\x93NUMPY\x01\x00", "a NumPy array file"),
    (b"\x89PNG\r\n", "an image"), (b"\xff\xd8\xff\xe0", "an image"), (b"GIF89a", "an image"),
    (b"II*\x00", "an image"), (b"MM\x00*", "an image"),
    (b"PF\n3 3\n", "a PFM disparity map"), (b"Pf\n3 3\n", "a PFM disparity map"),
    (b"  \n{\"a\": 1}", "a JSON file"), (b"[1, 2]", "a JSON file"),
    (b"weights\n", "a text file"), (b"abcde\xc3", "a text file"), (b"abcdef\xff", "a text file"),
    (b"abcde\xffxyz0", "a binary file of another kind"), (b"abcde\xffxyz", "a text file"),
    (b"ab\x00cd", "a binary file of another kind"), (b"PK\x03", "a text file"),
    (b"\xffabcdefgh", "a binary file of another kind"),
])
def test_sniff_names_every_kind(head, kind):
    """Mutants of sniff: every signature, the JSON / text / binary tests, the bound of a multi-byte character
    cut at the end of the head (an invalid byte 4 or fewer bytes before the end is still text)."""
    assert mck.sniff(head) == kind


def _torch_file(path: Path, payload) -> Path:
    torch.save(payload, path)
    return path


def test_check_checkpoint_file_refusals_word_for_word(tmp_path, monkeypatch):
    """Mutants of check_checkpoint_file: the size bound (8 GiB allowed, one byte more refused, in GiB with one
    decimal), the kind, a zip without torch's pickle, a damaged zip, the default `what`."""
    good = _torch_file(tmp_path / "w.pt", {"state_dict": {}})
    mck.check_checkpoint_file(good)
    json_file = tmp_path / "w.json"
    json_file.write_bytes(b'{"a": 1}')
    plain_zip = tmp_path / "z.pt"
    with zipfile.ZipFile(plain_zip, "w") as z:
        z.writestr("archive/data.txt", "x")
    broken = tmp_path / "broken.pt"
    broken.write_bytes(b"PK\x03\x04" + b"\x00" * 40)
    cases = {json_file: f"{json_file}: a JSON file, not a torch checkpoint",
             plain_zip: f"{plain_zip}: a zip archive, not a readable torch checkpoint",
             broken: f"{broken}: a damaged or incomplete file, not a readable torch checkpoint",
             tmp_path / "none.pt": f"{tmp_path / 'none.pt'}: checkpoint file not found"}
    for path, line in cases.items():
        with pytest.raises(DataError) as info:
            mck.check_checkpoint_file(path)
        assert str(info.value) == line
    real_size = os.path.getsize
    monkeypatch.setattr(os.path, "getsize", lambda p: mck.MAX_CHECKPOINT_BYTES if Path(p) == good else real_size(p))
    mck.check_checkpoint_file(good, "weights file")
    monkeypatch.setattr(os.path, "getsize", lambda p: mck.MAX_CHECKPOINT_BYTES + 1)
    with pytest.raises(DataError) as info:
        mck.check_checkpoint_file(good, "weights file")
    assert str(info.value) == f"{good}: weights file of 8.0 GiB, larger than the 8 GiB lfbench reads"
    monkeypatch.setattr(os.path, "getsize", lambda p: 50 * 1024**3 + 1024**3 // 4)
    with pytest.raises(DataError) as info:
        mck.check_checkpoint_file(good)
    assert str(info.value) == f"{good}: checkpoint file of 50.2 GiB, larger than the 8 GiB lfbench reads"


def test_zip_problem_of_an_empty_or_unreadable_archive(tmp_path, monkeypatch):
    """Mutants of _zip_problem's except branch: an empty file and a damaged one in their words; a member whose
    name ends in data.pkl anywhere makes it torch's."""
    empty = tmp_path / "e"
    empty.write_bytes(b"")
    assert mck._zip_problem(empty) == "an empty file"
    junk = tmp_path / "j"
    junk.write_bytes(b"junk")
    assert mck._zip_problem(junk) == "a damaged or incomplete file"
    ok = tmp_path / "ok.zip"
    with zipfile.ZipFile(ok, "w") as z:
        z.writestr("x/other.txt", "")
        z.writestr("x/data.pkl", "")
    assert mck._zip_problem(ok) is None

    def unreadable(path):
        raise OSError("io")
    monkeypatch.setattr(mck.zipfile, "ZipFile", unreadable)
    assert mck._zip_problem(junk) == "a damaged or incomplete file"


def test_read_checkpoint_refusals_word_for_word(tmp_path):
    """Mutants of read_checkpoint: the payload returned, a non-dict named by its type and `what`, Python
    objects refused (weights_only), a damaged torch zip and a damaged legacy file in their words (not called
    Python objects)."""
    good = _torch_file(tmp_path / "w.pt", {"a": torch.ones(2)})
    payload = mck.read_checkpoint(good)
    assert list(payload) == ["a"] and payload["a"].device.type == "cpu"
    listed = _torch_file(tmp_path / "l.pt", [1, 2])
    objects = _torch_file(tmp_path / "o.pt", {"x": SimpleNamespace(a=1)})
    damaged = tmp_path / "d.pt"
    with zipfile.ZipFile(damaged, "w") as z:
        z.writestr("archive/data.pkl", b"\x80\x02garbage")
    legacy = tmp_path / "g.pt"  # torch's legacy (non-zip) format begins with a pickle: opcodes no plain value has
    legacy.write_bytes(b"\x80\x02garbage\xff\x00" * 3)
    cases = {(listed, "weights file"): f"{listed}: a torch file holding a list, not an lfbench weights file (a dict)",
             (listed, None): f"{listed}: a torch file holding a list, not an lfbench checkpoint file (a dict)",
             (objects, None): f"{objects}: holds Python objects beyond tensors and plain values; lfbench loads "
                              "weights only and does not unpickle it",
             (damaged, None): f"{damaged}: a damaged torch file, not a readable torch checkpoint",
             (legacy, None): f"{legacy}: a damaged or incomplete file, not a readable torch checkpoint"}
    for (path, what), line in cases.items():
        with pytest.raises(DataError) as info:
            mck.read_checkpoint(path) if what is None else mck.read_checkpoint(path, what)
        assert str(info.value) == line


def test_a_weights_file_is_checked_before_torch_reads_it(tmp_path, monkeypatch):
    """Mutants that drop check_checkpoint_file from read_checkpoint or pass another `what`."""
    monkeypatch.setattr(torch, "load", lambda *a, **k: pytest.fail("torch.load reached"))
    text = tmp_path / "t.pt"
    text.write_text("hello\n")
    with pytest.raises(DataError) as info:
        mck.read_checkpoint(text, "weights file")
    assert str(info.value) == f"{text}: a text file, not a torch checkpoint"
    with pytest.raises(DataError) as info:
        mck.read_checkpoint(tmp_path / "missing.pt", "weights file")
    assert str(info.value) == f"{tmp_path / 'missing.pt'}: weights file not found"


def test_training_load_checks_the_format(tmp_path):
    """Mutants of training.checkpoint.load: the format compared only when one is expected, its line."""
    path = _torch_file(tmp_path / "c.pt", {"format": "a"})
    assert tck.load(path) == {"format": "a"} and tck.load(path, "a") == {"format": "a"}
    for payload, line in (({"format": "a"}, "not a b file (format 'a')"), ({}, "not a b file (format None)")):
        _torch_file(path, payload)
        with pytest.raises(DataError) as info:
            tck.load(path, "b")
        assert str(info.value) == f"{path}: {line}"


# --------------------------------------------------------------------------- ablation/cell.py


def _task(cell_dir: Path, fingerprint: str = "F", eval_fingerprint: str = "E") -> cell.CellTask:
    return cell.CellTask(cell_id="interval=1", values={}, config={}, fingerprint=fingerprint,
                         eval_fingerprint=eval_fingerprint, cell_dir=str(cell_dir), data_links={}, stage1_dir=None,
                         scenes=(), evaluation=None, threads=1)


def _finished_cell(cell_dir: Path) -> dict:
    """A cell folder with final.pt, results.json and a marker recording their digests."""
    cell_dir.mkdir()
    _torch_file(cell_dir / "final.pt", {"state_dict": {"w": torch.arange(3.0)}})
    (cell_dir / "results.json").write_text('{"records": []}')
    marker = {"fingerprint": "F", "eval_fingerprint": "E",
              "final_sha256": tck.state_sha256({"w": torch.arange(3.0)}),
              "results_sha256": hashlib.sha256(b'{"records": []}').hexdigest()}
    (cell_dir / cell.MARKER).write_text(json.dumps(marker))
    return marker


def test_read_marker_is_a_dict_or_none(tmp_path):
    """Mutants of read_marker: absent, unreadable and non-dict markers are None; the marker file's name."""
    assert cell.read_marker(tmp_path) is None
    (tmp_path / "cell.json").write_text("{broken")
    assert cell.read_marker(tmp_path) is None
    (tmp_path / "cell.json").write_text("[1]")
    assert cell.read_marker(str(tmp_path)) is None
    (tmp_path / "cell.json").write_text('{"a": 1}')
    assert cell.read_marker(tmp_path) == {"a": 1}


def test_recorded_mismatch_names_the_file_that_differs(tmp_path):
    """Mutants of recorded_mismatch and weights_digest: which file, which key, results first, the digest of the
    state dict (not of the file's bytes), a weights file without a state dict, a missing file's line."""
    cell_dir = tmp_path / "c"
    marker = _finished_cell(cell_dir)
    assert cell.recorded_mismatch(cell_dir, marker) is None
    assert cell.weights_digest(cell_dir / "final.pt") == marker["final_sha256"]
    assert cell.recorded_mismatch(cell_dir, {**marker, "final_sha256": "0"}) == \
        f"{cell_dir / 'final.pt'} is not the file the cell recorded (final_sha256)"
    assert cell.recorded_mismatch(cell_dir, {**marker, "final_sha256": "0", "results_sha256": "0"}) == \
        f"{cell_dir / 'results.json'} is not the file the cell recorded (results_sha256)"
    _torch_file(cell_dir / "final.pt", {"state_dict": [1]})
    assert cell.recorded_mismatch(cell_dir, marker) == f"{cell_dir / 'final.pt'}: not exported weights (no state_dict)"
    (cell_dir / "results.json").unlink()
    assert cell.recorded_mismatch(cell_dir, marker) == f"{cell_dir / 'results.json'}: cell results not found"
    with pytest.raises(DataError) as info:
        cell.weights_digest(cell_dir / "final.pt")
    assert str(info.value) == f"{cell_dir / 'final.pt'}: not exported weights (no state_dict)"


def test_is_done_decides_re_use_from_the_marker(tmp_path, caplog):
    """Mutants of is_done: no marker, another training config (SpecError word for word), other evaluation
    settings, a changed file (logged only with warn, in its words), all recorded: done."""
    cell_dir = tmp_path / "c"
    assert cell.is_done(_task(cell_dir)) is False
    marker = _finished_cell(cell_dir)
    assert cell.is_done(_task(cell_dir)) is True
    with pytest.raises(SpecError) as info:
        cell.is_done(_task(cell_dir, fingerprint="G"))
    assert str(info.value) == (f"cell interval=1 in {cell_dir} was trained with another config; use another --out "
                               "folder (or delete that cell folder)")
    assert cell.is_done(_task(cell_dir, eval_fingerprint="other")) is False
    (cell_dir / "cell.json").write_text(json.dumps({**marker, "results_sha256": "0"}))
    with caplog.at_level(logging.INFO, logger="lfbench.ablation.cell"):
        assert cell.is_done(_task(cell_dir), warn=False) is False
        assert caplog.records == []
        assert cell.is_done(_task(cell_dir)) is False
    assert [(r.levelno, r.getMessage()) for r in caplog.records] == [
        (logging.WARNING, f"cell interval=1: {cell_dir / 'results.json'} is not the file the cell recorded "
                          "(results_sha256); the cell is re-made")]


def test_link_data_folder_makes_relative_links_and_re_points_wrong_ones(tmp_path):
    """Mutants of link_data_folder: a new link is relative (a moved folder resumes) and its folder made; a
    right link is kept as it is (absolute too); a wrong or dangling link is re-pointed; a real folder kept."""
    target = tmp_path / "shared" / "data" / "synth"
    target.mkdir(parents=True)
    link = tmp_path / "cells" / "a" / "data" / "synth"
    cell.link_data_folder(link, target)
    assert os.readlink(link) == "../../../shared/data/synth" and link.resolve() == target
    absolute = tmp_path / "abs"
    absolute.symlink_to(target)
    cell.link_data_folder(absolute, target)
    assert os.readlink(absolute) == str(target)
    other = tmp_path / "other"
    other.mkdir()
    for wrong in (other, tmp_path / "gone"):
        link.unlink()
        link.symlink_to(wrong)
        cell.link_data_folder(link, target)
        assert os.readlink(link) == "../../../shared/data/synth"
    loop = tmp_path / "loop"
    loop.symlink_to(loop)
    cell.link_data_folder(loop, target)
    assert os.readlink(loop) == "shared/data/synth"
    real = tmp_path / "real"
    real.mkdir()
    cell.link_data_folder(real, target)
    assert real.is_dir() and not real.is_symlink()


def test_link_data_folder_without_symlinks_links_nothing(tmp_path, monkeypatch):
    """Mutant of the suppress(OSError) around symlink_to: no symlink support is no error."""
    def refuse(self, *a, **k):
        raise OSError(errno.EPERM, "Operation not permitted")
    monkeypatch.setattr(Path, "symlink_to", refuse)
    cell.link_data_folder(tmp_path / "x" / "link", tmp_path)
    assert not (tmp_path / "x" / "link").exists() and (tmp_path / "x").is_dir()


# --------------------------------------------------------------------------- executor.py


def test_run_marked_holds_the_label_while_the_item_runs(tmp_path, monkeypatch):
    """Mutants of run_marked: the mark is the worker's pid file holding the label during fn, removed after
    (also on an error); no marks folder, no mark; the kill hook only for its own label."""
    kills = []
    monkeypatch.setattr(os, "kill", lambda pid, sig: kills.append((pid, sig)))
    monkeypatch.setenv(executor.KILL_WORKER_ENV, "other")
    monkeypatch.setattr(executor, "_marks", tmp_path)
    seen = []

    def fn(item):
        seen.append(sorted((p.name, p.read_text(encoding="utf-8")) for p in tmp_path.iterdir()))
        if item == "bad":
            raise ValueError(item)
        return item * 2
    assert executor.run_marked(fn, "scene é", 21) == 42
    with pytest.raises(ValueError):
        executor.run_marked(fn, "scene b", "bad")
    assert seen == [[(str(os.getpid()), "scene é")], [(str(os.getpid()), "scene b")]]
    assert list(tmp_path.iterdir()) == [] and kills == []
    executor.run_marked(fn, "other", 1)
    assert kills == [(os.getpid(), signal.SIGKILL)]
    monkeypatch.setattr(executor, "_marks", None)
    assert executor.run_marked(lambda x: x, "a", 5) == 5 and list(tmp_path.iterdir()) == []


def test_init_worker_sets_marks_signal_gpu_and_threads(tmp_path, monkeypatch):
    """Mutants of init_worker: the marks folder and the SIGTERM handler only with marks, the GPU from the
    queue (None: CUDA_VISIBLE_DEVICES left alone), torch's threads only when given."""
    handlers, threads = [], []
    monkeypatch.setattr(signal, "signal", lambda sig, h: handlers.append((sig, h)))
    monkeypatch.setattr(torch, "set_num_threads", threads.append)
    monkeypatch.setattr(executor, "_marks", None)
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES", raising=False)
    executor.init_worker(None)
    assert (executor._marks, handlers, threads, os.environ.get("CUDA_VISIBLE_DEVICES")) == (None, [], [], None)
    queue = SimpleNamespace(get=lambda: None)
    executor.init_worker(3, queue, str(tmp_path))
    assert executor._marks == tmp_path and isinstance(executor._marks, Path)
    assert handlers == [(signal.SIGTERM, executor._stopped_by_pool)] and threads == [3]
    assert "CUDA_VISIBLE_DEVICES" not in os.environ
    executor.init_worker(None, SimpleNamespace(get=lambda: "1"))
    assert os.environ["CUDA_VISIBLE_DEVICES"] == "1" and threads == [3]


def test_a_dead_worker_is_named_by_the_marks_left(tmp_path):
    """Mutants of ProcessPool._died: the pool shut down (waiting, futures cancelled), the marks' labels sorted
    and quoted with ' or ', the label that saw it when no mark is left or no folder."""
    calls = []
    pool = SimpleNamespace(shutdown=lambda **k: calls.append(k))
    (tmp_path / "2").write_text("scene b", encoding="utf-8")
    (tmp_path / "1").write_text("scene a", encoding="utf-8")
    died = executor.WORKER_DIED
    error = executor.ProcessPool._died(pool, tmp_path, "seen", died)
    assert type(error) is RunFailed and calls == [{"wait": True, "cancel_futures": True}]
    assert str(error) == ("a worker process died (killed, or out of memory) while running 'scene a' or 'scene b': "
                          "run the same command again")
    for p in tmp_path.iterdir():
        p.unlink()
    (tmp_path / "3").write_bytes(b"bad \xff")
    assert str(executor.ProcessPool._died(pool, tmp_path, "seen", "{names}")) == "'bad \ufffd'"
    (tmp_path / "3").unlink()
    assert str(executor.ProcessPool._died(pool, tmp_path, "seen", "{names}")) == "'seen'"
    assert str(executor.ProcessPool._died(pool, tmp_path / "gone", "seen", "x {names}")) == "x 'seen'"


def test_replace_dir_moves_the_old_folder_aside_under_a_hidden_name(tmp_path, monkeypatch):
    """Mutants of the aside folder's name (prefix `.<target>.`, suffix `.old`): the old folder goes into
    `.site.<8 hex>.old/site` beside the target."""
    moves = []
    real = os.replace
    monkeypatch.setattr(os, "replace", lambda a, b: (moves.append((Path(a), Path(b))), real(a, b))[1])
    target = tmp_path / "site"
    target.mkdir()
    new = tmp_path / "new"
    new.mkdir()
    atomic.replace_dir(new, target)
    (aside_src, aside), (finished, to) = moves
    assert (aside_src, finished, to) == (target, new, target) and aside.name == "site"
    name = aside.parent.name
    assert aside.parent.parent == tmp_path and name.startswith(".site.") and name.endswith(".old")
    assert len(name) == len(".site.") + 8 + len(".old")


def test_replace_dir_succeeds_when_the_old_folder_cannot_be_removed(tmp_path, monkeypatch):
    """Mutants of `rmtree(old, ignore_errors=True)`: a leftover old copy is no error (the swap is done)."""
    target = tmp_path / "site"
    target.mkdir()
    (target / "keep").write_text("old")
    new = tmp_path / "new"
    new.mkdir()
    real = os.unlink

    def refuse(path, *a, **k):
        if os.fspath(path).endswith("keep"):
            raise PermissionError(errno.EACCES, "Permission denied", path)
        return real(path, *a, **k)
    monkeypatch.setattr(os, "unlink", refuse)
    atomic.replace_dir(new, target)
    assert target.is_dir() and not (target / "keep").exists()


def test_check_checkpoint_file_reads_only_the_head(tmp_path):
    """Mutant `f.read(None)`: the kind is told from the first 512 bytes (text there, a NUL byte after them)."""
    path = tmp_path / "w.pt"
    path.write_bytes(b"a" * 512 + b"\x00")
    with pytest.raises(DataError) as info:
        mck.check_checkpoint_file(path)
    assert str(info.value) == f"{path}: a text file, not a torch checkpoint"


def test_link_data_folder_re_points_an_absolute_link_to_a_target_not_there_yet(tmp_path):
    """Mutants of `resolve(strict=True)`: a link that leads nowhere is replaced by the relative one, even when
    it names the target (an absolute link to scenes not generated yet)."""
    target = tmp_path / "shared" / "synth"
    link = tmp_path / "cell" / "synth"
    link.parent.mkdir()
    link.symlink_to(target)
    cell.link_data_folder(link, target)
    assert os.readlink(link) == "../shared/synth"


def test_run_marked_when_the_mark_is_already_gone(tmp_path, monkeypatch):
    """Mutants of `unlink(missing_ok=True)`: a mark removed meanwhile (the pool's SIGTERM handler removes it
    first) is no error; the item's result comes back."""
    monkeypatch.setattr(executor, "_marks", tmp_path)

    def fn(item):
        for p in tmp_path.iterdir():
            p.unlink()
        return item + 1
    assert executor.run_marked(fn, "a", 1) == 2


def test_read_weights_refusals_word_for_word(tmp_path):
    """Mutants of read_weights, is_weights and _is_name: a training checkpoint, a payload without a state dict
    or a config, another network named (a registry-style name shown, 40 characters at most, ASCII letters,
    digits and `_-.`, one character included; any other text not shown), the same network, a name of
    `same_network`, no name stored."""
    path = tmp_path / "w.pt"
    weights = {"state_dict": {}, "config": {}}
    checks = [({"format": mck.CHECKPOINT_FORMAT, **weights}, "tinycnn",
               "a training checkpoint (the resume state of lfbench train), not exported weights: give the run's "
               "final.pt, best.pt or stage*.pt"),
              ({"state_dict": {}}, None, "a torch checkpoint without 'state_dict' and 'config': not lfbench weights"),
              ({"config": {}, "state_dict": []}, None,
               "a torch checkpoint without 'state_dict' and 'config': not lfbench weights"),
              ({"state_dict": {}, "config": []}, None,
               "a torch checkpoint without 'state_dict' and 'config': not lfbench weights"),
              ({**weights, "method": "sub-focal_2.0"}, "tinycnn",
               "a sub-focal_2.0 checkpoint, not tinycnn (run it as sub-focal_2.0:weights=...)"),
              ({**weights, "method": "a" * 40}, "tinycnn", f"a {'a' * 40} checkpoint, not tinycnn (run it as "
                                                           f"{'a' * 40}:weights=...)"),
              ({**weights, "method": "x"}, "tinycnn", "a x checkpoint, not tinycnn (run it as x:weights=...)"),
              ({**weights, "method": "a" * 41}, "tinycnn", "a checkpoint of another network, not tinycnn"),
              ({**weights, "method": "bad name"}, "tinycnn", "a checkpoint of another network, not tinycnn"),
              ({**weights, "method": "é"}, "tinycnn", "a checkpoint of another network, not tinycnn")]
    for payload, network, line in checks:
        _torch_file(path, payload)
        with pytest.raises(DataError) as info:
            mck.read_weights(path, network)
        assert str(info.value) == f"{path}: {line}"
    for payload, network, same in (({**weights, "method": "tinycnn"}, "tinycnn", ()),
                                   ({**weights, "method": "lfattnet"}, "subfocal", ("x", "lfattnet")),
                                   ({**weights, "method": "other"}, None, ()),
                                   ({**weights, "method": ""}, "tinycnn", ()),
                                   ({**weights, "method": 3}, "tinycnn", ()), (weights, "tinycnn", ())):
        _torch_file(path, payload)
        assert mck.read_weights(path, network, same) == payload
    _torch_file(path, [1])
    with pytest.raises(DataError) as info:
        mck.read_weights(path)
    assert str(info.value) == f"{path}: a torch file holding a list, not an lfbench weights file (a dict)"
    assert not mck._is_name("")


def test_python_objects_stay_refused_when_torch_is_told_to_unpickle(tmp_path, monkeypatch):
    """Mutants that leave `weights_only` to torch's default (None, dropped): TORCH_FORCE_NO_WEIGHTS_ONLY_LOAD
    turns that default off, an explicit weights_only=True stays."""
    objects = _torch_file(tmp_path / "o.pt", {"x": SimpleNamespace(a=1)})
    monkeypatch.setenv("TORCH_FORCE_NO_WEIGHTS_ONLY_LOAD", "1")
    with pytest.raises(DataError) as info:
        mck.read_checkpoint(objects)
    assert str(info.value).startswith(f"{objects}: holds Python objects beyond tensors and plain values")


_AS_CUDA = []


def _tag_as_cuda(obj):
    """torch.save's location tag of a CPU storage while a test asks for it: 'cuda:0' (a file written on a GPU)."""
    return "cuda:0" if _AS_CUDA and obj.device.type == "cpu" else None


torch.serialization.register_package(0, _tag_as_cuda, lambda obj, location: None)


def test_weights_saved_on_a_gpu_load_on_the_cpu(tmp_path):
    """Mutants of `map_location="cpu"` (None, dropped): a file whose tensors were saved from a GPU loads on
    a machine without one, its tensors on the CPU."""
    _AS_CUDA.append(True)
    try:
        path = _torch_file(tmp_path / "gpu.pt", {"w": torch.arange(3.0)})
    finally:
        _AS_CUDA.clear()
    payload = mck.read_checkpoint(path)
    assert payload["w"].device.type == "cpu" and payload["w"].tolist() == [0.0, 1.0, 2.0]
