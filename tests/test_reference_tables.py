"""Issue 29.2 / 30.4: a paper's tables are generic declarations, read by one "our cells beside a declared
table" in the ablation report (no SubFocal table in lfbench's code): another paper's table with other axes
and another metric is rendered with its labels and join without editing lfbench; the cost of a cell is its
trainable's hook; and an ablation scored on UrbanLF-Syn scenes writes the paper's Table III beside its cells,
as ``lfbench report`` does."""

from __future__ import annotations

import ast
import math
from pathlib import Path
from types import SimpleNamespace

import pandas as pd
import pytest
from helpers import isolate_registries
from test_ablate import quiet, write_spec
from test_table3 import write_paper3

import lfbench.reports.reference as reference_module
from lfbench.ablation import report
from lfbench.ablation.facts import cell_info
from lfbench.ablation.runner import _cost_estimate, run_ablation
from lfbench.ablation.significance import comparisons
from lfbench.ablation.spec import load_spec
from lfbench.method.trainable import Trainable, get_trainable, register_trainable
from lfbench.reports.reference import PaperTable, Reference
from lfbench.results import Record, Results
from lfbench.utils.errors import SpecError
from lfbench.utils.registry import Registry

# A made-up paper of another network: its table joins our `width` to its `channels` column and our
# `interpolation` to its `resampling` column, reports BadPix 0.03 and Q25 (not SubFocal's BadPix 0.07 / MSE)
# and a GPU time, and states that a wider network is better.
OTHER = Reference(
    name="other-2026", networks=("subfocal",), methods=("Other",), label="other (A100)",
    benchmark_note="other: Tables I/II", ablation_note="other: its ablation, A100",
    tables=(PaperTable(id="widths", file="widths.csv", caption="other: widths", keys=("channels", "resampling"),
                       axes={"width": "channels", "interpolation": "resampling"},
                       metrics={"badpix_0.03": "bp3", "q25_x100": "q25"}, measures=("test_time",),
                       extra={"test_time": "gpu_s", "params": "params_m"},
                       labels={"width": "channels of the cost volume", "test_time": "GPU time (s), A100"},
                       names={"bilinear": "lin"}, trend={"width": "higher"}, figure="time"),))
SPEC = 'title = "widths"\ntable = "widths"\n[[grid]]\nwidth = [2, 3]\n'


@pytest.fixture
def other_registered(monkeypatch):
    """OTHER as if a plugin registered it under lfbench.references (no lfbench file edited)."""
    registry = Registry("reference", reference_module.Reference)
    registry.add("other-2026", OTHER)
    monkeypatch.setattr(reference_module, "REFERENCES", registry)
    return OTHER


def _scores(spec) -> tuple[Results, list[dict]]:
    res = Results()
    for k, cell in enumerate(spec.cells):
        for metric, value in (("badpix_0.03", 30.0 + k), ("q25_x100", 5.0 + k), ("badpix_0.07", 9.0)):
            res.records.append(Record(cell.id, "synth_5_0", metric, value, "lowres"))
    markers = [{"id": c.id, "train_s": 60.0, "own_train_s": 30.0, "test_s": 2.0 + k, "time_size": 16,
                "device": "cpu", "threads": 1} for k, c in enumerate(spec.cells)]
    return res, markers


def test_another_papers_table_is_joined_and_labelled_as_declared(tmp_path, other_registered):
    spec = load_spec(write_spec(tmp_path, SPEC, '[report]\nreference = "other-2026"\n'))
    paper = tmp_path / "paper"
    paper.mkdir()
    (paper / "table1_per_scene.csv").write_text("method,scene,metric,value\nOther,dots,badpix_0.07,1.5\n")
    (paper / "table2_average.csv").write_text("method,metric,value\nOther,badpix_0.07,2.5\n")
    (paper / "widths.csv").write_text("channels,resampling,bp3,q25,gpu_s,params_m\n2,lin,31.5,4.25,0.5,1.1\n"
                                      "3,lin,29.5,3.75,0.75,2.2\n3,nearest,99,99,9,9\n")
    res, markers = _scores(spec)
    written = report.write_report(spec, tmp_path / "out", res, markers, paper=paper, log=quiet)
    names = {p.name for p in written}
    assert {"table_widths.csv", "accuracy_vs_test_time.png"} <= names and "table4.csv" not in names
    table = pd.read_csv(tmp_path / "out" / "table_widths.csv").set_index("cell")
    ours = f"ours ({spec.budget_label()})"
    assert list(table.columns) == [
        "channels of the cost volume", "interpolation", "paper row", f"BadPix 0.03 (%), {ours}",
        "BadPix 0.03 (%), other (A100)", f"Q25, {ours}", "Q25, other (A100)",
        "test time (s), ours (9x9x16x16, cpu, 1 thread)", "GPU time (s), A100", "params, other (A100)"]
    row = table.loc["width=3"]
    assert row["paper row"] == "3 / lin"  # our bilinear is its "lin"
    assert row[f"BadPix 0.03 (%), {ours}"] == 31.0 and row["BadPix 0.03 (%), other (A100)"] == 29.5
    assert row[f"Q25, {ours}"] == 6.0 and row["Q25, other (A100)"] == 3.75
    assert row["GPU time (s), A100"] == 0.75 and row["params, other (A100)"] == 2.2
    assert table.loc["width=2", "BadPix 0.03 (%), other (A100)"] == 31.5
    md = (tmp_path / "out" / "table_widths.md").read_text()
    assert "other: its ablation, A100" in md and "BadPix 0.07" not in md.split("\n\n", 1)[1].split("\n")[0]
    # the declared trend, tested in the declared first metric
    comps = comparisons(OTHER.table("widths"), cell_info(spec, tuple(OTHER.table("widths").join)))
    assert [(c.claim, c.better, c.worse) for c in comps] == [("bilinear: width 3 better than 2", "width=3",
                                                              "width=2")]


def test_a_table_the_reference_does_not_declare_is_refused_when_the_spec_is_read(tmp_path, other_registered):
    with pytest.raises(SpecError, match=r"table: expected one of widths, tables12, none \(reference 'other-2026'\), "
                                        r"got 'table4'") as err:
        load_spec(write_spec(tmp_path, SPEC.replace('"widths"\n[[', '"table4"\n[['),
                             '[report]\nreference = "other-2026"\n'))
    assert str(tmp_path / "spec.toml") in str(err.value)


class _Costly(Trainable):
    """A toy network whose cost grows with its channels (the hook under test)."""

    calls: list = []

    def cost_estimate(self, model, steps):
        type(self).calls.append((dict(model), steps))
        return 10.0 * model.get("channels", 1) * steps


def test_the_cost_of_a_cell_is_its_trainables_hook(monkeypatch):
    isolate_registries(monkeypatch)  # the toy network is forgotten after the test (others list every network)
    register_trainable("toycost-29")(_Costly)
    task = SimpleNamespace(network="toycost-29", stage1_dir=None,
                           config={"model": {"channels": 4}, "stages": [{"steps": 3}, {"steps": 2}]})
    assert _cost_estimate(task) == 200.0 and _Costly.calls == [({"channels": 4}, 5)]
    task.stage1_dir = "shared"  # the shared stage 1 is not the cell's own cost
    assert _cost_estimate(task) == 80.0 and _Costly.calls[-1] == ({"channels": 4}, 2)
    # a network without the hook: the steps; SubFocal: candidates x steps, phase shifts 1.6x
    assert Trainable().cost_estimate({}, 7) is None
    sub = get_trainable("subfocal")
    assert sub.cost_estimate({"interval": 0.5, "interpolation": "phase"}, 10) == pytest.approx(17 * 10 * 1.6)
    assert sub.cost_estimate({"interval": 1.0, "d_min": -0.5, "d_max": 1.5}, 4) == 12.0


def test_an_ablation_scored_on_urbanlf_writes_table3_beside_the_paper(tmp_path):
    """The cells are scored on UrbanLF-Syn-layout samples (the spec's data through the dataset seam, by its
    protocol) and the ablation report puts Table III beside the paper's rows, as `lfbench report` does."""
    from lfbench.cli import main

    assert main(["synth", "--layout", "urbanlf-syn", "--size", "64x48", "--numbers", "11,27",
                 "--out", str(tmp_path / "data")]) == 0
    spec_path = write_spec(tmp_path, 'title = "t3"\n', evaluation='data = "data"\nerror_maps = false\n')
    spec_path.write_text(spec_path.read_text().replace("synthetic = { seed = 5, size = 48, scenes = 1 }\n", ""))
    spec = load_spec(spec_path)
    paper = write_paper3(tmp_path / "paper")
    run_ablation(spec, tmp_path / "out", progress=False, paper=paper, log=quiet)
    out = tmp_path / "out"
    results = Results.read(out / "results.json")
    assert results.meta["dataset"] == "urbanlf-syn" and set(results.scenes) == {"Image11", "Image27"}
    assert "q25_x100" not in {r.metric for r in results.records}  # scored by UrbanLF-Syn's protocol
    table = pd.read_csv(out / "table_table3_paper.csv").set_index("method")
    assert list(table.index) == ["base", "LFattNet (paper)", "SubFocal (paper)"]
    ours = {r.scene: r.value for r in results.records if r.metric == "badpix_0.07"}
    assert table.loc["base", "Img11"] == pytest.approx(ours["Image11"], rel=1e-5, abs=1e-9)
    assert table.loc["base", "badpix_0.07"] == pytest.approx((ours["Image11"] + ours["Image27"]) / 2, rel=1e-5,
                                                             abs=1e-9)
    assert table.loc["base", "scenes"] == 2 and math.isnan(table.loc["base", "Img50"])
    assert table.loc["SubFocal (paper)", "Img27"] == 1.5 and table.loc["SubFocal (paper)", "params_millions"] == 5.06
    caption = (out / "table_table3_paper.md").read_text()
    assert "Table III (UrbanLF-Syn" in caption and "t3: table3 beside the paper's" in caption
    cells = pd.read_csv(out / "table_cells.csv")
    assert [c for c in cells.columns if c.startswith(("BadPix", "MSE", "Q25"))] == [
        f"BadPix {t} (%), ours ({spec.budget_label()})" for t in ("0.07", "0.03", "0.01")] + [
        f"MSE x100, ours ({spec.budget_label()})"]


def test_no_paper_table_adapters_remain():
    assert not hasattr(reference_module, "Table4") and not hasattr(Reference, "table4")
    for path in Path(report.__file__).parent.glob("*.py"):  # the ablation's code names no paper's table or axis
        tree = ast.parse(path.read_text())
        docs = {id(node.body[0].value) for node in ast.walk(tree) if isinstance(
            node, ast.Module | ast.ClassDef | ast.FunctionDef) and node.body and isinstance(node.body[0], ast.Expr)}
        strings = {node.value for node in ast.walk(tree) if isinstance(node, ast.Constant)
                   and isinstance(node.value, str) and id(node) not in docs and path.name != "reference.py"}
        assert not strings & {"table4", "table5", "beta", "interval", "interpolation", "uafl"}, path


def test_figure_and_table_labels_come_from_the_metric_definitions(tmp_path):
    import numpy as np

    from lfbench.reports.sweep_table import sweep_figure, sweep_table
    from lfbench.reports.uncertainty import _measure_label
    from lfbench.scoring.uncertainty import Sparsification
    from lfbench.training.curves import _validation_labels

    assert _validation_labels([{"badpix": 3.0, "threshold": 0.03}]) == ("BadPix 0.03 (%)", "MSE x100")
    assert _validation_labels([{"badpix": 3.0}]) == ("BadPix (%)", "MSE x100")  # no threshold recorded
    f = np.linspace(0, 0.9, 4)
    sp = Sparsification(f, 1 - f, 0.5 * (1 - f), np.ones_like(f), "badpix_0.015", "%", 100, False)
    assert _measure_label(sp) == "BadPix(0.015) of remaining pixels [%]"
    frame = pd.DataFrame({"label": ["a"] * 3, "method": ["planesweep"] * 3, "interval": [0.5] * 3,
                          "interpolation": ["nearest"] * 3, "subpixel": ["equiangular"] * 3, "scene": ["s"] * 3,
                          "metric": ["q25_x100", "badpix_0.015", "mse_x100"], "value": [1.0, 2.0, 3.0],
                          "runtime_s": [1.0] * 3})
    table = sweep_table(frame)  # the metrics the frame holds, in the one display order, labelled by Metric
    assert list(table.columns[3:]) == ["MSE x100", "Q25", "BadPix 0.015 (%)", "time per scene (s)"]
    assert list(sweep_table(frame, ["badpix_0.015"]).columns[3:]) == ["BadPix 0.015 (%)", "time per scene (s)"]
    assert sweep_figure(table, tmp_path / "q25.png", "q25_x100").stat().st_size > 1000


def test_an_ordering_in_a_metric_where_higher_is_better_is_tested_in_its_direction(monkeypatch):
    """A declared table whose first metric is higher-is-better (a plugin's): its trend is reproduced when the
    better variant scores higher, not reversed."""
    import lfbench.ablation.significance as significance

    table = PaperTable(id="x", keys=("k",), metrics={"accuracy": ""}, trend={"k": "higher"})
    info = pd.DataFrame({"variant": ["k=1", "k=1", "k=2", "k=2"], "seed": [1, 2, 1, 2], "k": [1, 1, 2, 2]},
                        index=["k=1_seed=1", "k=1_seed=2", "k=2_seed=1", "k=2_seed=2"])
    scores = pd.DataFrame({"method": list(info.index), "scene": ["s"] * 4, "metric": ["accuracy"] * 4,
                           "value": [50.0, 51.0, 90.0, 92.0]})
    accuracy = SimpleNamespace(higher_is_better=True, badness=lambda v: -v)  # as Metric.badness where higher is better
    monkeypatch.setattr(significance.METRICS, "find", lambda _: accuracy)
    row = significance.significance_table(table, info, scores).iloc[0]
    assert row["claim (paper)"] == "k 2 better than 1" and row["better"] == "k=2"
    assert row["difference (worse - better)"] == pytest.approx(40.5) and row["verdict"] == "reproduced"
