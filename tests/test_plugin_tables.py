"""A plugin's ablation and report as a plugin author meets them (examples/tiny_plugin installed as a user
installs it, run with lfbench's own commands): no SubFocal paper rows unless the spec or --paper asks for
them, even where a paper folder is found (issue 22.6), and an ablation site that shows the means over
seeds, their intervals and the verdicts against each baseline, as the Markdown tables have them (22.7)."""

from __future__ import annotations

import html
import re
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from helpers import example_copy

pytestmark = pytest.mark.slow
SCENE = "synth_11_0"  # the example spec's one evaluation scene


def lfbench(env: dict, *args: object) -> str:
    proc = subprocess.run([sys.executable, "-m", "lfbench", *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


def paper_folder(folder: Path) -> Path:
    """A made-up paper folder (not the paper's numbers) that reports the plugin's evaluation scene, found
    through LFBENCH_PAPER_DIR as a user's own would be: an old lfbench put its rows beside any ablation."""
    folder.mkdir(parents=True)
    (folder / "table1_per_scene.csv").write_text(f"method,scene,metric,value\nSubFocal,{SCENE},badpix_0.07,1.5\n")
    (folder / "table2_average.csv").write_text("method,metric,value\nSubFocal,badpix_0.07,2.5\n")
    return folder


@pytest.fixture(scope="module")
def ablated(example_plugin, tmp_path_factory):
    """The example's channels ablation with two seeds and the zero map as a baseline, run with --html while
    a paper folder is set in the environment."""
    base = tmp_path_factory.mktemp("plugin_tables")
    _, env = example_plugin
    src = example_copy(base / "src")
    paper = paper_folder(base / "paper")
    env = {**env, "LFBENCH_PAPER_DIR": str(paper)}
    env.pop("LFBENCH_HCI_ROOT", None)
    text = (src / "ablate_channels.toml").read_text()
    assert 'table = "none"' in text
    spec = src / "seeded.toml"
    spec.write_text(text.replace('table = "none"', 'table = "none"\nseeds = [1, 2]')
                    + '\n[[methods]]\nlabel = "zero"\nspec = "constant"\n')
    out = base / "ablate"
    lfbench(env, "ablate", spec, "--out", out, "--html", "--no-progress")
    return env, spec, out, paper


def _texts(folder: Path) -> dict[str, str]:
    return {p.name: p.read_text(encoding="utf-8") for p in sorted(folder.iterdir())
            if p.suffix in (".md", ".tex", ".csv", ".html")}


def test_a_plugin_ablation_has_no_paper_rows_unless_asked(ablated):
    env, spec, out, paper = ablated
    files = {**_texts(out), **{f"html/{k}": v for k, v in _texts(out / "html").items()}}
    assert "table_average.md" in files and "html/index.html" in files
    assert not [name for name in files if "paper" in name]
    assert not [name for name, text in files.items() if "SubFocal" in text or "Tables I/II (HCI" in text]
    # asked for: --paper names the folder, and the paper's row stands beside the cells
    lfbench(env, "ablate", spec, "--out", out, "--report-only", "--html", "--paper", paper)
    average = (out / "table_average_paper.md").read_text()
    assert "SubFocal (paper, Table II, 1 scenes)" in average and "2.500" in average


def test_a_plugin_report_has_no_paper_rows_unless_asked(ablated, tmp_path):
    env, _, out, _ = ablated
    lfbench(env, "report", out, "--out", tmp_path / "plain", "--html")
    texts = {**_texts(tmp_path / "plain"), **_texts(tmp_path / "plain" / "html")}
    assert not [name for name, text in texts.items() if "SubFocal" in text or "paper" in name]
    lfbench(env, "report", out, "--out", tmp_path / "asked", "--paper")  # bare --paper: LFBENCH_PAPER_DIR
    assert "SubFocal (paper" in (tmp_path / "asked" / "table_average_paper.md").read_text()


def _html_table(page: str, table_id: str) -> list[list[str]]:
    """The rows of one table of a page as cell texts (header row first)."""
    body = re.search(rf'<table class="sortable[^"]*" id="{re.escape(table_id)}">(.*?)</table>', page, re.S)
    assert body, f"no table {table_id}"
    rows = re.findall(r"<tr>(.*?)</tr>", body.group(1), re.S)
    cells = [re.findall(r"<t[hd][^>]*>(.*?)</t[hd]>", row, re.S) for row in rows]
    return [[html.unescape(re.sub(r"<[^>]+>", "", c)).strip() for c in row] for row in cells]


def test_the_ablation_site_shows_seed_means_intervals_and_verdicts(ablated):
    _, _, out, _ = ablated
    page = (out / "html" / "index.html").read_text(encoding="utf-8")
    seeds = pd.read_csv(out / "table_seeds.csv").set_index("variant")
    rows = _html_table(page, "table-seeds")
    header, body = rows[0], {r[0]: r[1:] for r in rows[1:]}
    assert set(body) == {"channels=4", "channels=8"} == set(seeds.index)
    for variant, row in seeds.iterrows():
        shown = dict(zip(header[1:], body[variant], strict=True))
        assert shown["seeds"] == "2"
        for column in ("badpix_0.07 mean", "badpix_0.07 95% low", "badpix_0.07 95% high", "mse_x100 95% high"):
            assert shown[column] == f"{row[column]:.3f}", (variant, column)
        assert 0 <= row["badpix_0.07 95% low"] <= row["badpix_0.07 mean"] <= row["badpix_0.07 95% high"] <= 100
    verdicts = pd.read_csv(out / "table_baselines.csv").set_index("variant")["vs zero"]
    rows = _html_table(page, "table-baselines")
    column = rows[0].index("vs zero")
    assert {r[0]: r[column] for r in rows[1:]} == verdicts.to_dict()
    assert "Mean over seeds" in page and "Against the baselines" in page
