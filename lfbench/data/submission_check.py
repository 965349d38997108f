"""Submission validator, stricter than the benchmark toolkit's.

A submission is a folder or a zip holding ``disp_maps/<scene>.pfm`` (gray ``Pf``, (H, W) float32,
512x512 for HCI, finite values only) and ``runtimes/<scene>.txt`` (one positive finite number of
seconds) for every expected scene, and nothing else. A zip may hold these at its top level or inside
one top-level folder; its members are read in memory (never extracted) and must not escape the folder
(absolute paths, ``..``, backslashes, symbolic links). Nothing is ever unpickled.

Every problem is reported, one line each, naming the file.
"""

from __future__ import annotations

import os
import re
import stat
import zipfile
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path, PurePosixPath

import numpy as np

from lfbench.data.pfm import parse_pfm
from lfbench.data.submission import DISP_DIR, RUNTIME_DIR
from lfbench.utils.errors import DataError

# The 12 scenes of the benchmark's submission (stratified, training, test), in the toolkit's order.
BENCHMARK_SCENES: tuple[str, ...] = (
    "backgammon", "dots", "pyramids", "stripes",
    "boxes", "cotton", "dino", "sideboard",
    "bedroom", "bicycle", "herbs", "origami",
)
DEFAULT_SIZE: tuple[int, int] = (512, 512)  # (H, W) of a disparity map

_RUNTIME_MAX_BYTES = 256
_PFM_HEADER_SLACK = 1024  # header bytes allowed on top of the float data
_MAX_LISTED_UNKNOWN = 50
_FLOAT_RE = re.compile(r"^[+]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")


@dataclass(frozen=True)
class Problem:
    """One problem: ``file`` (as shown to the user) and what is wrong with it."""

    file: str
    message: str

    def __str__(self) -> str:
        return f"{self.file}: {self.message}"


@dataclass
class ValidationReport:
    """What was checked (``source``, the expected ``scenes``) and every problem found."""

    source: str
    scenes: tuple[str, ...]
    problems: list[Problem] = field(default_factory=list)

    @property
    def ok(self) -> bool:
        return not self.problems

    def add(self, file: str, message: str) -> None:
        self.problems.append(Problem(file, message))


# --------------------------------------------------------------------------- submission sources

@dataclass(frozen=True)
class _Entry:
    """A regular file of the submission: ``rel`` is its path inside the submission folder (POSIX)."""

    rel: str
    display: str
    size: int


class _FolderSource:
    """A submission folder on disk; symbolic links are reported, never followed."""

    def __init__(self, root: Path) -> None:
        self.root = root

    def scan(self, report: ValidationReport) -> list[_Entry]:
        entries = []

        def onerror(exc: OSError) -> None:
            report.add(str(exc.filename), f"cannot list folder: {exc.strerror or exc}")

        for dirpath, dirnames, filenames in os.walk(self.root, onerror=onerror, followlinks=False):
            here = Path(dirpath)
            for name in sorted(dirnames + filenames):
                path = here / name
                rel = path.relative_to(self.root).as_posix()
                st = os.lstat(path)
                if stat.S_ISLNK(st.st_mode):
                    report.add(str(path), "symbolic link (not allowed in a submission)")
                elif stat.S_ISREG(st.st_mode):
                    entries.append(_Entry(rel, str(path), st.st_size))
                elif not stat.S_ISDIR(st.st_mode):
                    report.add(str(path), "not a regular file")
            dirnames[:] = [d for d in dirnames if not (here / d).is_symlink()]
        return entries

    def read(self, entry: _Entry, limit: int) -> bytes:
        with open(self.root / entry.rel, "rb") as f:
            return f.read(limit + 1)

    def display(self, rel: str = "") -> str:
        """How a path inside the submission is shown (also for files that are absent)."""
        return str(self.root / rel) if rel else str(self.root)


class _ZipSource:
    """A zipped submission, read member by member in memory."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            self.zf = zipfile.ZipFile(path)
        except zipfile.BadZipFile:
            raise DataError("not a valid zip file", path) from None
        except OSError as exc:
            raise DataError(f"cannot read zip: {exc.strerror or exc}", path) from None
        self.infos: dict[str, zipfile.ZipInfo] = {}
        self.prefix = ""

    def close(self) -> None:
        self.zf.close()

    def _display(self, name: str) -> str:
        return f"{self.path}:{name}"

    def scan(self, report: ValidationReport) -> list[_Entry]:
        safe: list[zipfile.ZipInfo] = []
        seen: set[str] = set()
        for info in self.zf.infolist():
            name = info.filename
            problem = _unsafe_member(info)
            if problem is None and name in seen:
                problem = "duplicate member name"
            seen.add(name)
            if problem is not None:
                report.add(self._display(name), problem)
            elif not info.is_dir():
                safe.append(info)
        prefix = self.prefix = _zip_prefix([i.filename for i in safe])
        entries = []
        for info in safe:
            name = info.filename
            # a member outside the submission folder gets a key no expected file can have: it is unexpected
            rel = name[len(prefix):] if name.startswith(prefix) else "/" + name
            if info.flag_bits & 0x1:
                report.add(self._display(name), "encrypted member (not allowed)")
                continue
            self.infos[rel] = info
            entries.append(_Entry(rel, self._display(name), info.file_size))
        return entries

    def display(self, rel: str = "") -> str:
        return self._display(self.prefix + rel) if rel else str(self.path)

    def read(self, entry: _Entry, limit: int) -> bytes:
        try:
            with self.zf.open(self.infos[entry.rel]) as f:
                return f.read(limit + 1)
        except (zipfile.BadZipFile, NotImplementedError, RuntimeError, OSError, EOFError) as exc:
            raise DataError(f"cannot read member: {exc}", entry.display) from None


def _unsafe_member(info: zipfile.ZipInfo) -> str | None:
    """Why a zip member could escape the submission folder (or None if it cannot)."""
    name = info.filename
    if "\\" in name:
        return "member name uses backslashes (may escape the folder on extraction)"
    if "\x00" in name:
        return "member name contains a NUL character"
    if name.startswith("/") or re.match(r"^[A-Za-z]:", name):
        return "absolute path (escapes the submission folder)"
    if ".." in PurePosixPath(name).parts:
        return "'..' in the path (escapes the submission folder)"
    if stat.S_ISLNK(info.external_attr >> 16):
        return "symbolic link (not allowed in a submission)"
    return None


def _zip_prefix(names: Sequence[str]) -> str:
    """The submission folder inside a zip: '' when disp_maps/ or runtimes/ sit at the top level, else 'X/'
    for the one top-level folder X holding them (members elsewhere, e.g. __MACOSX/, are unexpected)."""
    parts = [n.split("/") for n in names]
    if any(len(p) > 1 and p[0] in (DISP_DIR, RUNTIME_DIR) for p in parts):
        return ""
    holders = {p[0] for p in parts if len(p) > 2 and p[1] in (DISP_DIR, RUNTIME_DIR)}
    return f"{holders.pop()}/" if len(holders) == 1 else ""


# --------------------------------------------------------------------------- checks

def _check_map(data: bytes, display: str, size: tuple[int, int], report: ValidationReport) -> None:
    try:
        disp = parse_pfm(data, display)
    except DataError as exc:
        report.add(display, _message(exc))
        return
    h, w = size
    if disp.ndim != 2:
        report.add(display, "3-channel PF map: a disparity map must be a gray Pf map")
        return
    if disp.shape != (h, w):
        report.add(display, f"map is {disp.shape[1]}x{disp.shape[0]}, expected {w}x{h}")
    bad = int(np.count_nonzero(~np.isfinite(disp)))
    if bad:
        n_nan = int(np.count_nonzero(np.isnan(disp)))
        report.add(display, f"{bad} non-finite values ({n_nan} NaN, {bad - n_nan} inf)")


def _check_runtime(data: bytes, display: str, report: ValidationReport) -> None:
    if len(data) > _RUNTIME_MAX_BYTES:
        report.add(display, f"runtime file too large (over {_RUNTIME_MAX_BYTES} bytes): expected one number")
        return
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        report.add(display, "runtime file is not UTF-8 text")
        return
    tokens = text.split()
    if len(tokens) != 1:
        report.add(display, f"expected one number of seconds, found {len(tokens)} values")
        return
    token = tokens[0]
    if not _FLOAT_RE.match(token):
        report.add(display, f"runtime {token[:30]!r} is not a positive decimal number")
        return
    value = float(token)
    if not np.isfinite(value) or value <= 0:
        report.add(display, f"runtime {token[:30]!r} must be a positive finite number of seconds")


def _too_large(head: bytes, nbytes: int, size: tuple[int, int], check: str) -> str:
    h, w = size
    if check != "map":
        return f"runtime file too large ({nbytes} bytes): expected one number"
    dims = re.match(rb"P[fF]\s+(\d+)\s+(\d+)\s", head)
    if dims and (int(dims[1]), int(dims[2])) != (w, h):
        return f"map is {int(dims[1])}x{int(dims[2])}, expected {w}x{h}"
    return f"file too large ({nbytes} bytes) for a {w}x{h} map"


def _message(exc: DataError) -> str:
    """The error's message without the path it names (the report names the file itself)."""
    return " ".join(str(exc.args[0] if exc.args else exc).split())


def _entries_by_rel(entries: list[_Entry]) -> dict[str, _Entry]:
    return {e.rel: e for e in entries}


def parse_size(text: str) -> tuple[int, int]:
    """'512' -> (512, 512); 'WxH' -> (H, W). DataError on anything else."""
    from lfbench.data.scene import MAX_RESOLUTION_PX

    m = re.fullmatch(r"\s*(\d{1,9})\s*(?:[xX]\s*(\d{1,9})\s*)?", text)
    if not m or int(m[1]) <= 0 or (m[2] is not None and int(m[2]) <= 0):
        raise DataError(f"bad --size {text[:40]!r}: expected N or WxH, e.g. 512 or 512x512")
    w = int(m[1])
    h = int(m[2]) if m[2] is not None else w
    if max(h, w) > MAX_RESOLUTION_PX:
        raise DataError(f"bad --size {text[:40]!r}: each side must be at most {MAX_RESOLUTION_PX} px")
    return h, w


def validate_submission(path: str | Path, scenes: Sequence[str] | None = None,
                        size: tuple[int, int] = DEFAULT_SIZE) -> ValidationReport:
    """Check a submission folder or zip; returns every problem found (an empty list = valid).

    scenes: expected scene names (default :data:`BENCHMARK_SCENES`); size: (H, W) of every map in px.
    Raises DataError only when ``path`` cannot be opened at all.
    """
    path = Path(path)
    scenes = tuple(BENCHMARK_SCENES if scenes is None else scenes)
    bad_names = [s for s in scenes if not s or "/" in s or "\\" in s or s in (".", "..")]
    if bad_names or not scenes:
        raise DataError(f"bad scene list {list(scenes)!r}")
    report = ValidationReport(str(path), scenes)
    if path.is_dir():
        source: _FolderSource | _ZipSource = _FolderSource(path)
    elif path.is_file():
        source = _ZipSource(path)
    elif path.exists() or path.is_symlink():
        raise DataError("not a folder or a zip file", path)
    else:
        raise DataError("submission not found", path)
    try:
        _validate(source, scenes, size, report)
    finally:
        if isinstance(source, _ZipSource):
            source.close()
    return report


def _validate(source: _FolderSource | _ZipSource, scenes: tuple[str, ...], size: tuple[int, int],
              report: ValidationReport) -> None:
    entries = _entries_by_rel(source.scan(report))
    h, w = size
    map_limit = 3 * 4 * h * w + _PFM_HEADER_SLACK  # room for a 3-channel PF map, reported as such
    expected: set[str] = set()
    for scene in scenes:
        for rel, limit, check in ((f"{DISP_DIR}/{scene}.pfm", map_limit, "map"),
                                  (f"{RUNTIME_DIR}/{scene}.txt", _RUNTIME_MAX_BYTES, "runtime")):
            expected.add(rel)
            entry = entries.get(rel)
            if entry is None:
                report.add(source.display(rel), "missing")
                continue
            try:
                if entry.size > limit:  # never read more than a valid file can hold; its header says why
                    report.add(entry.display, _too_large(source.read(entry, 64)[:64] if check == "map" else b"",
                                                         entry.size, size, check))
                    continue
                data = source.read(entry, limit)
            except DataError as exc:
                report.add(entry.display, _message(exc))
                continue
            except OSError as exc:
                report.add(entry.display, f"cannot read: {exc.strerror or exc}")
                continue
            if check == "map":
                _check_map(data, entry.display, size, report)
            else:
                _check_runtime(data, entry.display, report)
    unknown = [e for rel, e in sorted(entries.items()) if rel not in expected]
    for e in unknown[:_MAX_LISTED_UNKNOWN]:
        report.add(e.display, "unexpected file")
    if len(unknown) > _MAX_LISTED_UNKNOWN:
        report.add(source.display(), f"{len(unknown) - _MAX_LISTED_UNKNOWN} more unexpected files not listed")


def iter_problem_lines(report: ValidationReport) -> Iterator[str]:
    """The report's problems as printable lines, one per problem."""
    for p in report.problems:
        yield " ".join(str(p).split())


__all__ = ["BENCHMARK_SCENES", "DEFAULT_SIZE", "Problem", "ValidationReport", "validate_submission", "parse_size",
           "iter_problem_lines"]
