"""The dataset's protocol drives the presentation (issue 38): a TOML dataset scored at BadPix 0.5 / 1 px with a
4 px border and its own disparity range gets maps, captions, BadPix series and pages at those thresholds, every
page names the dataset, its range and its border, and the intro explains no HCI scene it does not have."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest
from helpers import run_cli
from PIL import Image

from lfbench.data.generic import SPEC_FILE
from lfbench.data.synth import generate_scene, quantize
from lfbench.reports.figures import CURVE_THRESHOLDS, MARKED_THRESHOLDS, Thresholds, read_curves_csv


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """A 5x5 TOML dataset of one 40x40 scene, scored with the plane sweep into --html --figures."""
    base = tmp_path_factory.mktemp("proto")
    root = base / "data"
    root.mkdir()
    (root / SPEC_FILE).write_text(
        '[views]\npattern = "view_{v}_{u}.png"\nangular = 5\n[ground_truth]\nfile = "gt.npy"\nformat = "npy"\n'
        '[protocol]\nborder = 4\nmetrics = ["badpix_0.5", "badpix_1", "mse_x100"]\ndisparity_range = [-2, 3]\n')
    scene = generate_scene(3, size=40, angular=5)
    folder = root / "street"
    folder.mkdir()
    views = quantize(scene.views)
    for v in range(5):
        for u in range(5):
            Image.fromarray(views[v, u]).save(folder / f"view_{v}_{u}.png")
    np.save(folder / "gt.npy", scene.disparity)
    out = base / "run"
    return root, out


def test_thresholds_come_from_the_protocols_metrics():
    assert Thresholds.of_metrics(["badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100"]) == Thresholds()
    assert Thresholds() == Thresholds(MARKED_THRESHOLDS, 0.07)
    assert Thresholds().curve is CURVE_THRESHOLDS  # HCI's series unchanged
    t = Thresholds.of_metrics(["mse_x100", "badpix_1", "badpix_0.5"])
    assert t.marked == (0.5, 1.0) and t.primary == 1.0  # no table order of their own: the protocol's first
    assert t.curve[0] == 0.0 and t.curve[-1] == 1.25 and len(t.curve) == 101
    assert Thresholds.of_metrics(["mse_x100"]) == Thresholds()


def test_pages_and_figures_follow_the_protocol(run, capsys):
    root, out = run
    rc, _, err = run_cli(capsys, "evaluate", "--data", str(root), "--method", "planesweep", "--out", str(out),
                         "--html", "--figures", "--no-progress")
    assert rc == 0, err
    data = json.loads((out / "results.json").read_text())
    assert data["meta"]["protocol"] == {"metrics": ["badpix_0.5", "badpix_1", "mse_x100"],
                                        "disparity_range": [-2.0, 3.0]}
    value = {r["metric"]: r["value"] for r in data["records"]}
    index = (out / "html" / "index.html").read_text(encoding="utf-8")
    scene = (out / "html" / "scene-street.html").read_text(encoding="utf-8")
    for page in (out / "html").glob("*.html"):
        text = page.read_text(encoding="utf-8")
        assert ('<p class="dataset">Dataset: toml; disparity range [-2, 3] px per view step; 4 px border '
                'ignored.</p>') in text, page.name
    assert "backgammon" not in index and "highres" not in index.split("</section>", 1)[0]
    assert "Dotted: 0.5, 1 px." in index and "Dotted: 0.5, 1 px." in scene
    assert "0.07" not in scene and "0.01" not in scene
    # the map's BadPix is the protocol's first threshold, 0.5 px, and equals the table's number
    shown = re.search(r"BadPix\(0\.5\) ([0-9.]+) % at low resolution", scene)
    assert shown is not None and float(shown[1]) == pytest.approx(value["badpix_0.5"], abs=0.005)
    assert "|gt − pred| &gt; 0.5 px" in scene and "(4 px border)" in scene
    # the figures' BadPix series runs to 1.25 px and crosses the table's numbers at its thresholds
    curve = next(c for c in read_curves_csv(out / "figures" / "badpix_series.csv") if c.scene == "street")
    assert curve.thresholds[-1] == 1.25
    for t, metric in ((0.5, "badpix_0.5"), (1.0, "badpix_1")):
        assert curve.values[np.argmin(np.abs(curve.thresholds - t))] == pytest.approx(value[metric], abs=1e-9)


def test_results_of_two_datasets_are_refused_in_one_line(tmp_path, capsys):
    """Roots of two datasets are not scored into one results file (one protocol per table): one line naming the
    root, both datasets and what to do (it said 'not laid out as dataset hci')."""
    from helpers import assert_one_error_line

    assert run_cli(capsys, "synth", "--out", tmp_path / "hci", "--size", "32", "--scenes", "1", "--no-progress")[0] == 0
    assert run_cli(capsys, "synth", "--out", tmp_path / "ulf", "--layout", "urbanlf-syn", "--size", "32x24",
                   "--scenes", "1", "--no-progress")[0] == 0
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "hci", "--data", tmp_path / "ulf", "--method", "gt",
                         "--out", tmp_path / "out", "--no-progress")
    assert_one_error_line(rc, err, str(tmp_path / "ulf"), "is dataset 'urbanlf-syn'", "is 'hci'",
                          "evaluate each into its own --out")
    assert not (tmp_path / "out").exists()
