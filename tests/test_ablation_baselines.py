"""lfbench.ablation.baselines: does every cell of an ablation beat the spec's [[methods]] (plane sweep, zero
map)? Verdicts on hand-made scores (with and without seeds, the t-interval by hand with scipy), the metric
direction read from the registry, and the report end to end (`lfbench ablate --report-only`) against the
zero map scored for real on the tiny spec's synthetic scene."""

from __future__ import annotations

import dataclasses
import json
import logging
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy import stats
from test_ablate import quiet, write_spec

from lfbench.ablation import baselines, report
from lfbench.ablation.baselines import baselines_table, summary_lines
from lfbench.ablation.facts import cell_info
from lfbench.ablation.spec import load_spec
from lfbench.results import Record, Results
from lfbench.scoring.metrics import get_metric

PLANE, ZERO = "Plane sweep", "Zero map"
METHODS = f"""
[[methods]]
label = "{PLANE}"
spec = "planesweep:device=cpu"
[[methods]]
label = "{ZERO}"
spec = "constant"
"""
BP, MSE = "BadPix(0.07)", "MSE x100"  # the registry's names of badpix_0.07 and mse_x100


def _frame(values: dict[str, dict[str, tuple[float, float]]]) -> pd.DataFrame:
    """method -> scene -> (BadPix 0.07, MSE x100) as the long results frame (low resolution)."""
    rows = [{"method": method, "scene": scene, "metric": metric, "value": float(v), "resolution": "lowres"}
            for method, per_scene in values.items() for scene, pair in per_scene.items()
            for metric, v in zip(("badpix_0.07", "mse_x100"), pair, strict=True)]
    return pd.DataFrame(rows)


# Baselines on two synthetic scenes (one group, the mean) and backgammon. Plane sweep: synthetic 15 / 5, backgammon
# 6 / 3; zero map: synthetic 85 / 120, backgammon 95 / 140.
BASELINES = {PLANE: {"synth_5_0": (10, 4), "synth_5_1": (20, 6), "backgammon": (6, 3)},
             ZERO: {"synth_5_0": (90, 130), "synth_5_1": (80, 110), "backgammon": (95, 140)}}
# interval=1 beats both; interval=0.5 is worse on MSE on backgammon (3.5 vs 3); interval=0.25 worse on both metrics
# on the synthetic mean (16 vs 15, 6 vs 5).
CELLS = {"interval=1": {"synth_5_0": (8, 2), "synth_5_1": (12, 4), "backgammon": (5, 2)},
         "interval=0.5": {"synth_5_0": (8, 2), "synth_5_1": (12, 4), "backgammon": (5, 3.5)},
         "interval=0.25": {"synth_5_0": (14, 5), "synth_5_1": (18, 7), "backgammon": (5, 2)}}
SYN2 = "synthetic (mean of 2)"


def _spec(tmp_path: Path, head: str, tail: str = METHODS):
    return load_spec(write_spec(tmp_path, head, tail))


def test_verdicts_without_seeds(tmp_path):
    spec = _spec(tmp_path, 'table = "table4"\n[[grid]]\ninterval = [1, 0.5, 0.25]\n')
    table = baselines_table(cell_info(spec), _frame({**CELLS, **BASELINES}), [PLANE, ZERO], seeds=False)
    assert list(table.index) == ["interval=1", "interval=0.5", "interval=0.25"] and table.index.name == "cell"
    row = table.loc["interval=0.25"]
    assert row[f"{BP}, {SYN2}, cell"] == 16.0 and row[f"{MSE}, {SYN2}, cell"] == 6.0  # (14 + 18) / 2, (5 + 7) / 2
    assert row[f"{BP}, {SYN2}, {PLANE}"] == 15.0 and row[f"{MSE}, backgammon, {ZERO}"] == 140.0
    assert table.loc["interval=1", f"vs {PLANE}"] == "beats"
    assert table.loc["interval=0.5", f"vs {PLANE}"] == "does not beat: MSE x100 on backgammon (3.500 vs 3.000)"
    assert row[f"vs {PLANE}"] == (f"does not beat: {BP} on {SYN2} (16.000 vs 15.000); "
                                  f"{MSE} on {SYN2} (6.000 vs 5.000)")
    assert set(table[f"vs {ZERO}"]) == {"beats"}
    assert not any("95%" in c for c in table.columns)  # no seeds: no interval columns
    lines = summary_lines(table, [PLANE, ZERO], [SYN2, "backgammon"])
    assert lines[0] == ("2 of 3 cells do not beat Plane sweep: interval=0.5 (does not beat: MSE x100 on backgammon "
                        f"(3.500 vs 3.000)); interval=0.25 ({row[f'vs {PLANE}']})")
    assert lines[1] == f"every cell beats Zero map on {BP} and {MSE} on {SYN2}, backgammon"
    # equal is not better; a missing baseline score is not resolved, not a loss
    tie = baselines_table(cell_info(spec), _frame({**CELLS, **BASELINES, "interval=1": BASELINES[PLANE]}), [PLANE],
                          seeds=False)
    assert tie.loc["interval=1", f"vs {PLANE}"].startswith(f"does not beat: {BP} on {SYN2} (15.000 vs 15.000)")
    part = baselines_table(cell_info(spec), _frame({**CELLS, PLANE: {"synth_5_0": (10, 4), "synth_5_1": (20, 6)}}),
                           [PLANE], seeds=False)
    assert part.loc["interval=1", f"vs {PLANE}"] == (f"not resolved: {BP} on backgammon (no score); "
                                                      f"{MSE} on backgammon (no score)")
    # a baseline not scored at all (e.g. its weights are missing): no verdict, said once
    absent = baselines_table(cell_info(spec), _frame({**CELLS, PLANE: BASELINES[PLANE]}), [PLANE, ZERO],
                             seeds=False)
    assert set(absent[f"vs {ZERO}"]) == {"not resolved: no scores to compare"}
    assert summary_lines(absent, [ZERO], [SYN2, "backgammon"]) == [
        "no verdict against Zero map: no scores to compare (not scored, or the cells have no scores)"]


def _half(values: list[float]) -> float:
    """Half width of the 95 % t-interval of the mean, by hand."""
    x = np.asarray(values, dtype=np.float64)
    return float(stats.t.ppf(0.975, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))


# Seeds 1-3; one synthetic scene and backgammon; plane sweep 20 / 5 (synthetic), 10 / 4 (backgammon).
SEEDED = {  # variant -> per seed: (synthetic BadPix, synthetic MSE, backgammon BadPix, backgammon MSE)
    "interval=1": [(10, 1, 5, 1.0), (11, 2, 6, 1.5), (12, 3, 7, 2.0)],      # every 95 % high below the baseline
    "interval=0.5": [(15, 1, 5, 1.0), (18, 2, 6, 1.5), (21, 3, 7, 2.0)],    # synthetic BadPix mean 18, high > 20
    "interval=0.25": [(10, 1, 5, 4.5), (11, 2, 6, 5.0), (12, 3, 7, 5.5)],   # backgammon MSE mean 5 > 4
}
SEEDED_PLANE = {"synth_5_0": (20, 5), "backgammon": (10, 4)}


def _seeded_frame() -> pd.DataFrame:
    values = {PLANE: SEEDED_PLANE}
    for variant, runs in SEEDED.items():
        for seed, (sb, sm, bb, bm) in enumerate(runs, start=1):
            values[f"{variant}_seed={seed}"] = {"synth_5_0": (sb, sm), "backgammon": (bb, bm)}
    return _frame(values)


SEEDS_HEAD = 'seeds = [1, 2, 3]\ntable = "table4"\n[[grid]]\ninterval = [1, 0.5, 0.25]\n'


def test_verdicts_with_seeds_use_the_upper_end_of_the_t_interval(tmp_path):
    spec = _spec(tmp_path, SEEDS_HEAD)
    table = baselines_table(cell_info(spec), _seeded_frame(), [PLANE], seeds=True)
    assert table.index.name == "variant" and list(table["seeds"]) == [3, 3, 3]
    syn1 = "synthetic (mean of 1)"
    row = table.loc["interval=0.5"]
    high = 18 + _half([15, 18, 21])  # 18 + 4.303 * 3 / sqrt(3) = 25.45: reaches the plane sweep's 20
    assert row[f"{BP}, {syn1}, cell"] == pytest.approx(18.0)
    assert row[f"{BP}, {syn1}, cell 95% high"] == pytest.approx(high, rel=1e-12)
    assert row[f"{BP}, {syn1}, {PLANE}"] == 20.0
    assert row[f"vs {PLANE}"] == f"not resolved: {BP} on {syn1} (95% high {high:.3f} vs 20.000)"
    first = table.loc["interval=1"]
    assert first[f"vs {PLANE}"] == "beats"
    assert first[f"{MSE}, backgammon, cell 95% high"] == pytest.approx(1.5 + _half([1.0, 1.5, 2.0]), rel=1e-12)
    assert table.loc["interval=0.25", f"vs {PLANE}"] == "does not beat: MSE x100 on backgammon (5.000 vs 4.000)"
    lines = summary_lines(table, [PLANE], [syn1, "backgammon"])
    assert lines == [f"2 of 3 cells do not beat {PLANE}: interval=0.5 ({row[f'vs {PLANE}']}); interval=0.25 "
                     "(does not beat: MSE x100 on backgammon (5.000 vs 4.000))"]
    # one seed left: a mean below the baseline, but no interval
    one = _seeded_frame()
    one = one[~one["method"].str.contains("seed=[23]", regex=True)]
    single = baselines_table(cell_info(spec), one, [PLANE], seeds=True).loc["interval=1"]
    assert single["seeds"] == 1 and single[f"vs {PLANE}"].startswith(f"not resolved: {BP} on {syn1} (95% high - vs")


def test_the_direction_comes_from_the_metric_registry(tmp_path, monkeypatch):
    """Were MSE x100 higher-is-better, a lower MSE than the baseline's would lose, and the interval's lower end
    would decide."""
    def flipped(metric_id: str):
        m = get_metric(metric_id)
        return dataclasses.replace(m, higher_is_better=True) if metric_id == "mse_x100" else m

    monkeypatch.setattr(baselines, "get_metric", flipped)
    spec = _spec(tmp_path, SEEDS_HEAD)
    table = baselines_table(cell_info(spec), _seeded_frame(), [PLANE], seeds=True)
    assert f"{MSE}, backgammon, cell 95% low" in table.columns
    assert table.loc["interval=1", f"vs {PLANE}"] == (f"does not beat: {MSE} on synthetic (mean of 1) (2.000 vs "
                                                      "5.000); MSE x100 on backgammon (1.500 vs 4.000)")
    low = 5 - _half([4.5, 5.0, 5.5])  # mean 5 > 4 but the lower end 3.76 is not
    assert table.loc["interval=0.25", f"{MSE}, backgammon, cell 95% low"] == pytest.approx(low, rel=1e-12)
    assert "higher is better" in baselines.baselines_caption(seeds=True)


def test_report_writes_the_table_and_heads_the_captions_with_the_summary(tmp_path, monkeypatch):
    for var in ("LFBENCH_PAPER_DIR", "LFBENCH_HCI_ROOT"):  # no paper tables: the captions must say so
        monkeypatch.delenv(var, raising=False)
    spec = _spec(tmp_path, SEEDS_HEAD, METHODS.split("[[methods]]\nlabel = \"Zero")[0])
    frame = _seeded_frame()
    results = Results(records=[Record(r.method, r.scene, r.metric, r.value, r.resolution) for r in frame.itertuples()])
    markers = [{"id": c.id, "train_s": 60.0, "own_train_s": 60.0, "test_s": 1.0, "time_size": 16, "device": "cpu",
                "threads": 1} for c in spec.cells]
    logged: list[str] = []
    report.write_report(spec, tmp_path / "out", results, markers, log=logged.append)
    summary = next(line for line in logged if line.startswith("2 of 3 cells do not beat Plane sweep: interval=0.5"))
    csv = pd.read_csv(tmp_path / "out" / "table_baselines.csv").set_index("variant")
    assert csv.loc["interval=0.25", f"vs {PLANE}"] == "does not beat: MSE x100 on backgammon (5.000 vs 4.000)"
    assert csv.loc["interval=0.5", f"{BP}, synthetic (mean of 1), cell 95% high"] == float(
        "%.6g" % (18 + _half([15, 18, 21])))
    md = (tmp_path / "out" / "table_baselines.md").read_text().splitlines()
    assert md[1] == summary + "  " and "95 % t-interval over seeds (within the metric's range) must lie wholly" in md[2]
    for stem in ("table_cells", "table4"):
        assert (tmp_path / "out" / f"{stem}.md").read_text().splitlines()[1] == summary + "  "
    # no paper tables given: only the table with paper columns says so; the others do not mention the paper
    not_found = "paper: not shown (the paper's tables were not found)"
    assert not_found in (tmp_path / "out" / "table4.md").read_text()
    for stem in ("table_cells", "table_seeds", "table_significance", "table_per_scene", "table_average"):
        text = (tmp_path / "out" / f"{stem}.md").read_text()
        assert "paper:" not in text, stem
    # without [[methods]]: no such table, no summary
    bare = _spec(tmp_path / "bare", SEEDS_HEAD, tail="")
    logged.clear()
    report.write_report(bare, tmp_path / "bare_out", results, markers, log=logged.append)
    assert not (tmp_path / "bare_out" / "table_baselines.md").exists()
    assert not any("beat" in line for line in logged)


def test_report_only_end_to_end_against_the_zero_map_scored_for_real(tmp_path, caplog):
    """The tiny spec's synthetic scene, the zero map and the oracle scored by run_methods, two hand-made
    cells around the zero map's scores, then `lfbench ablate --report-only`."""
    from lfbench.ablation.runner import prepare_evaluation, run_methods
    from lfbench.cli import main
    from lfbench.data.hci import HCIScene

    tail = '\n[[methods]]\nlabel = "Zero map"\nspec = "constant"\n[[methods]]\nlabel = "Oracle"\nspec = "gt"\n'
    path = write_spec(tmp_path, 'table = "table4"\n[[grid]]\ninterval = [1, 0.5]\n', tail,
                      evaluation="error_maps = false\n")
    spec, out = load_spec(path), tmp_path / "out"
    scenes = prepare_evaluation(spec, out, quiet)
    (folder, _), = scenes
    gt = HCIScene(Path(folder)).gt_disparity()[15:-15, 15:-15].astype(np.float64)  # inside the 15 px border
    zero_bp, zero_mse = 100 * np.mean(np.abs(gt) > 0.07), 100 * np.mean(gt**2)
    combined = Results(meta={"scenes": [folder]})
    for res in run_methods(spec, out, scenes, quiet):
        combined.extend(res)
    for cid, delta in (("interval=1", -1.0), ("interval=0.5", 1.0)):  # just better / worse than the zero map
        combined.records += [Record(cid, "synth_5_0", "badpix_0.07", zero_bp + delta, "lowres"),
                             Record(cid, "synth_5_0", "mse_x100", zero_mse - 1.0, "lowres")]
        (out / "cells" / cid).mkdir(parents=True)
        (out / "cells" / cid / "cell.json").write_text(json.dumps({"id": cid, "train_s": 1.0, "own_train_s": 1.0}))
        (out / "cells" / cid / "timing.json").write_text(json.dumps({"test_s": 0.5, "time_size": 16,
                                                                     "device": "cpu", "threads": 1}))
    combined.write(out)
    with caplog.at_level(logging.INFO, logger="lfbench.ablation.report"):
        assert main(["ablate", str(path), "--out", str(out), "--report-only"]) == 0
    table = pd.read_csv(out / "table_baselines.csv").set_index("cell")
    syn = "synthetic (mean of 1)"
    assert table.loc["interval=1", f"{BP}, {syn}, Zero map"] == pytest.approx(zero_bp, rel=1e-5)  # 6 digits
    assert table.loc["interval=1", f"{MSE}, {syn}, Zero map"] == pytest.approx(zero_mse, rel=1e-5)
    assert table.loc["interval=1", f"{MSE}, {syn}, Oracle"] == 0.0
    assert table.loc["interval=1", "vs Zero map"] == "beats"
    assert table.loc["interval=0.5", "vs Zero map"] == (f"does not beat: {BP} on {syn} ({zero_bp + 1:.3f} vs "
                                                        f"{zero_bp:.3f})")
    assert table.loc["interval=1", "vs Oracle"] == (f"does not beat: {BP} on {syn} ({zero_bp - 1:.3f} vs 0.000); "
                                                    f"{MSE} on {syn} ({zero_mse - 1:.3f} vs 0.000)")
    assert "1 of 2 cells do not beat Zero map: interval=0.5 (does not beat:" in caplog.text
    assert "2 of 2 cells do not beat Oracle" in caplog.text

    # a copy that keeps only results.json (as results/ablations/ does): the cell markers it recorded rebuild the
    # same tables; without them the cells count as unfinished (one line, exit 2)
    kept, saved = tmp_path / "kept", Results.read(out / "results.json")
    kept.mkdir()
    saved.write(kept)
    assert main(["ablate", str(path), "--out", str(kept), "--report-only"]) == 2
    saved.meta["ablation"] = {"cells": [{**json.loads((out / "cells" / cid / "cell.json").read_text()),
                                         **json.loads((out / "cells" / cid / "timing.json").read_text())}
                                        for cid in ("interval=1", "interval=0.5")]}
    saved.write(kept)
    assert main(["ablate", str(path), "--out", str(kept), "--report-only"]) == 0
    for stem in ("table_baselines", "table_cells", "table4"):
        assert (kept / f"{stem}.csv").read_text() == (out / f"{stem}.csv").read_text(), stem
