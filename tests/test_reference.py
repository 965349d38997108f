"""References (issue 21.5): a paper's tables beside ours are data its method's plugin ships (SubFocal's:
methods/subfocal/paper.toml, registered under the entry-point group lfbench.references), read strictly;
core names no paper: labels, files, the best loss and beta come from the reference, and which reference
an ablation uses follows from its spec."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pandas as pd
import pytest
from test_ablate import quiet, write_paper, write_spec

from lfbench.ablation import report
from lfbench.ablation.facts import cell_info
from lfbench.ablation.significance import comparisons
from lfbench.ablation.spec import load_spec
from lfbench.reports.paper import load_paper
from lfbench.reports.reference import (
    PaperTable,
    Reference,
    default_reference,
    get_reference,
    list_references,
    read_reference,
    reference_for_network,
)
from lfbench.utils.errors import SpecError

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = ROOT / "methods" / "subfocal" / "paper.toml"


def test_subfocal_ships_its_paper_as_a_registered_reference():
    pyproject = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert pyproject["project"]["entry-points"]["lfbench.references"] == {
        "subfocal-tci2023": "lfbench_methods.subfocal:paper.toml"}
    assert "subfocal/*.toml" in pyproject["tool"]["setuptools"]["package-data"]["lfbench_methods"]
    paper = list_references()["subfocal-tci2023"]
    assert paper == read_reference(SHIPPED)
    assert paper.methods == ("SubFocal",) and paper.label == "paper (RTX 3090, full training)"
    assert paper.table("table4").extra["train_time"] == "train_hours_rtx3090"
    assert paper.table("table5").names == {"l1": "baseline_l1"} and paper.table("table5").where == {"beta": "0.1"}
    assert paper.table("table5").best == "uafl" and paper.table("beta").best == "0.1"
    assert [t.id for t in paper.ablation_tables()] == ["table4", "table5", "beta"]
    assert default_reference() == paper  # the default network's (subfocal) paper
    assert reference_for_network("lfattnet") == paper and reference_for_network("tinycnn") is None
    with pytest.raises(SpecError, match="Unknown reference 'nope'. Available: subfocal-tci2023"):
        get_reference("nope")


def test_the_core_spells_no_paper():
    """What the paper is lives in the plugin's data file, not in lfbench's code (reference.py's docstring
    shows the file layout with SubFocal's values as its example)."""
    for path in (ROOT / "lfbench").rglob("*.py"):
        code = path.read_text()
        if path.name != "reference.py":
            assert "RTX" not in code and "rtx3090" not in code, path
        assert "PAPER_UAFL_BETA" not in code and '("SubFocal",)' not in code, path


@pytest.mark.parametrize("text, message", [
    ('name = "x"\n', "networks: is required"),
    (SHIPPED.read_text().replace('name = "subfocal-tci2023"', 'name = "x"\nnetwork = "subfocal"'),
     "unknown key\\(s\\): network"),
    (SHIPPED.read_text().replace('trend = { interval = "lower" }', 'trend = { interval = "finer" }'),
     "trend: interval: expected lower or higher"),
    (SHIPPED.read_text().replace('measures = ["stage_train_time"]', 'measures = ["gpu_hours"]'),
     "measures: unknown gpu_hours"),
    (SHIPPED.read_text().replace('methods = ["SubFocal"]', 'methods = "SubFocal"'), "methods: expected"),
    (SHIPPED.read_text().replace('names = { l1 = "baseline_l1" }', 'names = { l1 = 1 }'),
     r"tables\[4\].names: expected"),
    (SHIPPED.read_text().replace('id = "table5"', 'id = "table4"'), "table id 'table4' declared twice"),
    (SHIPPED.read_text().replace('figure = "time"', 'figure = "bars"'), r"tables\[3\].figure: expected one of"),
    (SHIPPED.read_text().replace('scene_metric = "badpix_0.07"', ''), r"tables\[2\].scene_metric: is required"),
    (SHIPPED.read_text().replace('file = "table3_urbanlf.csv"', 'file = "table3_urbanlf.csv"\ncolumns = 3'),
     r"\[tables\[2\]\] unknown key\(s\): columns"),
])
def test_a_reference_file_is_read_strictly(tmp_path, text, message):
    path = tmp_path / "ref.toml"
    path.write_text(text)
    with pytest.raises(SpecError, match=message) as err:
        read_reference(path)
    assert str(path) in str(err.value)


SHIPPED_TABLE4 = 'title = "t4"\ntable = "table4"\n[[grid]]\ninterval = [1, 0.5]\n'


def test_which_reference_a_spec_stands_beside(tmp_path):
    paper = default_reference()
    none = load_spec(write_spec(tmp_path, 'title = "plugin-like"\ntable = "none"\n[[grid]]\ninterval = [1]\n',
                                name="none.toml"))
    assert none.paper_methods is None and report.spec_reference(none) is None  # nothing asked
    assert report.spec_reference(none, paper="DIR") == paper  # --paper asks
    asked = load_spec(write_spec(tmp_path, 'title = "a"\ntable = "none"\n[[grid]]\ninterval = [1]\n',
                                 '[report]\npaper_methods = ["SubFocal", "LFattNet"]\n', name="asked.toml"))
    assert asked.paper_methods == ("SubFocal", "LFattNet") and report.spec_reference(asked) == paper
    table4 = load_spec(write_spec(tmp_path, SHIPPED_TABLE4, name="t4.toml"))
    assert report.spec_reference(table4) == paper
    off = load_spec(write_spec(tmp_path, SHIPPED_TABLE4, '[report]\nreference = "none"\n', name="off.toml"))
    assert report.spec_reference(off, paper="DIR") is None
    with pytest.raises(SpecError, match="Unknown reference 'nope'"):  # when the spec is read, before any work
        load_spec(write_spec(tmp_path, SHIPPED_TABLE4, '[report]\nreference = "nope"\n', name="bad.toml"))


def test_labels_and_orderings_come_from_the_reference(tmp_path):
    """A made-up paper that finds MSE best and labels its columns its own way: the tables follow it."""
    spec = load_spec(write_spec(tmp_path, 'seeds = [1, 2]\ntable = "table5"\n[[grid]]\nloss = ["l1", "mse", "uafl"]\n'))
    other = Reference(name="other", networks=("subfocal",), methods=("OACC-Net",), label="paper (A100, 2 h)",
                      benchmark_note="paper: other, Tables I/II", ablation_note="paper: other",
                      tables=(PaperTable(id="table5", file="table5_losses.csv", keys=("loss",), best="mse",
                                         names={"l1": "baseline_l1"}, metrics={"badpix_0.07": "badpix_0.07"}),))
    comps = comparisons(other.table("table5"), cell_info(spec, ("loss",)))
    assert {(c.claim, c.worse.split("_seed")[0]) for c in comps} == {
        ("loss mse better than loss l1", "loss=l1"), ("loss mse better than loss uafl", "loss=uafl")}
    assert report.paper_key(spec.cells[0].config, other.table("table5")) == ("baseline_l1",)
    assert report.paper_key(spec.cells[4].config, other.table("table5")) == ("uafl",)  # no where: any beta of UAFL
    tables = load_paper(write_paper(tmp_path / "paper"), other)
    assert tables.default_methods == ("OACC-Net",)
    frame = pd.DataFrame({"loss": ["l1", "mse"], "badpix_0.07": [3.0, 2.0], "mse_x100": [1.0, 1.0],
                          "own_train_s": [60.0, 60.0]}, index=["loss=l1_seed=1", "loss=mse_seed=1"])
    t5 = report.reference_table(spec, frame, other.table("table5"), tables, quiet)
    assert "BadPix 0.07 (%), paper (A100, 2 h)" in t5.columns
    assert t5.loc["loss=l1_seed=1", "BadPix 0.07 (%), paper (A100, 2 h)"] == 12.5  # its baseline_l1 row
