"""Whole output sets: a run's files appear in its folder together or not at all.

A run writes every output into a staging folder inside OUT (``.lfbench-stage.<pid>.<random>``),
then commits: a journal (``.lfbench-commit.json``, written atomically) names the staged entries
and the previous run's entries to drop; the entries are moved into OUT one by one (renames on one
file system); a manifest (``.lfbench-outputs.json``) records the set; the journal goes last. A kill
before the journal leaves OUT as it was (the next run deletes the dead staging folder); a kill
after it is rolled forward by the next run, and readers refuse a folder whose journal is pending
(:func:`check_complete`). A write error (disk full, read-only folder) while staging is one
:class:`~lfbench.utils.errors.LFBenchError` naming the file, and OUT is untouched.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator, Sequence
from pathlib import Path

from lfbench.utils.atomic import write_text
from lfbench.utils.errors import DataError, LFBenchError

__all__ = ["JOURNAL", "MANIFEST", "OutputSet", "check_complete", "check_output_file", "prepare_output_folder",
           "recover", "staged_outputs"]

STAGE_PREFIX = ".lfbench-stage."
JOURNAL = ".lfbench-commit.json"
MANIFEST = ".lfbench-outputs.json"
_TRASH = ".trash"
# temporaries a killed run leaves (suffix .tmp / .old): the demo's data and HTML report, earlier versions'
# maps and figures
_OLD_TEMPORARIES = (".data.", ".figures.", ".html.", ".maps.")


class OutputSet:
    """A run's staging folder in ``out``; :meth:`commit` moves the named entries into ``out``."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.created = not self.out.exists()  # removed again by abort() when the run writes nothing
        prepare_output_folder(self.out)
        recover(self.out)
        try:
            self.stage = Path(tempfile.mkdtemp(prefix=f"{STAGE_PREFIX}{os.getpid()}.", dir=self.out))
        except OSError as exc:
            raise DataError(f"cannot write into the output folder: {exc.strerror or exc}", self.out) from None
        self.committed = False  # True once the journal is written: from then on a failure rolls forward

    def final(self, staged: Path) -> Path:
        """Where a staged path lands in ``out``."""
        return self.out / Path(staged).relative_to(self.stage)

    def commit(self, entries: Sequence[str]) -> None:
        """Move the staged top-level ``entries`` (names in the staging folder) into ``out`` as one set,
        dropping the entries of the previous committed run that this one does not write."""
        entries = sorted(set(entries))
        missing = [e for e in entries if not (self.stage / e).exists()]
        if missing:
            raise RuntimeError(f"staged outputs missing: {missing}")
        previous = _read_manifest(self.out)
        journal = {"stage": self.stage.name, "entries": entries,
                   "remove": sorted(set(previous) - set(entries))}
        write_text(self.out / JOURNAL, json.dumps(journal, indent=1) + "\n")  # the commit point
        self.committed = True
        _roll_forward(self.out, journal)

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


def check_output_file(path: str | Path) -> None:
    """DataError unless ``path`` can be written as a file: not a folder, its folder creatable and
    writable. Checked before the work, so that minutes of computing are not lost to a typo."""
    path = Path(path)
    if path.is_dir():
        raise DataError("is a folder, expected a file path", path)
    prepare_output_folder(path.parent)


@contextlib.contextmanager
def staged_outputs(out: str | Path) -> Iterator[OutputSet]:
    """An :class:`OutputSet` for ``out``; on any exception its staging folder is removed (``out`` is
    untouched) and a write error becomes one LFBenchError naming the file."""
    outputs = OutputSet(out)
    try:
        yield outputs
    except OSError as exc:
        outputs.abort()
        where = Path(exc.filename) if exc.filename else outputs.out
        with contextlib.suppress(ValueError):
            where = outputs.final(where)
        raise LFBenchError(f"cannot write: {exc.strerror or exc} (nothing written to {outputs.out})", where) from None
    except BaseException:
        outputs.abort()
        raise


def recover(out: Path) -> None:
    """Finish a commit that a killed run left half done, and delete staging folders of dead runs
    and temporaries of earlier versions."""
    journal_path = out / JOURNAL
    if journal_path.is_file():
        try:
            journal = json.loads(journal_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            journal = None
        if isinstance(journal, dict) and (out / str(journal.get("stage", ""))).is_dir():
            _roll_forward(out, journal)
        else:
            journal_path.unlink(missing_ok=True)
    for entry in out.iterdir() if out.is_dir() else ():
        name = entry.name
        if name.startswith(STAGE_PREFIX) and not _alive(name):
            shutil.rmtree(entry, ignore_errors=True)
        elif name.startswith(_OLD_TEMPORARIES) and name.endswith((".tmp", ".old")):
            shutil.rmtree(entry, ignore_errors=True)


def check_complete(folder: Path) -> None:
    """DataError when ``folder`` holds a run whose commit was interrupted (its files may mix two runs)."""
    if (folder / JOURNAL).is_file():
        raise DataError(f"an interrupted run left this folder half updated ({JOURNAL}); run the command again "
                        "to finish it", folder)


def _roll_forward(out: Path, journal: dict) -> None:
    """Move the journal's entries from its staging folder into ``out`` (idempotent), then drop it."""
    stage = out / str(journal["stage"])
    trash = stage / _TRASH
    trash.mkdir(exist_ok=True)
    for name in journal.get("remove", []):
        _move_aside(out / name, trash)
    for name in journal["entries"]:
        src = stage / name
        if src.exists() or src.is_symlink():  # not yet moved
            _move_aside(out / name, trash)
            os.replace(src, out / name)
    write_text(out / MANIFEST, json.dumps({"entries": list(journal["entries"])}, indent=1) + "\n")
    (out / JOURNAL).unlink(missing_ok=True)
    shutil.rmtree(stage, ignore_errors=True)


def _move_aside(path: Path, trash: Path) -> None:
    if path.exists() or path.is_symlink():
        os.replace(path, Path(tempfile.mkdtemp(dir=trash)) / path.name)


def _read_manifest(out: Path) -> list[str]:
    try:
        entries = json.loads((out / MANIFEST).read_text(encoding="utf-8")).get("entries", [])
    except (OSError, ValueError, AttributeError):
        return []
    return [e for e in entries if isinstance(e, str) and e and "/" not in e and e not in (".", "..")]


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
    return True
