"""Whole output sets: a run's files appear in its folder together or not at all.

A run writes every output into a staging folder inside OUT (``.lfbench-stage.<pid>.<random>``),
then commits: the new manifest (``.lfbench-outputs.json``: the names of the set) is written into the
staging folder, a journal (``.lfbench-commit.json``, written atomically) names the staged entries
and the previous set's entries to drop (the commit point); then the entries are moved into OUT one
by one, the previous ones into the staging folder's trash, and the manifest last (renames on one file
system: nothing is allocated after the commit point, so a full disk cannot stop a commit half way);
the journal goes last. A kill before the journal leaves OUT as it was (the next run deletes the dead
staging folder); a kill after it is rolled forward by the next run, and readers refuse a folder whose
journal is pending (:func:`check_complete`). A write error (disk full, read-only folder) while
staging is one :class:`~lfbench.utils.errors.LFBenchError` naming the file, and OUT is untouched.

Several writers can share one folder as long as each names its own set (``name``): a training run's
exports (``final.pt``, ``summary.json``) and an ablation cell's scores live in one folder, each set
with its own journal and manifest (``.lfbench-commit.<name>.json``, ``.lfbench-outputs.<name>.json``).

Journals and manifests are read back from a folder anyone may have written to, so they are untrusted:
before anything is moved or deleted, every name in them must be one lfbench writes (the staging
folder a direct child named ``.lfbench-stage.*``; entries plain top-level names, not hidden, without
path separators; no symbolic link in what is staged), else one DataError naming the file and nothing
is touched.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import stat
import tempfile
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

from lfbench.utils.atomic import check_replaceable, write_text
from lfbench.utils.errors import DataError, LFBenchError
from lfbench.utils.jsonfile import parse_json

__all__ = ["JOURNAL", "MANIFEST", "OutputSet", "check_complete", "check_output_entries", "check_output_file",
           "check_within", "prepare_output_folder", "read_manifest", "recover", "staged_outputs"]

STAGE_PREFIX = ".lfbench-stage."
JOURNAL = ".lfbench-commit.json"
MANIFEST = ".lfbench-outputs.json"
_TRASH = ".trash"
_SET_NAME = re.compile(r"[a-z][a-z0-9_]{0,31}")
_JOURNAL_NAME = re.compile(r"\.lfbench-commit(?:\.([a-z][a-z0-9_]{0,31}))?\.json")
_MAX_BOOK_BYTES = 1024**2  # a journal or manifest lists top-level names: far below this
# temporaries a killed run leaves (suffix .tmp / .old): the demo's data and HTML report, earlier versions'
# maps and figures
_OLD_TEMPORARIES = (".data.", ".figures.", ".html.", ".maps.")
_BOOK_TEMPORARIES = (".lfbench-commit", ".lfbench-outputs")  # atomic_open's temporaries of journals, manifests


def journal_name(name: str | None = None) -> str:
    """The journal of the set ``name`` (None: the folder's main set)."""
    return JOURNAL if name is None else f".lfbench-commit.{_check_set_name(name)}.json"


def manifest_name(name: str | None = None) -> str:
    """The manifest of the set ``name`` (None: the folder's main set)."""
    return MANIFEST if name is None else f".lfbench-outputs.{_check_set_name(name)}.json"


def _check_set_name(name: str) -> str:
    if not _SET_NAME.fullmatch(name):
        raise ValueError(f"not a set name: {name!r}")
    return name


class OutputSet:
    """A run's staging folder in ``out``; :meth:`commit` moves the named entries into ``out``.

    ``name``: which set of the folder this run replaces (None: the main one)."""

    def __init__(self, out: str | Path, name: str | None = None) -> None:
        self.out = Path(out)
        self.name = name
        self.created = not self.out.exists()  # removed again by abort() when the run writes nothing
        prepare_output_folder(self.out)
        check_output_entries(self.out)
        recover(self.out)
        read_manifest(self.out, name)  # a manifest that is not lfbench's is refused before the work
        try:
            self.stage = Path(tempfile.mkdtemp(prefix=f"{STAGE_PREFIX}{os.getpid()}.", dir=self.out))
        except OSError as exc:
            raise DataError(f"cannot write into the output folder: {exc.strerror or exc}", self.out) from None
        self.committed = False  # True once the journal is written: from then on a failure rolls forward

    def final(self, staged: str | Path) -> Path:
        """Where a staged path lands in ``out``."""
        return self.out / Path(staged).relative_to(self.stage)

    def commit(self, entries: Sequence[str], keep: Iterable[str] = ()) -> None:
        """Move the staged top-level ``entries`` (names in the staging folder) into ``out`` as one set,
        dropping the entries of the previous set that this one does not write, except those named in
        ``keep`` (the previous set's files this run read and leaves as they are: they stay in the set)."""
        entries = sorted(set(entries))
        bad = [e for e in entries if not _is_entry_name(e)]
        missing = [e for e in entries if not os.path.lexists(self.stage / e)]
        if bad or missing:
            raise RuntimeError(f"staged outputs not valid: {bad + missing}")
        previous = read_manifest(self.out, self.name)
        kept = sorted(k for k in set(keep) - set(entries) if k in previous and os.path.lexists(self.out / k))
        _check_staged(self.stage, entries, self.out / journal_name(self.name))
        write_text(self.stage / manifest_name(self.name), _manifest_text(entries + kept))
        (self.stage / _TRASH).mkdir()
        journal = {"stage": self.stage.name, "entries": entries,
                   "remove": sorted(set(previous) - set(entries) - set(kept))}
        write_text(self.out / journal_name(self.name), json.dumps(journal, indent=1) + "\n")  # the commit point
        self.committed = True
        _roll_forward(self.out, _Journal(self.stage.name, tuple(entries), tuple(journal["remove"]),
                                         journal_name(self.name), manifest_name(self.name)))

    def commit_written(self, paths: Iterable[str | Path], keep: Iterable[str] = ()) -> list[Path]:
        """:meth:`commit` the top-level entries that hold ``paths`` (files or folders written in the staging
        folder); returns where ``paths`` land in ``out``, in their order."""
        paths = [Path(p) for p in paths]
        self.commit([p.relative_to(self.stage).parts[0] for p in paths], keep)
        return [self.final(p) for p in paths]

    def abort(self) -> None:
        """Drop the staging folder (``out`` stays as it was), unless the commit point was passed: then
        the staging folder and journal stay for the next run to roll forward."""
        if not self.committed:
            shutil.rmtree(self.stage, ignore_errors=True)
            if self.created:
                with contextlib.suppress(OSError):
                    self.out.rmdir()  # only if empty


def prepare_output_folder(out: Path) -> None:
    """Create ``out`` (DataError when it is a file or cannot be created): checked before any work."""
    if out.exists() and not out.is_dir():
        raise DataError("output folder is a file", out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DataError(f"cannot create the output folder: {exc.strerror or exc}", out) from None
    if not os.access(out, os.W_OK | os.X_OK):
        raise DataError("output folder is not writable", out)


def check_output_entries(out: Path) -> None:
    """DataError naming the first entry at the top of the output folder ``out`` that a set's commit could
    replace but that is not a regular file, folder or symbolic link (a device, FIFO or socket): lfbench
    replaces only what it could have written. Checked before the work."""
    if not out.is_dir():
        return
    for entry in sorted(out.iterdir()):
        if not stat.S_ISDIR(os.lstat(entry).st_mode):
            check_replaceable(entry)


def check_output_file(path: str | Path) -> Path:
    """The file a command writes when told to write ``path`` (``--out FILE``, ``--json FILE``, a golden file):
    ``path`` itself, or, for a symbolic link, the file the link leads to (followed, so that the link stays and
    its target is updated). DataError naming ``path`` unless that is a regular file or absent (never a folder,
    a device such as a copy of ``/dev/null``, a FIFO or a socket: :func:`lfbench.utils.atomic.check_replaceable`)
    and its folder creatable and writable. Checked before the work, so that minutes of computing are not lost
    to a typo, and nothing but a regular file is ever replaced; write to the path it returns."""
    path = Path(path)
    target = path
    if path.is_symlink():
        try:
            target = path.resolve(strict=False)
        except (OSError, RuntimeError):  # a loop of links
            raise DataError("symbolic link that leads nowhere (a loop)", path) from None
    if target.is_dir():
        raise DataError("is a folder, expected a file path", path)
    try:
        check_replaceable(target)
    except DataError as exc:
        if target == path:
            raise
        raise DataError(f"symbolic link to {target}, which {exc.args[0]}", path) from None
    prepare_output_folder(target.parent)
    return target


@contextlib.contextmanager
def staged_outputs(out: str | Path, name: str | None = None) -> Iterator[OutputSet]:
    """An :class:`OutputSet` for ``out``; on any exception its staging folder is removed (``out`` is
    untouched) and a write error becomes one LFBenchError naming the file."""
    outputs = OutputSet(out, name)
    try:
        yield outputs
    except OSError as exc:
        outputs.abort()
        where = Path(exc.filename) if exc.filename else outputs.out
        with contextlib.suppress(ValueError):
            where = outputs.final(where)
        if outputs.committed:
            raise LFBenchError(f"cannot finish the commit: {exc.strerror or exc} (the next run into "
                               f"{outputs.out} finishes it)", where) from None
        raise LFBenchError(f"cannot write: {exc.strerror or exc} (nothing written to {outputs.out})", where) from None
    except BaseException:
        outputs.abort()
        raise


def recover(out: Path) -> None:
    """Finish the commits that killed runs left half done, and delete staging folders of dead runs and
    temporaries of earlier versions. Every journal is checked before anything is touched (DataError
    naming the journal when it is not one lfbench wrote)."""
    if not out.is_dir():
        return
    journals = [_read_journal(out, p.name) for p in sorted(out.iterdir()) if _JOURNAL_NAME.fullmatch(p.name)]
    for journal in journals:
        _roll_forward(out, journal)
    for entry in out.iterdir():
        name = entry.name
        if (name.startswith(STAGE_PREFIX) and not _alive(name)) or (
                name.startswith(_OLD_TEMPORARIES) and name.endswith((".tmp", ".old"))):
            _remove(entry)
        elif name.startswith(_BOOK_TEMPORARIES) and name.endswith(".tmp"):  # a journal write cut by a kill
            _remove(entry)


def check_complete(folder: Path) -> None:
    """DataError when ``folder`` holds a set whose commit was interrupted (its files may mix two runs)."""
    pending = sorted(p.name for p in folder.iterdir() if _JOURNAL_NAME.fullmatch(p.name)) if folder.is_dir() else []
    if pending:
        raise DataError(f"an interrupted run left this folder half updated ({pending[0]}); run the command again "
                        "to finish it", folder)


def check_within(path: str | Path, folder: str | Path, what: str = "the folder it was read from") -> None:
    """DataError unless ``path`` really (symbolic links followed) lies inside ``folder``: a path read
    back from an output folder never leads out of it."""
    path, folder = Path(path), Path(folder)
    try:
        inside = path.resolve(strict=True).is_relative_to(folder.resolve(strict=True))
    except (OSError, RuntimeError):  # a dangling link or a loop
        raise DataError("broken symbolic link or unreadable path", path) from None
    if not inside:
        raise DataError(f"symbolic link leading out of {what} (not allowed)", path)


def read_manifest(out: Path, name: str | None = None) -> list[str]:
    """The entries of the set ``name`` in ``out`` (empty when it has none); DataError naming the manifest
    when it is not one lfbench wrote."""
    path = Path(out) / manifest_name(name)
    if not os.path.lexists(path):
        return []
    return _manifest_entries(path, "output manifest")


# --------------------------------------------------------------------------- journals, checked

@dataclass(frozen=True)
class _Journal:
    stage: str
    entries: tuple[str, ...]
    remove: tuple[str, ...]
    journal: str  # its file name in OUT
    manifest: str  # the file name of its set's manifest


def _is_entry_name(name: object) -> bool:
    """A plain top-level name lfbench writes: not hidden (its own files are), no path separator."""
    return (isinstance(name, str) and 0 < len(name.encode("utf-8", "surrogateescape")) <= 255
            and not name.startswith(".") and not any(c in name for c in "/\\\0"))


def _names(value: object) -> bool:
    """Whether ``value`` is a list of distinct entry names."""
    return isinstance(value, list) and all(_is_entry_name(n) for n in value) and len(set(value)) == len(value)


def _refused(path: Path, why: str) -> DataError:
    return DataError(f"{why}: not a file lfbench wrote; nothing was changed (remove it if this folder is yours "
                     "and the run that wrote it is not running)", path)


def _read_book(path: Path, what: str) -> object:
    """A journal or manifest, parsed strictly; DataError naming it when it is not a regular file of JSON."""
    try:
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode):
            raise _refused(path, f"{what} is not a regular file")
        if st.st_size > _MAX_BOOK_BYTES:
            raise _refused(path, f"{what} is larger than {_MAX_BOOK_BYTES // 1024} KiB")
        raw = path.read_bytes()
    except OSError as exc:
        raise DataError(f"cannot read {what}: {exc.strerror or exc}", path) from None
    try:
        return parse_json(raw.decode("utf-8"), path, what)
    except (UnicodeDecodeError, DataError):
        raise _refused(path, f"{what} is not valid UTF-8 JSON") from None


def _manifest_entries(path: Path, what: str) -> list[str]:
    data = _read_book(path, what)
    entries = data.get("entries") if isinstance(data, dict) and set(data) == {"entries"} else None
    if not _names(entries):
        raise _refused(path, f"{what} must list plain top-level names (no path, not hidden)")
    return list(entries)


def _read_journal(out: Path, file_name: str) -> _Journal:
    """The journal ``out/file_name`` with every name in it checked (nothing is touched here)."""
    path = out / file_name
    set_name = _JOURNAL_NAME.fullmatch(file_name).group(1)
    data = _read_book(path, "commit journal")
    if not (isinstance(data, dict) and set(data) == {"stage", "entries", "remove"}):
        raise _refused(path, "commit journal must hold exactly stage, entries and remove")
    stage, entries, remove = data["stage"], data["entries"], data["remove"]
    if not (isinstance(stage, str) and stage.startswith(STAGE_PREFIX) and _is_plain(stage)):
        raise _refused(path, f"commit journal: stage must be a folder {STAGE_PREFIX}* in the output folder")
    for key, names in (("entries", entries), ("remove", remove)):
        if not _names(names):
            raise _refused(path, f"commit journal: {key} must list plain top-level names (no path, not hidden)")
    if set(entries) & set(remove):
        raise _refused(path, "commit journal: a name is both an entry and to be removed")
    try:
        mode = os.lstat(out / stage).st_mode
    except FileNotFoundError:
        raise DataError(f"commit journal: its staging folder {stage} is gone, so the interrupted commit cannot be "
                        "finished; nothing was changed (remove the journal to keep the folder as it is)",
                        path) from None
    if not stat.S_ISDIR(mode):
        raise _refused(path, f"commit journal: the staging folder {stage} is not a folder (or a symbolic link)")
    journal = _Journal(stage, tuple(entries), tuple(remove), file_name, manifest_name(set_name))
    _check_staged(out / stage, journal.entries, path)
    staged_manifest = out / stage / journal.manifest
    if os.path.lexists(staged_manifest):
        listed = _manifest_entries(staged_manifest, "staged output manifest")
        if not set(entries) <= set(listed) or set(listed) & set(remove):
            raise _refused(path, "commit journal and its staged manifest disagree")
    return journal


def _is_plain(name: str) -> bool:
    return name not in ("", ".", "..") and not any(c in name for c in "/\\\0") and len(name) <= 255


def _check_staged(stage: Path, entries: Sequence[str], journal: Path) -> None:
    """Refuse symbolic links among the staged entries (anywhere inside them) and as the trash: a commit
    moves only what lfbench wrote, and never through a link."""
    trash = stage / _TRASH
    if os.path.lexists(trash) and not stat.S_ISDIR(os.lstat(trash).st_mode):
        raise _refused(journal, f"commit journal: {trash} is not a folder")
    for name in entries:
        path = stage / name
        if os.path.islink(path):
            raise _refused(journal, f"commit journal: staged entry {path} is a symbolic link")
        for root, dirs, files in os.walk(path):
            for child in (*dirs, *files):
                if os.path.islink(os.path.join(root, child)):
                    raise _refused(journal, f"commit journal: staged entry {path} holds a symbolic link "
                                            f"({os.path.join(root, child)})")


# --------------------------------------------------------------------------- rolling forward

def _roll_forward(out: Path, journal: _Journal) -> None:
    """Move the journal's entries from its staging folder into ``out`` (idempotent), then drop it. Only
    renames: nothing is allocated (the manifest was staged before the commit point)."""
    stage = out / journal.stage
    trash = stage / _TRASH
    trash.mkdir(exist_ok=True)  # made before the commit point; again only for a journal of an earlier version
    for name in journal.remove:
        _move_aside(out / name, trash)
    for name in journal.entries:
        src = stage / name
        if os.path.lexists(src):  # not yet moved
            _move_aside(out / name, trash)
            os.replace(src, out / name)
    staged_manifest = stage / journal.manifest
    if os.path.lexists(staged_manifest):
        os.replace(staged_manifest, out / journal.manifest)
    elif not _manifest_lists(out / journal.manifest, journal.entries):  # a journal of an earlier version
        write_text(out / journal.manifest, _manifest_text(journal.entries))
    (out / journal.journal).unlink(missing_ok=True)
    shutil.rmtree(stage, ignore_errors=True)


def _manifest_lists(path: Path, entries: Sequence[str]) -> bool:
    try:
        return sorted(_manifest_entries(path, "output manifest")) == sorted(entries)
    except DataError:
        return False


def _manifest_text(entries: Iterable[str]) -> str:
    return json.dumps({"entries": sorted(entries)}, indent=1) + "\n"


def _move_aside(path: Path, trash: Path) -> None:
    """Move ``path`` (a link itself, never its target) into the trash."""
    if not os.path.lexists(path):
        return
    target = trash / path.name
    if os.path.lexists(target):  # only after a partial roll forward of an odd folder
        target = Path(tempfile.mkdtemp(dir=trash)) / path.name
    os.replace(path, target)


def _remove(path: Path) -> None:
    """Delete a stale temporary: a folder with its content, a file or a link (never what a link points to)."""
    with contextlib.suppress(OSError):
        if stat.S_ISDIR(os.lstat(path).st_mode):
            shutil.rmtree(path, ignore_errors=True)
        else:
            path.unlink()


def _alive(stage_name: str) -> bool:
    """Whether the process that made a staging folder (pid in its name) still runs."""
    try:
        pid = int(stage_name[len(STAGE_PREFIX):].split(".", 1)[0])
    except ValueError:
        return False
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except (OverflowError, ValueError):
        return False
    return True
