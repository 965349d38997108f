"""The ablation and report rooms follow the dataset's protocol (issue 38): a 7x7 .npy dataset scored with a 6 px
border, BadPix 0.05 / 0.2, MSE x100 and a signed bias. The merged ablation results carry the protocol's scoring
meta (the site and the error-map figures say and draw 6 px, never HCI's 15), the baseline verdicts, the best cell
and the orderings take the protocol's primary metric (its first BadPix in table order: BadPix(0.07) on HCI, here
BadPix(0.05)), the radar chart plots a signed metric by its magnitude, table headers name every BadPix(t), and
the footer names no high-resolution scene where the dataset has none. Checked on a finished ablation made by hand
(its cells' maps saved, its [[methods]] scored for real), and once end to end (slow)."""

from __future__ import annotations

import html
import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from helpers import run_cli, shifted_views, write_submission
from npy7_plugin import ANGULAR, Npy7Dataset, write_npy7_scene
from test_npy7_dataset import ABLATION, SIZE, TRAIN

from lfbench.data.dataset import DatasetProtocol
from lfbench.data.pfm import read_pfm
from lfbench.reports.figures import safe_name
from lfbench.results import Record, Results
from lfbench.scoring.base import ANY_VALUE, Metric
from lfbench.utils.errors import DataError

MARKER = "lfnpy7.toml"
PROTOCOL = DatasetProtocol(border_px=6, metrics=("badpix_0.05", "badpix_0.2", "mse_x100", "bias_signed"),
                           disparity_range=(-2.0, 2.0), angular_size=(ANGULAR, ANGULAR),
                           reference_view="centre view [3, 3]")
CELLS = ("width=2", "width=3")
METHODS = ("Zero map",)
#: test_npy7_dataset's ablation, with the cells' widths to fill in and the zero map as a baseline.
SPEC = ABLATION.replace("width = [2]", "width = {widths}") + '[[methods]]\nlabel = "Zero map"\nspec = "constant"\n'


def _bias(gt, pred, mask=None, *, toolkit=False, **_):
    keep = np.ones(gt.shape, bool) if mask is None else mask
    return float(np.mean((pred - gt)[keep]))


BIAS = Metric(id="bias_signed", name="Bias", description="Mean signed disparity error (px).", unit="px", fn=_bias,
              signed=True, value_range=ANY_VALUE)


class Lfnpy7(Npy7Dataset):
    """The npy7 layout under another protocol (and marker): 6 px border, two BadPix thresholds, a signed bias."""

    name = "lfnpy7"
    protocol = PROTOCOL

    @classmethod
    def matches(cls, root: Path) -> bool:
        return (Path(root) / MARKER).is_file()


@pytest.fixture(scope="module")
def registered():
    """The dataset and the bias in the process-wide registries for this module only."""
    from lfbench.data.dataset import DATASETS
    from lfbench.scoring.metrics import METRICS

    with pytest.MonkeyPatch.context() as mp:
        for reg in (DATASETS, METRICS):
            reg.names()  # the entry points loaded before the copy
            for attr in ("_objects", "_entries", "_aliases", "load_errors"):
                mp.setattr(reg, attr, dict(getattr(reg, attr)))
        DATASETS.add(Lfnpy7.name, Lfnpy7)
        METRICS.register(BIAS)
        yield


def _dataset(root: Path) -> Path:
    """The 24x32 scenes 'train0' (d = 1) and 'val0' (d = -1) of 7x7 views, exact shifts by d px per view step."""
    rng = np.random.default_rng(0)
    for name, d in (("train0", 1), ("val0", -1)):
        centre = rng.integers(0, 256, size=(*SIZE, 3), dtype=np.uint8)
        write_npy7_scene(root, name, name[:-1], shifted_views(centre, d, ANGULAR), np.full(SIZE, float(d), np.float32))
    (root / "npy7.toml").unlink()  # this layout's marker only
    (root / MARKER).touch()
    return root


def _spec(tmp: Path, root: Path, widths: str) -> Path:
    (tmp / "train.toml").write_text(TRAIN.format(root=root))
    path = tmp / "ablate.toml"
    path.write_text(SPEC.format(root=root, widths=widths))
    return path


def _quiet(_msg: str) -> None:
    pass


#: The cells' made-up scores: width=3 is the better cell by BadPix(0.05) (the primary metric), width=2 by
#: BadPix(0.2) and MSE x100 (so the best cell says which metric picked it).
SCORES = {"width=2": {"badpix_0.05": 50.0, "badpix_0.2": 5.0, "mse_x100": 0.1, "bias_signed": -0.01},
          "width=3": {"badpix_0.05": 20.0, "badpix_0.2": 30.0, "mse_x100": 5.0, "bias_signed": 0.02}}


@pytest.fixture(scope="module")
def ablation(registered, tmp_path_factory):
    """A finished two-cell ablation of the dataset, made by hand: each cell's saved maps (ground truth plus
    noise), marker, timing and made-up scores; the [[methods]] (the zero map) scored for real; the
    merged results' meta as `lfbench evaluate` writes it (the protocol's, with its scoring rules). Returns the
    spec, OUT and the scene's name."""
    from lfbench.ablation.cell import scoring_kwargs
    from lfbench.ablation.runner import prepare_evaluation, run_methods
    from lfbench.ablation.spec import load_spec

    tmp = tmp_path_factory.mktemp("lfnpy7")
    root = _dataset(tmp / "data")
    path = _spec(tmp, root, "[2, 3]")
    spec, out = load_spec(path), tmp / "out"
    scenes = prepare_evaluation(spec, out, _quiet)
    scoring = scoring_kwargs(spec.evaluation)
    combined = Results(meta={**scoring["meta"], "scoring": scoring["rules"].to_meta(),
                             "scenes": [folder for folder, _ in scenes]})
    for res in run_methods(spec, out, scenes, _quiet):
        combined.extend(res)
    rng = np.random.default_rng(1)
    gt = np.full(SIZE, -1.0, np.float32)
    for cid in CELLS:
        write_submission(out / "cells" / cid / "maps", {"val0": gt + rng.normal(scale=0.1, size=gt.shape)})
        combined.records += [Record(cid, "val0", m, v, "lowres") for m, v in SCORES[cid].items()]
        (out / "cells" / cid / "cell.json").write_text(json.dumps({"id": cid, "train_s": 1.0, "own_train_s": 1.0}))
        (out / "cells" / cid / "timing.json").write_text(json.dumps({"test_s": 0.5, "time_size": 16,
                                                                     "device": "cpu", "threads": 1}))
    combined.write(out)
    return path, out, "val0"


@pytest.fixture(scope="module")
def reported(ablation):
    """The ablation's tables, figures and site with --maps best (nothing run again)."""
    from lfbench.cli import main

    path, out, scene = ablation
    assert main(["ablate", str(path), "--out", str(out), "--report-only", "--html", "--maps", "best"]) == 0
    return out, scene


def test_the_merged_results_record_the_protocols_scoring(ablation):
    """What the run merges its cells under (lfbench.ablation.cell.results_meta): the protocol's scoring rules,
    metrics, range and dataset, as `lfbench evaluate` records them."""
    from lfbench.ablation.cell import results_meta
    from lfbench.ablation.spec import load_spec

    meta = results_meta(load_spec(ablation[0]).evaluation)
    assert meta["scoring"] == {"border_px": 6, "toolkit_nonfinite": False, "highres_scenes": []}
    assert meta["dataset"] == "lfnpy7" and meta["protocol"] == {
        "metrics": ["badpix_0.05", "badpix_0.2", "mse_x100", "bias_signed"], "disparity_range": [-2.0, 2.0]}
    assert {k: v for k, v in Results.read(ablation[1]).meta.items() if k in meta} == meta


def test_site_and_figures_follow_the_6px_border(reported):
    out, scene = reported
    index = (out / "html" / "index.html").read_text(encoding="utf-8")
    page = (out / "html" / f"scene-{scene}.html").read_text(encoding="utf-8")
    line = ('<p class="dataset">Dataset: lfnpy7; disparity range [-2, 2] px per view step; 6 px border '
            'ignored.</p>')
    assert line in index and line in page
    assert "15 px" not in index and "15 px" not in page
    assert "(6 px border)" in page and "(15 px border)" not in page
    # the footer names no high-resolution scene on a dataset without any
    assert "Scoring: 6 px border ignored; non-finite predictions count as bad pixels." in index
    assert "for no scene" not in index
    # the best cell's map is drawn at the protocol's primary threshold, BadPix(0.05), inside the 6 px border
    pred = read_pfm(out / "cells" / "width=3" / "maps" / "disp_maps" / f"{scene}.pfm")
    expected = 100 * np.mean(np.abs(pred + 1.0)[6:-6, 6:-6] > 0.05)
    shown = re.search(r'width=3</a> <span class="unit">BadPix\(0\.05\) ([0-9.]+) % at low resolution', page)
    assert shown is not None and float(shown[1]) == pytest.approx(expected, abs=0.005)
    assert 'Zero map</a> <span class="unit">BadPix(0.05) 100.00 % at low resolution' in page
    assert "BadPix(0.07)" not in page


def test_the_error_map_figures_draw_at_the_6px_border(ablation, tmp_path):
    """The error-map figures (their masks and the caption "evaluation mask: N px border" drawn into the
    overview) take the rules and thresholds the ablation's writers are handed: the recorded 6 px, BadPix 0.05."""
    from lfbench.ablation.report import run_writers
    from lfbench.ablation.spec import load_spec
    from lfbench.reports.writers import OutputWriter

    class Probe(OutputWriter):
        def write(self, run):
            self.rules, self.thresholds = run.rules, run.thresholds
            return []

    path, out, _ = ablation
    probe = Probe()
    run_writers([probe], load_spec(path), Results.read(out), tmp_path, out, maps="none")
    assert probe.rules.border_px == 6 and probe.thresholds.primary == 0.05 and probe.thresholds.marked == (0.05, 0.2)


def test_baseline_verdicts_use_the_protocols_metrics(reported):
    out, _ = reported
    text = (out / "table_baselines.md").read_text(encoding="utf-8")
    assert "BadPix(0.07)" not in text
    assert "BadPix(0.05), val0, cell" in text and "MSE x100, val0, Zero map" in text
    assert ("'beats' = better than the baseline on each of BadPix(0.05) (lower is better), MSE x100 (lower is "
            "better) on every scene group") in text
    header = text.split("\n")
    row = next(r for r in header if r.startswith("| width=3"))
    assert " - " not in row.replace("does not beat", "")  # every value there


def test_best_cell_by_the_protocols_primary_metric(reported, ablation):
    from lfbench.ablation.report import best_cell
    from lfbench.ablation.spec import load_spec

    out, scene = reported
    spec, results = load_spec(ablation[0]), Results.read(out)
    assert best_cell(spec, results) == "width=3" and best_cell(spec, results, "mse_x100") == "width=2"
    page = (out / "html" / f"scene-{scene}.html").read_text(encoding="utf-8")
    drawn = {label for label in (*CELLS, *METHODS) if f"/{safe_name(label)}.disp.png" in page}
    assert drawn == {"width=3", *METHODS}
    index = html.unescape((out / "html" / "index.html").read_text(encoding="utf-8"))
    assert "Maps drawn with --maps best: the best cell's (BadPix(0.05)) and the extra methods'." in index
    from lfbench.ablation.report import primary_ablation_metric

    assert primary_ablation_metric(results) == "badpix_0.05"


def test_table_headers_name_every_badpix_threshold(reported):
    out, _ = reported
    lines = (out / "table_average.md").read_text(encoding="utf-8").splitlines()
    head = next(line for line in lines if line.startswith("| method"))
    assert [c.strip() for c in head.strip("|").split("|")] == [
        "method", "MSE x100", "BadPix(0.05)", "BadPix(0.2)", "Bias", "scenes", "runtime_s"]


def test_primary_metric_of_a_protocol():
    from lfbench.data.dataset import DEFAULT_METRICS
    from lfbench.scoring.metrics import primary_metric

    assert primary_metric(DEFAULT_METRICS) == "badpix_0.07"  # HCI's choice, unchanged
    assert primary_metric(["mse_x100", "badpix_0.2", "badpix_0.05"]) == "badpix_0.2"  # the protocol's first BadPix
    assert primary_metric(["mse_x100", "q25_x100"]) == "mse_x100" and primary_metric([]) is None


def test_verdict_metrics_of_a_protocol():
    from lfbench.ablation.baselines import VERDICT_METRICS, verdict_metrics
    from lfbench.data.dataset import DEFAULT_METRICS

    assert verdict_metrics(DEFAULT_METRICS) == VERDICT_METRICS == ("badpix_0.07", "mse_x100")
    assert verdict_metrics(PROTOCOL.metrics) == ("badpix_0.05", "mse_x100")
    assert verdict_metrics(["badpix_1"]) == ("badpix_1",)


def test_radar_plots_a_signed_metric_by_its_magnitude(registered):
    from lfbench.reports.toolkit_figures import radar_radii

    scores = pd.DataFrame({"far": [-0.073, 1.0, 10.0], "near": [-0.006, 1.0, 10.0]},
                          index=["bias_signed", "mse_x100", "badpix_0.05"])
    radii = radar_radii(scores)
    vmax = 0.073 * 1.2
    step = vmax / 4
    assert radii.loc["bias_signed", "near"] == pytest.approx((0.006 + step) / (vmax + step))
    assert radii.loc["bias_signed", "far"] == pytest.approx((0.073 + step) / (vmax + step))
    assert radii.loc["bias_signed", "near"] < radii.loc["bias_signed", "far"]  # closer to 0: nearer the centre
    assert radii.loc["mse_x100", "near"] == pytest.approx((1.0 + 0.3) / (1.2 + 0.3))  # unsigned: as before
    from lfbench.reports.toolkit_figures import radar_axis_name

    assert radar_axis_name("bias_signed") == "|Bias|" and radar_axis_name("mse_x100") == "MSE x100"


def test_headers_of_any_badpix_threshold():
    from lfbench.reports.tables import _header

    assert [_header(c) for c in ("badpix_0.05", "badpix_0.2", "badpix_0.07", "mse_x100", "runtime_s", "bad")] == [
        "BadPix(0.05)", "BadPix(0.2)", "BadPix(0.07)", "MSE x100", "runtime_s", "bad"]


def test_results_of_another_protocol_are_not_merged(ablation, tmp_path):
    """An earlier run's results.json scored at HCI's 15 px border does not share a table with cells scored at
    6 px: one line naming the file and both borders."""
    from lfbench.ablation.runner import merge_results
    from lfbench.results import check_same_scoring

    _, out, _ = ablation
    ours = Results.read(out)
    old = Results(records=[Record("old", "val0", "badpix_0.05", 1.0, "lowres")],
                  meta={**ours.meta, "scoring": {**ours.meta["scoring"], "border_px": 15}})
    old.write(tmp_path)
    with pytest.raises(DataError) as err:
        merge_results(tmp_path, ours)
    message = str(err.value)
    assert "\n" not in message and str(tmp_path / "results.json") in message
    assert "border px 15 here, 6 in the rest" in message
    check_same_scoring(ours, Results(meta={}), "x")  # results that record no rules: taken as they are


def test_report_of_the_merged_results_follows_the_border(reported, tmp_path, capsys):
    out, scene = reported
    rc, _, err = run_cli(capsys, "report", out / "results.json", "--out", tmp_path / "rep", "--html")
    assert rc == 0, err
    index = (tmp_path / "rep" / "html" / "index.html").read_text(encoding="utf-8")
    assert "6 px border ignored" in index and "15 px" not in index


@pytest.mark.slow
def test_ablate_end_to_end_records_the_border(registered, tmp_path, capsys):
    """One trained cell: the merged results.json carries the protocol's scoring and the site says 6 px."""
    root = _dataset(tmp_path / "data")
    spec = _spec(tmp_path, root, "[2]")
    rc, _, err = run_cli(capsys, "ablate", spec, "--out", tmp_path / "ab", "--html", "--no-progress")
    assert rc == 0, err
    meta = json.loads((tmp_path / "ab" / "results.json").read_text())["meta"]
    assert meta["scoring"]["border_px"] == 6 and meta["protocol"]["metrics"][0] == "badpix_0.05"
    index = (tmp_path / "ab" / "html" / "index.html").read_text(encoding="utf-8")
    assert "6 px border ignored" in index and "15 px" not in index



def test_a_cell_scored_under_another_protocol_is_refused(ablation):
    """A cell whose results.json records another border than the run's protocol: one line naming it."""
    from lfbench.results import check_same_scoring

    _, out, _ = ablation
    source = out / "cells" / "width=2" / "results.json"
    with pytest.raises(DataError) as err:
        check_same_scoring(Results.read(out), Results(meta={"scoring": {"border_px": 15}}), source)
    assert "border px 15 here, 6 in the rest" in str(err.value) and str(source) in str(err.value)
    assert "\n" not in str(err.value)
    ours = Results.read(out)
    other = Results(meta={**ours.meta, "scoring": {**ours.meta["scoring"], "scorer": "paper-author"}})
    with pytest.raises(DataError, match=r"\(scorer paper-author here, lfbench in the rest\)"):
        check_same_scoring(ours, other, source)  # the default scorer is compared too
