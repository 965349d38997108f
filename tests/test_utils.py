"""lfbench.utils: atomic writes and their file mode, the torch thread context, the $VAR expander, CLI logging."""

from __future__ import annotations

import io
import logging
import os
import stat
from pathlib import Path

import pytest

from lfbench.utils.atomic import FILE_MODE, atomic_open, fresh_dir, write_text
from lfbench.utils.envvars import expand_vars
from lfbench.utils.errors import SpecError
from lfbench.utils.log import configure_cli_logging, log_to_file
from lfbench.utils.threads import torch_threads


def _mode(path: Path) -> int:
    return stat.S_IMODE(path.stat().st_mode)


def test_atomic_write_sets_the_mode_on_the_file_and_never_touches_the_umask(tmp_path, monkeypatch):
    def no_umask(*_):
        raise AssertionError("os.umask must not be called (process-wide, races with other threads)")

    monkeypatch.setattr(os, "umask", no_umask)
    new = tmp_path / "sub" / "new.txt"
    write_text(new, "a")
    assert new.read_text() == "a" and _mode(new) == FILE_MODE == 0o644
    kept = tmp_path / "kept.txt"
    kept.write_text("old")
    kept.chmod(0o600)
    write_text(kept, "new")
    assert kept.read_text() == "new" and _mode(kept) == 0o600  # replacing a file keeps its mode
    with atomic_open(tmp_path / "x.bin", "wb", file_mode=0o640) as f:
        f.write(b"x")
    assert _mode(tmp_path / "x.bin") == 0o640


def test_fresh_dirs_are_new_hidden_and_take_their_mode_from_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        made = {fresh_dir(tmp_path, ".site.", ".tmp") for _ in range(20)}
        os.umask(0o077)
        private = fresh_dir(tmp_path, ".x.")
    finally:
        os.umask(old)
    assert len(made) == 20 and all(p.parent == tmp_path and p.name.startswith(".site.") and p.suffix == ".tmp"
                                   and not any(p.iterdir()) and _mode(p) == 0o755 for p in made)
    assert _mode(private) == 0o700  # the user's umask decides, not a fixed 0700 (tempfile.mkdtemp)


def test_atomic_write_leaves_the_old_file_on_an_error(tmp_path):
    path = tmp_path / "r.txt"
    path.write_text("old")
    with pytest.raises(RuntimeError), atomic_open(path, "w") as f:
        f.write("half")
        raise RuntimeError("interrupted")
    assert path.read_text() == "old" and sorted(p.name for p in tmp_path.iterdir()) == ["r.txt"]


def test_torch_threads_restores_the_count_also_on_an_exception():
    torch = pytest.importorskip("torch")
    before = torch.get_num_threads()
    with torch_threads(1) as n:
        assert n == torch.get_num_threads() == 1
    assert torch.get_num_threads() == before
    with pytest.raises(ValueError), torch_threads(1):
        raise ValueError
    assert torch.get_num_threads() == before
    with torch_threads(None) as n:
        assert n == before
    with torch_threads(0) as n:
        assert n == torch.get_num_threads() == (os.cpu_count() or 1)
    assert torch.get_num_threads() == before


def test_expand_vars(monkeypatch):
    monkeypatch.setenv("LFB_A", "/data")
    monkeypatch.delenv("LFB_UNSET", raising=False)
    assert expand_vars("$LFB_A/x/${LFB_A}") == "/data/x//data"
    assert expand_vars("~/y") == os.path.expanduser("~/y") and not expand_vars("~/y").startswith("~")
    with pytest.raises(SpecError, match=r"^cfg.toml: data.root: '\$LFB_UNSET/x' uses environment variable LFB_UNSET"):
        expand_vars("$LFB_UNSET/x", "cfg.toml", "data.root")
    with pytest.raises(SpecError, match=r"^path '\$\{LFB_UNSET\}' uses environment variable LFB_UNSET, which is not"):
        expand_vars("${LFB_UNSET}")


def test_cli_logging_shows_library_messages_once_at_the_chosen_level():
    logger = logging.getLogger("lfbench.runs.runner")
    first, second = io.StringIO(), io.StringIO()
    configure_cli_logging(0, first)
    configure_cli_logging(0, second)  # replaces the first handler: no message twice
    logger.info("info line")
    logger.debug("debug line")
    assert first.getvalue() == "" and second.getvalue() == "info line\n"
    quiet = io.StringIO()
    configure_cli_logging(-1, quiet)
    logger.info("hidden")
    logger.warning("shown")
    assert quiet.getvalue() == "shown\n"
    verbose = io.StringIO()
    configure_cli_logging(1, verbose)
    logger.debug("debug line")
    assert verbose.getvalue() == "debug line\n"
    configure_cli_logging(0)


def test_log_to_file_takes_the_training_log_off_the_console(tmp_path):
    console = io.StringIO()
    configure_cli_logging(0, console)
    train_log = logging.getLogger("lfbench.training.loop")
    with log_to_file(tmp_path / "cell" / "log.txt", "# header"):
        train_log.info("step 1")
        logging.getLogger("lfbench.runs.runner").info("not training")
    train_log.info("after")
    assert (tmp_path / "cell" / "log.txt").read_text() == "# header\nstep 1\n"
    assert console.getvalue() == "not training\nafter\n"
    assert logging.getLogger("lfbench.training").propagate
    configure_cli_logging(0)
