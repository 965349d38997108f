"""What `lfbench ablate` re-uses from its output folder is checked against what the folder recorded, or re-made
(issue 31, class 1): a cell's final.pt or results.json copied over from another cell, a [[methods]] weights file
whose content changed, a method's results.json changed. And an ablation folder moved or copied as a whole
resumes (class 7): its data links are relative, its fingerprints do not name where it lies.

One tiny two-cell ablation (interval 1 and 2: different cost volumes, different numbers) is run once; each test
works on a copy of it."""

from __future__ import annotations

import json
import logging
import shutil
from pathlib import Path

import pytest
from test_ablate import TWO_CELLS, write_spec

from lfbench.ablation.runner import run_ablation
from lfbench.ablation.spec import load_spec
from lfbench.utils.errors import DataError

pytestmark = pytest.mark.slow

CELLS = ("interval=1", "interval=2")


def _records(path: Path, method: str | None = None) -> dict:
    data = json.loads(path.read_text(encoding="utf-8"))
    return {(r["method"], r["scene"], r["metric"]): r["value"] for r in data["records"]
            if method is None or r["method"] == method}


def _values(path: Path, method: str) -> dict:
    """(scene, metric) -> value of ``method``'s records in the results.json ``path``."""
    return {(scene, metric): v for (m, scene, metric), v in _records(path, method).items()}


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    root = tmp_path_factory.mktemp("reuse")
    spec = write_spec(root, TWO_CELLS, evaluation="error_maps = false\n")
    run_ablation(load_spec(spec), root / "out", progress=False, log=lambda _m: None)
    cells = {c: json.loads((root / "out" / "cells" / c / "cell.json").read_text()) for c in CELLS}
    values = {c: _values(root / "out" / "results.json", c) for c in CELLS}
    assert values["interval=1"] != values["interval=2"]  # the test can tell the cells apart
    return spec, root / "out", cells, values


def _copy(finished, tmp_path: Path, name: str = "out") -> Path:
    _, out, _, _ = finished
    shutil.copytree(out, tmp_path / name, symlinks=True)
    return tmp_path / name


def _rerun(spec: Path, out: Path) -> list[str]:
    lines: list[str] = []
    run_ablation(load_spec(spec), out, progress=False, log=lines.append)
    return lines


@pytest.mark.parametrize("also_results", [False, True], ids=["weights", "weights-and-scores-gone"])
def test_a_cell_weights_file_copied_over_another_is_detected_and_the_cell_re_made(finished, tmp_path, caplog,
                                                                                   also_results):
    """Copying cell A's final.pt over cell B's: B is re-made from its own training checkpoint (the trainer
    re-exports the weights its checkpoint holds), never scored or timed with A's weights; the table keeps B's own
    numbers. With B's results.json gone too (so its scores are re-made), it used to score A's weights as B's."""
    spec, _, cells, values = finished
    out = _copy(finished, tmp_path)
    b = out / "cells" / "interval=2"
    shutil.copyfile(out / "cells" / "interval=1" / "final.pt", b / "final.pt")
    if also_results:
        (b / "results.json").unlink()
    with caplog.at_level(logging.INFO):
        lines = _rerun(spec, out)
    assert "cell interval=1: finished earlier, skipped" in lines
    assert "cell interval=2: finished earlier, skipped" not in lines
    log = caplog.text
    if not also_results:
        assert f"{b / 'final.pt'} is not the file the cell recorded (final_sha256); the cell is re-made" in log
    else:
        assert f"{b / 'results.json'}: cell results not found; the cell is re-made" in log
    assert log.count("the cell is re-made") == 1  # one line, from the run that re-makes it
    train_log = (b / "log.txt").read_text(encoding="utf-8")
    assert f"{b / 'final.pt'} does not hold the weights of {b / 'checkpoint.pt'}: re-exported" in train_log
    marker = json.loads((b / "cell.json").read_text())
    assert marker["final_sha256"] == cells["interval=2"]["final_sha256"]
    assert _values(out / "results.json", "interval=2") == values["interval=2"]
    assert _values(out / "results.json", "interval=1") == values["interval=1"]
    # what was re-made is re-used next time
    assert "cell interval=2: finished earlier, skipped" in _rerun(spec, out)


def test_a_cell_results_file_copied_over_another_is_re_made(finished, tmp_path, caplog):
    spec, _, _, values = finished
    out = _copy(finished, tmp_path)
    b = out / "cells" / "interval=2"
    shutil.copyfile(out / "cells" / "interval=1" / "results.json", b / "results.json")
    with caplog.at_level(logging.WARNING):
        _rerun(spec, out)
    assert f"{b / 'results.json'} is not the file the cell recorded (results_sha256)" in caplog.text
    assert _values(b / "results.json", "interval=2") == values["interval=2"]
    assert set(json.loads((out / "results.json").read_text())["meta"]["ablation"]["cells"][0]) >= {"final_sha256"}
    assert {m for m, _, _ in _records(out / "results.json")} == set(CELLS)


def test_the_test_time_is_never_measured_on_other_weights(finished, tmp_path):
    from lfbench.ablation.cell import time_cell

    spec, _, _, _ = finished
    out = _copy(finished, tmp_path)
    b = out / "cells" / "interval=2"
    shutil.copyfile(out / "cells" / "interval=1" / "final.pt", b / "final.pt")
    with pytest.raises(DataError, match="final.pt: not the weights the cell recorded"):
        time_cell(b, load_spec(spec).evaluation, 1)


def test_extra_methods_are_scored_again_when_their_weights_or_scores_changed(finished, tmp_path):
    """A [[methods]] entry is cached in OUT/methods/<label>/: the cache names the content of its weights (the
    same path with other weights is another method) and the bytes of its results.json."""
    spec, _, _, values = finished
    out = _copy(finished, tmp_path)
    weights = tmp_path / "w.pt"
    shutil.copyfile(out / "cells" / "interval=1" / "final.pt", weights)
    spec2 = tmp_path / "with_method.toml"
    spec2.write_text(spec.read_text() + f'\n[[methods]]\nlabel = "net"\nspec = "subfocal:weights={weights}"\n')
    lines = _rerun(spec2, out)
    assert "method net: scored on 1 scene(s)" in lines
    assert _values(out / "results.json", "net") == values["interval=1"]  # the same weights, the same numbers
    shutil.copyfile(out / "cells" / "interval=2" / "final.pt", weights)  # other weights under the same path
    lines = _rerun(spec2, out)
    assert "method net: scored on 1 scene(s)" in lines
    assert _values(out / "results.json", "net") == values["interval=2"]
    assert "method net: finished earlier, skipped" in _rerun(spec2, out)
    # its scores changed in place: scored again
    scores = out / "methods" / "net" / "results.json"
    data = json.loads(scores.read_text())
    data["records"][0]["value"] = 123.0
    scores.write_text(json.dumps(data))
    lines = _rerun(spec2, out)
    assert f"method net: {scores} is not the file its method.json recorded; scored again" in lines
    assert _values(out / "results.json", "net") == values["interval=2"]


@pytest.mark.parametrize("partial", [False, True], ids=["finished", "partial"])
def test_a_moved_ablation_folder_resumes(finished, tmp_path, partial):
    """`mv OUT elsewhere` then `lfbench ablate SPEC --out elsewhere`: finished cells are skipped (not scored
    again), an unfinished one is trained there; the data links are relative and lead into the moved folder."""
    spec, _, cells, values = finished
    out = _copy(finished, tmp_path, "first")
    if partial:  # cell 2 stopped before its last stage: its checkpoint is the shared-data run's at step 2
        b = out / "cells" / "interval=2"
        for name in ("cell.json", "results.json", "final.pt", "summary.json", "timing.json"):
            (b / name).unlink()
    moved = tmp_path / "elsewhere" / "moved"
    moved.parent.mkdir()
    shutil.move(out, moved)
    assert not out.exists()
    lines = _rerun(spec, moved)
    assert "cell interval=1: finished earlier, skipped" in lines
    assert ("cell interval=2: finished earlier, skipped" in lines) is not partial
    for c in CELLS:
        link = moved / "cells" / c / "data" / "synthetic"
        assert link.is_symlink() and not Path(link.readlink()).is_absolute()
        assert link.resolve().is_relative_to(moved.resolve())
        marker = json.loads((moved / "cells" / c / "cell.json").read_text())
        assert marker["final_sha256"] == cells[c]["final_sha256"]  # the same training: bit for bit
        assert _values(moved / "results.json", c) == values[c]


def test_an_absolute_data_link_of_an_earlier_version_is_re_pointed(finished, tmp_path):
    """A folder written by an earlier version (absolute links) and then moved, with a cell to finish: its link is
    replaced by the right, relative one (never followed), instead of 'symbolic link to another folder' refusing
    the resume."""
    spec, _, cells, values = finished
    out = _copy(finished, tmp_path, "first")
    for c in CELLS:
        link = out / "cells" / c / "data" / "synthetic"
        target = link.resolve()
        link.unlink()
        link.symlink_to(target, target_is_directory=True)  # absolute, into "first"
    b = out / "cells" / "interval=2"
    for name in ("cell.json", "results.json", "final.pt", "summary.json", "timing.json", "checkpoint.pt"):
        (b / name).unlink()  # cell 2 to train again from the start
    moved = tmp_path / "moved"
    shutil.move(out, moved)
    lines = _rerun(spec, moved)
    assert "cell interval=1: finished earlier, skipped" in lines
    link = moved / "cells" / "interval=2" / "data" / "synthetic"
    assert not Path(link.readlink()).is_absolute() and link.resolve().is_relative_to(moved.resolve())
    assert json.loads((b.parent.parent.parent / "moved" / "cells" / "interval=2" / "cell.json").read_text())[
        "final_sha256"] == cells["interval=2"]["final_sha256"]
    for c in CELLS:
        assert _values(moved / "results.json", c) == values[c]
