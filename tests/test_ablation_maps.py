"""Issue 32.5: `lfbench ablate --maps all|best|none` (`--no-maps`): an ablation of short cells spent longer drawing
the error-map figures and the site's maps than training. The cells still save their maps; the report draws
every cell's, only the best cell's (and the [[methods]]'), or none. Checked on a finished ablation made by hand
(two cells with saved maps around the zero map, scored for real on the tiny spec's synthetic scene)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import write_submission
from test_ablate import quiet, write_spec

from lfbench.ablation.report import best_cell, drawn_map_folders
from lfbench.ablation.runner import prepare_evaluation, run_methods
from lfbench.ablation.spec import load_spec
from lfbench.cli import main
from lfbench.data.hci import HCIScene
from lfbench.reports.figures import safe_name
from lfbench.results import Record, Results
from lfbench.utils.errors import SpecError

CELLS = ("interval=1", "interval=0.5")
TAIL = '\n[[methods]]\nlabel = "Zero map"\nspec = "constant"\n[[methods]]\nlabel = "Oracle"\nspec = "gt"\n'


@pytest.fixture(scope="module")
def ablation(tmp_path_factory) -> tuple[Path, Path, str]:
    """A finished ablation: the spec, OUT and the scene's name. interval=0.5 is the better cell (its maps are the
    ground truth plus small noise; interval=1's plus large noise), each with its saved maps and marker."""
    tmp = tmp_path_factory.mktemp("abl")
    path = write_spec(tmp, 'table = "none"\n[[grid]]\ninterval = [1, 0.5]\n', TAIL)
    spec, out = load_spec(path), tmp / "out"
    scenes = prepare_evaluation(spec, out, quiet)
    (folder, _), = scenes
    scene = HCIScene(Path(folder))
    combined = Results(meta={"scenes": [folder]})
    for res in run_methods(spec, out, scenes, quiet):
        combined.extend(res)
        combined.meta.setdefault("references", []).extend(res.meta.get("references", []))
    rng = np.random.default_rng(0)
    gt = scene.gt_disparity()
    for cid, noise, badpix in ((CELLS[0], 0.5, 60.0), (CELLS[1], 0.02, 10.0)):
        write_submission(out / "cells" / cid / "maps", {scene.name: gt + rng.normal(scale=noise, size=gt.shape)})
        combined.records += [Record(cid, scene.name, "badpix_0.07", badpix, "lowres"),
                             Record(cid, scene.name, "mse_x100", badpix / 10, "lowres")]
        (out / "cells" / cid / "cell.json").write_text(json.dumps({"id": cid, "train_s": 1.0, "own_train_s": 1.0}))
        (out / "cells" / cid / "timing.json").write_text(json.dumps({"test_s": 0.5, "time_size": 16,
                                                                     "device": "cpu", "threads": 1}))
    combined.write(out)
    return path, out, scene.name


def _drawn(out: Path, scene: str) -> tuple[set[str], set[str]]:
    """Labels whose maps the site's scene page shows, and the rows of the error-map figure's overview."""
    page = (out / "html" / f"scene-{scene}.html").read_text(encoding="utf-8")
    labels = {label for label in (*CELLS, "Zero map", "Oracle") if f"/{safe_name(label)}.disp.png" in page}
    figures = {p.name for p in (out / "figures" / "error_maps").glob("*.png")}
    return labels, figures


def test_maps_all_best_none(ablation):
    path, out, scene = ablation
    assert main(["ablate", str(path), "--out", str(out), "--report-only", "--html", "--maps", "all"]) == 0
    labels, figures = _drawn(out, scene)
    assert labels == {*CELLS, "Zero map", "Oracle"} and f"overview_{scene}.png" in figures
    index = (out / "html" / "index.html").read_text(encoding="utf-8")
    assert "Maps drawn with --maps" not in index
    # the oracle among the [[methods]] is a reference row, not ranked
    overview = index.split('id="table-overview"', 1)[1].split("</table>", 1)[0]
    assert 'data-v="Oracle"' in overview.split('<tbody class="reference">', 1)[1]

    assert main(["ablate", str(path), "--out", str(out), "--report-only", "--html", "--maps", "best"]) == 0
    labels, figures = _drawn(out, scene)
    assert labels == {"interval=0.5", "Zero map", "Oracle"}  # the best cell and the extra methods
    assert f"overview_{scene}.png" in figures
    assert "Maps drawn with --maps best" in (out / "html" / "index.html").read_text(encoding="utf-8")

    assert main(["ablate", str(path), "--out", str(out), "--report-only", "--html", "--no-maps"]) == 0
    labels, figures = _drawn(out, scene)
    assert labels == set() and figures == set()
    assert (out / "table_cells.md").is_file() and (out / "html" / "index.html").is_file()  # the rest is there
    assert "Maps drawn with --maps none" in (out / "html" / "index.html").read_text(encoding="utf-8")


def test_best_cell_and_the_drawn_folders(ablation):
    path, out, _ = ablation
    spec, results = load_spec(path), Results.read(out)
    assert best_cell(spec, results) == "interval=0.5"
    assert best_cell(spec, results, "mse_x100") == "interval=0.5"
    assert best_cell(spec, Results()) is None
    assert set(drawn_map_folders(spec, results, out, "best")) == {"interval=0.5", "Zero map", "Oracle"}
    assert set(drawn_map_folders(spec, results, out, "all")) == {*CELLS, "Zero map", "Oracle"}
    assert drawn_map_folders(spec, results, out, "none") == {}
    with pytest.raises(SpecError, match="--maps must be one of all, best, none"):
        drawn_map_folders(spec, results, out, "some")


def test_a_bad_maps_value_is_one_line(ablation, capsys):
    path, out, _ = ablation
    with pytest.raises(SystemExit) as exc:
        main(["ablate", str(path), "--out", str(out), "--report-only", "--maps", "some"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--maps: invalid choice: 'some'" in err[0]
    from lfbench.ablation.runner import report_only

    with pytest.raises(SpecError, match="--maps must be one of"):  # the library checks before any work
        report_only(load_spec(path), out / "nowhere", maps="some")
    assert not (out / "nowhere").exists()
