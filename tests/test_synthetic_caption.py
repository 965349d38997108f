"""Tables scored on synthetic data say so: `lfbench synth` marks its root (lfbench.data.provenance), evaluate
records it in the results (meta.synthetic), report and ablate put the line in every caption; a root
without the marker (or with a link, folder or FIFO of its name) is real data and no caption says otherwise."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pandas as pd
import pytest
from helpers import run_cli

from lfbench.data.provenance import SYNTHETIC_CAPTION, SYNTHETIC_MARKER, is_synthetic_root
from lfbench.results import Results


@pytest.fixture(scope="module")
def synthetic_root(tmp_path_factory) -> Path:
    from lfbench.cli import main

    root = tmp_path_factory.mktemp("synth") / "data"
    assert main(["synth", "--layout", "urbanlf-syn", "--size", "40x32", "--numbers", "11,27", "--seed", "0",
                 "--out", str(root)]) == 0
    return root


def _caption(table_md: Path) -> list[str]:
    """The caption lines above a markdown table (the lines before its header row)."""
    lines = table_md.read_text(encoding="utf-8").splitlines()
    return [line.strip() for line in lines[:next(i for i, line in enumerate(lines) if line.startswith("|"))]
            if line.strip()]


def test_synth_marks_its_root_and_evaluate_records_it(synthetic_root, tmp_path, capsys):
    assert (synthetic_root / SYNTHETIC_MARKER).is_file() and is_synthetic_root(synthetic_root)
    out = tmp_path / "ev"
    rc, _, err = run_cli(capsys, "evaluate", "--data", synthetic_root, "--method", "constant", "--out", out,
                         "--no-progress")
    assert rc == 0, err
    assert Results.read(out).meta["synthetic"] is True
    assert SYNTHETIC_CAPTION in _caption(out / "table_per_scene.md")
    rc, _, err = run_cli(capsys, "report", out, "--out", tmp_path / "rep")
    assert rc == 0, err
    assert SYNTHETIC_CAPTION in _caption(tmp_path / "rep" / "table_average.md")


def test_real_data_has_no_synthetic_line(synthetic_root, tmp_path, capsys):
    real = tmp_path / "real"
    shutil.copytree(synthetic_root, real)
    (real / SYNTHETIC_MARKER).unlink()
    rc, _, err = run_cli(capsys, "evaluate", "--data", real, "--method", "constant", "--out", tmp_path / "ev",
                         "--no-progress")
    assert rc == 0, err
    assert "synthetic" not in Results.read(tmp_path / "ev").meta
    assert not any("SYNTHETIC" in line for line in _caption(tmp_path / "ev" / "table_per_scene.md"))


@pytest.mark.parametrize("kind", ["symlink", "folder", "fifo"])
def test_only_a_regular_file_marks_a_root(tmp_path, kind):
    target = tmp_path / "elsewhere"
    target.write_text("x")
    marker = tmp_path / "root" / SYNTHETIC_MARKER
    marker.parent.mkdir()
    {"symlink": lambda: marker.symlink_to(target), "folder": marker.mkdir, "fifo": lambda: os.mkfifo(marker)}[kind]()
    assert not is_synthetic_root(marker.parent)
    assert not is_synthetic_root([tmp_path / "missing", marker.parent])


def test_ablation_captions_say_synthetic_and_time_at_the_scenes_angular_size(tmp_path, synthetic_root):
    from test_ablate import write_spec

    from lfbench.ablation.report import caption_lines, time_label
    from lfbench.ablation.spec import load_spec

    generated = load_spec(write_spec(tmp_path, 'title = "t"\ntable = "none"\n', '[[grid]]\n"model.width" = [2]\n'))
    assert generated.evaluation.synthetic is not None and SYNTHETIC_CAPTION in caption_lines(generated)
    real = tmp_path / "real"
    shutil.copytree(synthetic_root, real)
    (real / SYNTHETIC_MARKER).unlink()
    for root, said in ((synthetic_root, True), (real, False)):
        text = (tmp_path / "spec.toml").read_text().replace("synthetic = { seed = 5, size = 48, scenes = 1 }",
                                                           f"data = {str(root)!r}")
        (tmp_path / "data.toml").write_text(text)
        assert (SYNTHETIC_CAPTION in caption_lines(load_spec(tmp_path / "data.toml"))) is said
    frame = pd.DataFrame({"time_size": [64], "time_angular": [[7, 7]], "device": ["cpu"], "threads": [1]})
    assert time_label(frame) == "ours (7x7x64x64, cpu, 1 thread)"
