"""Text files lfbench writes and reads back are UTF-8 whatever the locale says.

A file opened without ``encoding=`` takes the locale's encoding: under ``LC_ALL=C`` without Python's UTF-8 mode
that is ASCII, and a non-ASCII label (a scene named ``Straße``, a method ``ÉPI``) fails to write or reads back
as replacement characters. These tests run the writers and readers in a child Python under exactly that locale
(``PYTHONUTF8=0``, ``PYTHONCOERCECLOCALE=0``: no coercion to C.UTF-8) and compare the bytes with an in-process
run. They kill the mutants that drop an ``encoding="utf-8"`` (results/mutation/issue39/README.md, "Fourth
round"): the child imports the same package the test does (under mutmut, the mutated copy, and it inherits
``MUTANT_UNDER_TEST``).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import lfbench
from lfbench.utils import atomic, executor

LABEL = "Straße ÉPI 深度"
_PACKAGE_ROOT = str(Path(lfbench.__file__).resolve().parent.parent)


# Under mutmut the child runs the mutant named by MUTANT_UNDER_TEST, which it inherits. A method's mutant is named
# with "ǁ" (``executor.xǁProcessPoolǁ_died__mutmut_11``): the ASCII child decodes that name into surrogates and would
# run the original method, so it takes the name back as the UTF-8 its parent wrote (an environment value holding
# "ǁ" cannot be set under this locale: mutmut's own copy of the name is set instead).
_UNDER_MUTMUT = ("import os\n"
                 "_name = os.environ.pop('MUTANT_UNDER_TEST', None)\n"
                 "if _name is not None:\n"
                 "    from mutmut.mutation import trampoline\n"
                 "    trampoline._mutant_under_test = os.fsencode(_name).decode('utf-8')\n")


def _ascii_child(code: str, *args: str) -> subprocess.CompletedProcess:
    """Run ``code`` in a child Python whose locale encoding is ASCII; skip when this Python will not give one.
    ``args`` are ASCII (non-ASCII text goes as JSON): the child decodes its argv as ASCII too."""
    env = {**os.environ, "LC_ALL": "C", "LANG": "C", "PYTHONUTF8": "0", "PYTHONCOERCECLOCALE": "0",
           "PYTHONPATH": os.pathsep.join(p for p in (_PACKAGE_ROOT, os.environ.get("PYTHONPATH")) if p)}
    probe = subprocess.run([sys.executable, "-c", "import locale, sys; print(sys.flags.utf8_mode, "
                            "locale.getencoding().lower())"], env=env, capture_output=True, text=True, check=True)
    if probe.stdout.split() != ["0", "ansi_x3.4-1968"]:
        pytest.skip(f"this Python under LC_ALL=C reads text as {probe.stdout.strip()!r}, not ASCII: the locale "
                    "cannot differ from UTF-8 here")
    return subprocess.run([sys.executable, "-c", _UNDER_MUTMUT + code, *args], env=env, capture_output=True, text=True,
                          timeout=60)


def test_write_text_writes_utf8_under_an_ascii_locale(tmp_path):
    """atomic.write_text with ``encoding=None`` or without it: UnicodeEncodeError in the ASCII child."""
    atomic.write_text(tmp_path / "here.txt", LABEL)
    child = _ascii_child("import json, sys; from lfbench.utils.atomic import write_text; write_text(sys.argv[1], "
                         "json.loads(sys.argv[2]))", str(tmp_path / "child.txt"), json.dumps(LABEL))
    assert child.returncode == 0, child.stderr.splitlines()[-1:]
    assert (tmp_path / "child.txt").read_bytes() == (tmp_path / "here.txt").read_bytes() == LABEL.encode("utf-8")


def test_run_marked_writes_its_mark_in_utf8_under_an_ascii_locale(tmp_path, monkeypatch):
    """run_marked's mark written without ``encoding="utf-8"``: UnicodeEncodeError in the ASCII child."""
    monkeypatch.setattr(executor, "_marks", tmp_path / "here")
    (tmp_path / "here").mkdir()
    here = executor.run_marked(lambda item: (tmp_path / "here" / str(os.getpid())).read_bytes(), LABEL, None)
    code = ("import json, os, sys; from pathlib import Path; from lfbench.utils import executor\n"
            "executor._marks = Path(sys.argv[1])\n"
            "mark = executor.run_marked(lambda item: (executor._marks / str(os.getpid())).read_bytes(), "
            "json.loads(sys.argv[2]), None)\n"
            "sys.stdout.write(mark.hex())")
    (tmp_path / "child").mkdir()
    child = _ascii_child(code, str(tmp_path / "child"), json.dumps(LABEL))
    assert child.returncode == 0, child.stderr.splitlines()[-1:]
    assert bytes.fromhex(child.stdout) == here == LABEL.encode("utf-8")


class _Pool:
    def shutdown(self, wait: bool, cancel_futures: bool) -> None:
        pass


def test_died_reads_the_marks_as_utf8_under_an_ascii_locale(tmp_path):
    """ProcessPool._died reading the marks without ``encoding="utf-8"``: replacement characters for the
    label in the ASCII child's error."""
    marks = tmp_path / "marks"
    marks.mkdir()
    (marks / "123").write_bytes(LABEL.encode("utf-8"))
    here = str(executor.ProcessPool._died(_Pool(), marks, "seen", "{names}"))
    code = ("import json, sys; from pathlib import Path; from lfbench.utils import executor\n"
            "class Pool:\n"
            "    def shutdown(self, wait, cancel_futures): pass\n"
            "sys.stdout.write(json.dumps(str(executor.ProcessPool._died(Pool(), Path(sys.argv[1]), 'seen', "
            "'{names}'))))")
    child = _ascii_child(code, str(marks))
    assert child.returncode == 0, child.stderr.splitlines()[-1:]
    assert json.loads(child.stdout) == here == repr(LABEL)
