"""lfbench ablate: grid expansion, shared stage 1 (bit-identical to a plain two-stage run), resume
(finished cells skipped, an interrupted cell resumed from its checkpoint), paper values beside ours,
and one-line spec errors. Training runs are tiny (width 2, patch 16, batch 1, 1 thread, 48 px scenes)."""

from __future__ import annotations

import importlib.util
import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch

from lfbench.ablation import facts, report
from lfbench.ablation.runner import run_ablation
from lfbench.ablation.spec import load_spec
from lfbench.results import Record, Results
from lfbench.training import checkpoint as ckpt
from lfbench.utils.errors import SpecError

TINY_BASE = """
[base]
seed = 3
[base.data]
train = ["synthetic"]
patch = 16
strides = [1]
stride_weights = [1]
[[base.data.synthetic]]
category = "synthetic"
seed = 1
size = 48
scenes = 1
[base.augment]
enabled = false
[base.model]
width = 2
interval = 1.0
interpolation = "bilinear"
[base.training]
batch_size = 1
device = "cpu"
checkpoint_every = 1
log_every = 1
prefetch = 0
[[base.stages]]
name = "l1"
loss = "l1"
lr = 1e-3
steps = 2
[[base.stages]]
name = "uafl"
loss = "uafl"
beta = 0.1
lr = 1e-4
steps = 1

[budget]
threads = 1

[evaluation]
synthetic = { seed = 5, size = 48, scenes = 1 }
time_size = 16
threads = 1
"""


def write_spec(folder: Path, head: str, tail: str = "", name: str = "spec.toml", evaluation: str = "") -> Path:
    """head + the tiny base config, budget and [evaluation] (+ ``evaluation`` lines) + tail."""
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / name
    path.write_text(head + TINY_BASE + evaluation + tail, encoding="utf-8")
    return path


def write_paper(folder: Path) -> Path:
    """A made-up paper folder (the values are not the paper's)."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "table1_per_scene.csv").write_text("method,scene,metric,value\nSubFocal,dots,badpix_0.07,1.5\n")
    (folder / "table2_average.csv").write_text("method,metric,value\nSubFocal,badpix_0.07,2.5\n")
    (folder / "table4_interval_interp.csv").write_text(
        "interval,interpolation,badpix_0.07,mse_x100,train_hours_rtx3090,test_seconds_512x512_rtx3090\n"
        "0.5,bilinear,11.11,0.222,33,4.4\n1,bilinear,55.55,0.666,77,8.8\n")
    (folder / "table5_losses.csv").write_text("loss,badpix_0.07\nbaseline_l1,12.5\nmse,9.75\nuafl,7.25\n")
    return folder


def quiet(_msg: str) -> None:
    pass


def load_state(path: Path) -> dict:
    return torch.load(path, map_location="cpu", weights_only=True)


# --------------------------------------------------------------------------- grid expansion (no training)

TABLE4_GRID = """
title = "t4"
table = "table4"
[[grid]]
interval = [1.0, 0.5, 0.25, 0.1]
interpolation = ["bilinear"]
[[grid]]
interval = [0.5]
interpolation = ["phase", "nearest", "bilinear"]
"""


def test_table4_grid_expands_to_six_cells_with_the_budget(tmp_path):
    spec = load_spec(write_spec(tmp_path, TABLE4_GRID))
    ids = [c.id for c in spec.cells]
    assert ids == ["interval=1_interpolation=bilinear", "interval=0.5_interpolation=bilinear",
                   "interval=0.25_interpolation=bilinear", "interval=0.1_interpolation=bilinear",
                   "interval=0.5_interpolation=phase", "interval=0.5_interpolation=nearest"]  # 0.5 bilinear once
    for cell in spec.cells:
        model = cell.config["model"]
        assert (model["interval"], model["interpolation"]) == (cell.values["interval"], cell.values["interpolation"])
        assert model["width"] == 2 and [s["steps"] for s in cell.config["stages"]] == [2, 1]
        assert cell.config["stages"][1] == {"name": "uafl", "loss": "uafl", "beta": 0.1, "lr": 1e-4, "steps": 1,
                                            "eps": 1e-7, "betas": [0.9, 0.999]}
    # the budget overrides the base; [set] reaches any other key
    budget = """
[budget]
steps = [7, 3]
batch = 2
model = { width = 4 }
patch = 24
threads = 1
[set]
training.log_every = 5
"stages.uafl.lr" = 2e-4
data.scene_weights = { synth_1_0 = 2.0 }
"""
    text = (TABLE4_GRID + TINY_BASE).replace("[budget]\nthreads = 1\n", budget)
    (tmp_path / "b.toml").write_text(text)
    spec = load_spec(tmp_path / "b.toml")
    c = spec.cells[0].config
    assert [s["steps"] for s in c["stages"]] == [7, 3] and c["training"]["batch_size"] == 2
    assert c["model"]["width"] == 4 and c["data"]["patch"] == 24
    assert c["training"]["log_every"] == 5 and c["stages"][1]["lr"] == 2e-4
    assert c["data"]["scene_weights"] == {"synth_1_0": 2.0} and c["training"]["batch_size"] == 2
    assert spec.budget_label() == "width 4, batch 2, patch 24, 7+3 steps, cpu"
    # a dotted training-config key as a grid axis (quoted or not)
    spec = load_spec(write_spec(tmp_path, "[[grid]]\nmodel.attention = [true, false]\n", name="c.toml"))
    assert [(c.id, c.config["model"]["attention"]) for c in spec.cells] == [("model.attention=true", True),
                                                                           ("model.attention=false", False)]


def test_only_the_synthetic_sets_the_cells_read_are_generated(tmp_path):
    """A base config's validation set that [set] "data.validation" = [] leaves unused is not generated."""
    from lfbench.ablation.runner import prepare_training_data

    sets = ('"data.synthetic" = [{category = "synthetic", seed = 1, size = 16, scenes = 1}, '
            '{category = "synthetic_val", seed = 2, size = 16, scenes = 1}]\n')
    for validation, generated in (("[]", ["synthetic_s1_16px_1"]),
                                  ('["synthetic_val"]', ["synthetic_s1_16px_1", "synthetic_val_s2_16px_1"])):
        out = tmp_path / validation.strip('[]"') / "out"
        spec = load_spec(write_spec(out.parent, "", f'[set]\n{sets}"data.validation" = {validation}\n'))
        links = prepare_training_data(spec.cells, out, quiet)
        assert sorted(p.name for p in (out / "data").iterdir()) == generated
        assert sorted(links["base"]) == sorted(n.split("_s")[0] for n in generated)


def test_a_cell_data_name_that_selects_nothing_is_refused_before_anything_is_written(tmp_path):
    spec = load_spec(write_spec(tmp_path, "", '[set]\n"data.validation" = ["nosuch"]\n'))
    with pytest.raises(SpecError, match=r"spec.toml: \[data\] no scene 'nosuch'; available: synth_1_0"):
        run_ablation(spec, tmp_path / "out", progress=False, log=quiet)
    assert not (tmp_path / "out").exists()


def test_loss_and_beta_axes(tmp_path):
    spec = load_spec(write_spec(tmp_path, """
table = "table5"
[[grid]]
loss = ["l1", "mse", "l1+js", "uafl", {loss = "uafl", beta = 0.5}]
[stage1]
shared = true
"""))
    last = {c.id: c.config["stages"][-1] for c in spec.cells}
    assert list(last) == ["loss=l1", "loss=mse", "loss=l1+js", "loss=uafl", "loss=uafl_beta=0.5"]
    assert last["loss=mse"] == {"name": "finetune_mse", "loss": "mse", "lr": 1e-4, "steps": 1, "eps": 1e-7,
                                "betas": [0.9, 0.999]}  # the uafl beta is not carried over
    assert last["loss=l1"]["name"] == "finetune_l1" and "beta" not in last["loss=l1"]
    assert last["loss=uafl"].get("beta") is None  # the loss's default (0.1)
    assert last["loss=uafl_beta=0.5"]["beta"] == 0.5
    assert all(c.config["stages"][0] == spec.cells[0].config["stages"][0] for c in spec.cells)
    table5 = report.spec_table(spec, report.spec_reference(spec))
    assert [report.paper_key(c.config, table5) for c in spec.cells] == [
        ("baseline_l1",), ("mse",), ("l1+js",), ("uafl",), None]  # the paper's UAFL row is at beta 0.1

    spec = load_spec(write_spec(tmp_path, "table = \"beta\"\n[[grid]]\nloss = [\"uafl\"]\nbeta = [1.0, 0.25]\n",
                                name="beta.toml"))
    assert [c.id for c in spec.cells] == ["loss=uafl_beta=1", "loss=uafl_beta=0.25"]
    assert [facts.loss_param(c.config, "beta") for c in spec.cells] == [1.0, 0.25]
    assert [facts.axis_value(c.config, "beta") for c in spec.cells] == [1.0, 0.25]


def run_main(args: list[str], capsys) -> tuple[int, str]:
    from lfbench.cli import main

    code = main(args)
    return code, capsys.readouterr().err


@pytest.mark.parametrize("head, tail, key", [
    ("tabel = \"table4\"\n", "", "unknown key(s): tabel"),
    ("[[grid]]\nintervall = [1.0]\n", "", "grid[0].intervall: unknown axis"),
    ("[[grid]]\ninterpolation = [\"bicubic\"]\n", "", "grid[0] cell interpolation=bicubic: [model]: interpolation"),
    ("[[grid]]\ninterval = 0.5\n", "", "grid[0].interval: expected a non-empty list"),
    ("table = \"table9\"\n", "", "table: expected one of"),
    ("", "[set]\n\"training.threads\" = \"two\"\n", "set: training.threads: expected int"),
    ("", "[set]\n\"stages.7.lr\" = 0.1\n", "set.stages.7.lr: stage 7 does not exist"),
    ("[[grid]]\ninterval = [1.0, 2.0]\n[stage1]\nshared = true\n", "", "stage1.shared: cell interval=2 differs"),
])
def test_bad_spec_is_one_line_naming_file_and_key(tmp_path, capsys, head, tail, key):
    path = write_spec(tmp_path, head, tail)
    code, err = run_main(["ablate", str(path), "--list"], capsys)
    assert code == 2
    assert err.count("\n") == 1 and str(path) in err and key in err, err


def test_bad_budget_and_missing_base(tmp_path, capsys):
    path = write_spec(tmp_path, "").parent / "spec.toml"
    path.write_text(path.read_text().replace("[budget]\nthreads = 1\n", "[budget]\nsteps = [5]\n"))
    code, err = run_main(["ablate", str(path), "--list"], capsys)
    assert code == 2 and "budget.steps: expected 2 numbers" in err and str(path) in err
    # [budget.model] holds the network's own parameters, of their types; the old budget.width says where it went
    for budget, problem in (("model = { width = 2.5 }", "budget.model.width: expected int, got float"),
                            ("model = { widht = 4 }", "[budget.model] unknown key(s): widht (accepted: angular, "
                                                      "attention, d_max, d_min, interpolation, interval, width)"),
                            ("width = 4", "budget.width: is now [budget.model] width")):
        path.write_text(write_spec(tmp_path, "").read_text().replace("[budget]\nthreads = 1\n",
                                                                     f"[budget]\n{budget}\n"))
        code, err = run_main(["ablate", str(path), "--list"], capsys)
        assert code == 2 and err.count("\n") == 1 and problem in err and str(path) in err, err
    other = tmp_path / "nobase.toml"
    other.write_text("base = \"missing.toml\"\n[evaluation]\nsynthetic = {seed = 1, size = 48, scenes = 1}\n")
    code, err = run_main(["ablate", str(other)], capsys)
    assert code == 2 and "base: training config" in err and "not found" in err and str(other) in err


# --------------------------------------------------------------------------- Table IV with made-up paper numbers

def test_table4_puts_the_paper_value_beside_ours(tmp_path):
    spec = load_spec(write_spec(tmp_path, TABLE4_GRID))
    paper = report.load_paper_tables(write_paper(tmp_path / "paper"), quiet)
    res = Results()
    for k, cell in enumerate(spec.cells):
        for scene, offset in (("a", 0.0), ("b", 2.0)):
            res.records.append(Record(cell.id, scene, "badpix_0.07", 10.0 * k + offset, "lowres"))
            res.records.append(Record(cell.id, scene, "mse_x100", 1.0 + k, "lowres"))
    markers = [{"id": c.id, "train_s": 60.0 * (k + 1), "test_s": 0.5 * (k + 1), "time_size": 64, "device": "cpu",
                "threads": 1} for k, c in enumerate(spec.cells)]
    frame = report.cell_frame(spec, res, markers)
    table4 = report.spec_table(spec, report.spec_reference(spec))
    t4 = report.reference_table(spec, frame, table4, paper, quiet)
    ours = f"BadPix 0.07 (%), ours ({spec.budget_label()})"
    theirs = "BadPix 0.07 (%), paper (RTX 3090, full training)"
    row = t4.loc["interval=0.5_interpolation=bilinear"]
    assert row[ours] == pytest.approx(11.0)  # (10 + 12) / 2, the second cell
    assert row[theirs] == 11.11 and row["MSE x100, paper (RTX 3090, full training)"] == 0.222
    assert row[f"train time (min), ours ({spec.budget_label()})"] == pytest.approx(2.0)
    assert row["train time (h), paper (RTX 3090, full training)"] == 33
    assert row["test time (s), ours (9x9x64x64, cpu, 1 thread)"] == 1.0
    assert row["test time (s), paper (RTX 3090, 512x512)"] == 4.4
    assert t4.loc["interval=1_interpolation=bilinear", theirs] == 55.55
    assert np.isnan(t4.loc["interval=0.5_interpolation=phase", theirs])  # not in the made-up table
    # the columns are adjacent: ours, then the paper's
    cols = list(t4.columns)
    assert cols.index(theirs) == cols.index(ours) + 1
    # without the paper's tables: no paper columns
    assert not any("paper" in c for c in report.reference_table(spec, frame, table4, None, quiet).columns)


# --------------------------------------------------------------------------- shared stage 1, end to end

TABLE5 = """
title = "tiny table V"
table = "table5"
[[grid]]
loss = ["l1", "uafl"]
[stage1]
shared = true
"""


@pytest.fixture(scope="module")
def shared_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("ablate")
    spec_path = write_spec(root, TABLE5)
    paper = write_paper(root / "paper")
    # --jobs 2: stage 1 here, then the two cells in two worker processes (1 torch thread each)
    run = run_ablation(load_spec(spec_path), root / "out", jobs=2, progress=False, paper=paper, log=quiet)
    return spec_path, root / "out", paper, run


@pytest.mark.slow
def test_shared_stage1_is_trained_once_and_bit_identical(shared_run, tmp_path):
    from lfbench.training.config import TrainConfig
    from lfbench.training.loop import train

    spec_path, out, _, run = shared_run
    # stage 1 ran once, in OUT/stage1, with only the first stage
    assert (out / "stage1" / "command.txt").read_text().count("lfbench train") == 1
    stage1 = load_state(out / "stage1" / "final.pt")
    assert stage1["training"]["steps"] == 2
    digest = ckpt.state_sha256(stage1["state_dict"])
    for cid in ("loss=l1", "loss=uafl"):
        marker = json.loads((out / "cells" / cid / "cell.json").read_text())
        assert marker["stage1_sha256"] == digest and marker["steps"] == 3
        log = (out / "cells" / cid / "log.txt").read_text()
        assert "stage 2, step 0 (global step 2)" in log and "[stage 1/2" not in log  # stage 1 not re-run
        copied = load_state(out / "cells" / cid / "stage1_l1.pt")["state_dict"]
        assert all(torch.equal(copied[k], v) for k, v in stage1["state_dict"].items())
    # the two cells' last stages differ (other losses), so their final weights do
    finals = [load_state(out / "cells" / c / "final.pt")["state_dict"] for c in ("loss=l1", "loss=uafl")]
    assert any(not torch.equal(finals[0][k], finals[1][k]) for k in finals[0])
    # a plain, uninterrupted two-stage `lfbench train` of the cell's config (in this process) ends bit for bit
    # where the cell did (in a worker process, from the shared stage 1)
    cfg = TrainConfig.from_toml(out / "cells" / "loss=uafl" / "train.toml")
    before = torch.get_num_threads()
    train(cfg, tmp_path / "plain", progress=False)
    assert torch.get_num_threads() == before
    plain = load_state(tmp_path / "plain" / "final.pt")["state_dict"]
    assert all(torch.equal(plain[k], v) for k, v in finals[1].items())


@pytest.mark.slow
def test_table5_has_the_paper_value_beside_ours(shared_run):
    _, out, _, run = shared_run
    t5 = pd.read_csv(out / "table5.csv").set_index("cell")
    ours = [c for c in t5.columns if c.startswith("BadPix 0.07 (%), ours (batch 1, patch 16, 2+1 steps")]
    theirs = "BadPix 0.07 (%), paper (RTX 3090, full training)"
    assert len(ours) == 1 and list(t5.columns).index(theirs) == list(t5.columns).index(ours[0]) + 1
    for cid, paper_value in (("loss=l1", 12.5), ("loss=uafl", 7.25)):
        records = json.loads((out / "cells" / cid / "results.json").read_text())["records"]
        bp = [r["value"] for r in records if r["metric"] == "badpix_0.07"]
        # The CSV tables hold 6 significant digits ("%.6g"): compare with the value rounded the same way.
        assert len(bp) == 1 and t5.loc[cid, ours[0]] == float("%.6g" % bp[0])
        assert t5.loc[cid, theirs] == paper_value
    cells = pd.read_csv(out / "table_cells.csv").set_index("cell")
    timing = json.loads((out / "cells" / "loss=uafl" / "timing.json").read_text())
    assert timing["time_size"] == 16 and timing["threads"] == 1 and len(timing["test_s_all"]) == 1
    test_time = cells.loc["loss=uafl", "test time (s), ours (9x9x16x16, cpu, 1 thread)"]
    assert test_time == float("%.6g" % timing["test_s"])
    md = (out / "table5.md").read_text()
    assert "paper (RTX 3090, full training)" in md and "ours (batch 1" in md and "12.500" in md
    combined = Results.read(out / "results.json")
    assert set(combined.methods) == {"loss=l1", "loss=uafl"} and combined.meta["ablation"]["shared_stage1"]
    for stem in ("table5", "table_cells", "table_per_scene", "table_average"):
        assert all((out / f"{stem}.{ext}").is_file() for ext in ("md", "tex", "csv"))
    overview = out / "figures" / "error_maps" / "overview_synth_5_0.png"
    assert overview.is_file() and overview.stat().st_size > 1000


@pytest.mark.slow
def test_cells_leave_training_curves_and_report_only_writes_the_html_report(shared_run, capsys):
    from lfbench.cli import main

    spec_path, out, paper, _ = shared_run
    for cid in ("loss=l1", "loss=uafl"):
        cell = out / "cells" / cid
        assert (cell / "learning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        if importlib.util.find_spec("tensorboard") is not None:
            assert list(cell.glob("events.out.tfevents.*")), "no TensorBoard event file beside metrics.jsonl"
    assert main(["ablate", str(spec_path), "--out", str(out), "--report-only", "--html", "--paper", str(paper)]) == 0
    index = (out / "html" / "index.html").read_text(encoding="utf-8")
    assert "tiny table V" in index and "method-loss=l1.html" in index
    scene = next((out / "html").glob("scene-*.html")).read_text(encoding="utf-8")
    assert "loss_l1.badpix.png" not in scene and "loss=l1.badpix.png" in scene  # each cell's maps
    assert "HTML report:" in capsys.readouterr().out


@pytest.mark.slow
def test_finished_cells_are_not_run_again(shared_run, monkeypatch):
    from lfbench.training import loop

    spec_path, out, paper, _ = shared_run
    markers = {p: p.stat().st_mtime_ns for p in [*(out / "cells").glob("*/cell.json"),
                                                  *(out / "cells").glob("*/timing.json")]}
    assert len(markers) == 4

    def no_training(*args, **kwargs):
        raise AssertionError("a finished cell was trained again")

    monkeypatch.setattr(loop, "train", no_training)
    lines: list[str] = []
    run_ablation(load_spec(spec_path), out, progress=False, paper=paper, log=lines.append)
    assert {p: p.stat().st_mtime_ns for p in markers} == markers
    assert sum("finished earlier, skipped" in line for line in lines) == 2


# --------------------------------------------------------------------------- an interrupted cell

@pytest.mark.slow
def test_an_interrupted_cell_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    from lfbench.training import loop

    spec_path = write_spec(tmp_path, "[[grid]]\nseed = [3, 4]\n", evaluation="error_maps = false\n")
    spec = load_spec(spec_path)
    out = tmp_path / "out"
    real_save = loop.Trainer.save_checkpoint

    def save_then_die(self, model, optimizer, stage, step):
        real_save(self, model, optimizer, stage, step)
        if self.paths.out.name == "seed=4" and (stage, step) == (0, 1):
            raise KeyboardInterrupt  # killed right after the checkpoint of step 1

    monkeypatch.setattr(loop.Trainer, "save_checkpoint", save_then_die)
    with pytest.raises(KeyboardInterrupt):
        run_ablation(spec, out, progress=False, log=quiet)
    monkeypatch.undo()
    assert (out / "cells" / "seed=3" / "cell.json").is_file()
    assert not (out / "cells" / "seed=4" / "cell.json").exists()
    assert load_state(out / "cells" / "seed=4" / "checkpoint.pt")["global_step"] == 1

    calls: list[str] = []
    real_train = loop.train

    def spy(cfg, out_dir, **kwargs):
        calls.append(Path(out_dir).name)
        return real_train(cfg, out_dir, **kwargs)

    monkeypatch.setattr(loop, "train", spy)
    run = run_ablation(spec, out, progress=False, log=quiet)
    assert calls == ["seed=4"]  # the finished cell is skipped, the interrupted one resumed
    log = (out / "cells" / "seed=4" / "log.txt").read_text()
    assert "(global step 1)" in log and "resuming from" in log
    assert json.loads((out / "cells" / "seed=4" / "cell.json").read_text())["steps"] == 3
    assert set(run.results.methods) == {"seed=3", "seed=4"}
    assert os.path.isfile(out / "table_cells.md") and not (out / "figures" / "error_maps").exists()
    # a cell folder of another config is refused, naming it
    changed = spec_path.read_text().replace("lr = 1e-3", "lr = 2e-3")
    (tmp_path / "changed.toml").write_text(changed)
    with pytest.raises(SpecError, match="seed=3"):
        run_ablation(load_spec(tmp_path / "changed.toml"), out, progress=False, log=quiet)


# --------------------------------------------------------------------------- many GPUs, clusters, concurrent runs

TWO_CELLS = """
title = "two cells"
table = "table4"
[[grid]]
interval = [1.0, 2.0]
"""


def _records(path: Path) -> dict:
    data = json.loads(path.read_text())
    return {(r["method"], r["scene"], r["metric"]): r["value"] for r in data["records"]}


@pytest.mark.slow
def test_submitit_local_executor_and_merged_cells_runs_give_the_jobs_1_results(tmp_path):
    """The cluster path (submitit's local executor: one job per cell, in a subprocess) and two `--cells` runs
    merged into one results.json (one of them the submitit run) give exactly what one `--jobs 1` run in this
    process gives."""
    import dataclasses

    from lfbench.utils.executor import ClusterOptions

    pytest.importorskip("submitit", reason="the cluster path needs submitit (pip install -e '.[cluster]')")
    spec = load_spec(write_spec(tmp_path, TWO_CELLS))
    assert len(spec.cells) == 2
    one = run_ablation(spec, tmp_path / "jobs1", jobs=1, progress=False, log=quiet)
    # --cells: one cell per run (as two processes or machines would), merged into one results file; the first
    # through submitit's local executor, the second in this process
    first, second = (dataclasses.replace(spec, cells=(cell,)) for cell in spec.cells)
    cluster = run_ablation(first, tmp_path / "split", jobs=1, progress=False, log=quiet,
                           cluster=ClusterOptions("local", timeout_min=10))
    assert (tmp_path / "split" / "submitit").is_dir()  # the job's pickles and logs
    (a,) = cluster.markers
    assert a["id"] == one.markers[0]["id"] and a["final_sha256"] == one.markers[0]["final_sha256"]  # bit-identical
    run_ablation(second, tmp_path / "split", progress=False, log=quiet)
    merged = json.loads((tmp_path / "split" / "results.json").read_text())
    assert _records(tmp_path / "split" / "results.json") == _records(tmp_path / "jobs1" / "results.json")
    assert sorted(m["id"] for m in merged["meta"]["ablation"]["cells"]) == sorted(c.id for c in spec.cells)
    for m in merged["meta"]["ablation"]["cells"]:  # each cell trained bit-identically, whichever way it ran
        assert m["final_sha256"] == next(o["final_sha256"] for o in one.markers if o["id"] == m["id"]), m["id"]
    # a second run of a finished cell replaces its records instead of adding them twice
    run_ablation(first, tmp_path / "split", progress=False, log=quiet)
    assert _records(tmp_path / "split" / "results.json") == _records(tmp_path / "jobs1" / "results.json")


def test_each_worker_gets_its_own_gpu_round_robin(monkeypatch, tmp_path):
    import queue
    import sys

    from lfbench.ablation import jobs
    from lfbench.utils import executor

    assert executor.worker_gpus(3, ["0", "1"]) == ["0", "1", "0"]
    assert executor.worker_gpus(2, []) == [None, None]  # no CUDA: every worker on the CPU
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    monkeypatch.delenv("CUDA_VISIBLE_DEVICES", raising=False)
    assert executor.visible_gpus() == ["0", "1"]
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "4,6")  # a job already restricted to two GPUs
    assert executor.visible_gpus() == ["4", "6"]
    gpus = queue.Queue()
    for g in executor.worker_gpus(2, executor.visible_gpus()):
        gpus.put(g)
    threads = torch.get_num_threads()
    try:
        executor.init_worker(1, gpus)  # what each spawned worker runs first
        assert os.environ["CUDA_VISIBLE_DEVICES"] == "4" and torch.get_num_threads() == 1
        executor.init_worker(1, gpus)
        assert os.environ["CUDA_VISIBLE_DEVICES"] == "6"
    finally:
        torch.set_num_threads(threads)
    with pytest.raises(SpecError, match="Unknown executor 'pbs'. Available: inline, local, pool, slurm"):
        executor.ClusterOptions("pbs")
    monkeypatch.setitem(sys.modules, "submitit", None)  # not installed
    with pytest.raises(SpecError, match=r"--executor needs submitit: pip install -e \"\.\[cluster\]\""):
        jobs.make_executor(executor.ClusterOptions("local"), tmp_path, 1)


def test_the_shared_stage1_waits_for_another_process_holding_its_lock(tmp_path, monkeypatch):
    import threading

    from filelock import FileLock

    from lfbench.ablation import runner

    spec = load_spec(write_spec(tmp_path, TABLE5))
    entered = threading.Event()
    monkeypatch.setattr(runner, "_shared_stage1", lambda *a: entered.set() or a[1])
    (tmp_path / "out" / "stage1").mkdir(parents=True)
    other = FileLock(tmp_path / "out" / "stage1" / "stage1.lock")  # another ablate process training stage 1
    other.acquire()
    worker = threading.Thread(target=runner.run_shared_stage1,
                              args=(spec, tmp_path / "out", {}, 1, False, quiet))
    worker.start()
    assert not entered.wait(0.5)  # blocked while the other process holds the lock
    other.release()
    worker.join(30)
    assert entered.is_set()


def test_ctrl_c_during_a_parallel_ablation_starts_no_further_cells(tmp_path, monkeypatch):
    """With --jobs N only N cells are in the pool at a time: a process pool feeds submitted calls to its
    workers ahead of time, beyond the reach of cancel_futures, so Ctrl-C (which stops the running cells at a
    checkpoint) must find no other cell already handed over."""
    from concurrent.futures import Future

    from lfbench.ablation import runner
    from lfbench.ablation.cell import CellTask
    from lfbench.utils import executor

    class Pool:  # records what is handed over; every call "finishes" at once
        submitted: list[str] = []

        def __init__(self, *args, **kwargs) -> None:
            pass

        def submit(self, fn, *args):
            task = args[-1]  # the pool's call: run_marked(run_cell, label, task)
            Pool.submitted.append(task.cell_id)
            fut: Future = Future()
            fut.set_result({"id": task.cell_id})
            return fut

        def shutdown(self, wait: bool = True, cancel_futures: bool = False) -> None:
            pass

    def interrupted(marker, log):
        raise KeyboardInterrupt  # Ctrl-C while the first finished cell is reported

    config = {"model": {}, "stages": [{"steps": 10}]}
    tasks = [CellTask(cell_id=f"c{i}", values={}, config=config, fingerprint="f", eval_fingerprint="e",
                      cell_dir=str(tmp_path / f"c{i}"), data_links={}, stage1_dir=None, scenes=(), evaluation=None,
                      threads=1) for i in range(5)]
    pool = executor.executor_for(executor.ClusterOptions("pool"), jobs=2)
    monkeypatch.setattr(executor, "ProcessPoolExecutor", Pool)
    monkeypatch.setattr(runner, "_report", interrupted)
    with pytest.raises(KeyboardInterrupt):
        runner.run_cells(tasks, pool, progress=False, log=lambda message: None)
    assert len(Pool.submitted) == 2  # was 5: every cell was queued into the pool at once

    Pool.submitted = []
    monkeypatch.setattr(runner, "_report", lambda marker, log: None)
    runner.run_cells(tasks, pool, progress=False, log=lambda message: None)
    assert sorted(Pool.submitted) == [t.cell_id for t in tasks]  # without an interrupt every cell runs once
