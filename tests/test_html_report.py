"""The static HTML report: built by `evaluate --html` and `report --html` from the results and the saved
maps, self-contained (every referenced file exists, nothing refers to http(s)), numbers with ranks,
resolutions, bootstrap intervals and the paper's labelled columns; and, in a real headless Chromium
where one is installed, images load, sorting works, pages link back and nothing logs an error."""

from __future__ import annotations

import contextlib
import io
import json
import os
import re
import shutil
import stat
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from helpers import write_scene, write_submission
from test_report import write_paper

from lfbench.cli import main
from lfbench.reports.figures import safe_name
from lfbench.scoring.prepare import upsample_nearest

SCENES = ("boxes", "dots")
SIZE = 40


class _Refs(HTMLParser):
    """Every src / href of a page, and the text of each table's rows (by table id)."""

    def __init__(self) -> None:
        super().__init__()
        self.refs: list[str] = []

    def handle_starttag(self, tag, attrs):
        for key, value in attrs:
            if key in ("src", "href") and value is not None:
                self.refs.append(value)


def _run(argv: list[str]) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(argv)
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    """Two tiny scenes (dots with high-resolution ground truth, scored at highres as on the benchmark),
    the oracle and two submissions (one worse everywhere), evaluated with --html --ci."""
    base = tmp_path_factory.mktemp("site")
    root = base / "data"
    rng = np.random.default_rng(0)
    maps_good, maps_bad = {}, {}
    for i, name in enumerate(SCENES):
        gt = rng.uniform(-1, 1, size=(SIZE, SIZE)).astype(np.float32)
        highres = upsample_nearest(gt, 10) if name == "dots" else None  # the oracle stays exact at highres
        write_scene(root, name, "training", size=SIZE, seed=i, gt=gt, gt_highres=highres)
        maps_good[name] = gt + rng.normal(scale=0.05, size=gt.shape).astype(np.float32)
        maps_bad[name] = gt + rng.normal(scale=0.3, size=gt.shape).astype(np.float32)
    good = write_submission(base / "good", maps_good)
    bad = write_submission(base / "bad", maps_bad)
    out = base / "run"
    rc, _, err = _run(["evaluate", "--data", str(root), "--method", "gt", "--method", f"published:path={good}",
                       "--method", f"published:path={bad}", "--out", str(out), "--html", "--ci",
                       "--ci-resamples", "40", "--no-progress"])
    assert rc == 0, err
    return out


def _pages(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.html"))


def test_site_has_an_index_a_page_per_scene_and_per_method(site):
    html = site / "html"
    names = {p.name for p in _pages(html)}
    assert names == {"index.html", *(f"scene-{s}.html" for s in SCENES),
                     *(f"method-{safe_name(m)}.html" for m in ("gt", "published:good", "published:bad"))}
    assert (site / "maps" / "gt" / "disp_maps" / "boxes.pfm").is_file()  # the maps the site was drawn from
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE(html.stat().st_mode) == 0o777 & ~umask  # as readable as a folder the user makes


def test_every_reference_is_a_file_of_the_site_and_nothing_is_fetched(site):
    html = site / "html"
    for page in _pages(html):
        parser = _Refs()
        parser.feed(page.read_text(encoding="utf-8"))
        for ref in parser.refs:
            if ref.startswith(("data:", "#")):
                continue
            from urllib.parse import unquote

            target = html / unquote(ref.split("#")[0])
            assert target.is_file(), f"{page.name} refers to missing {ref}"
    for path in html.rglob("*"):
        if path.is_file():
            data = path.read_bytes()
            assert b"http://" not in data and b"https://" not in data, path


def _table_rows(page: str, table_id: str) -> list[str]:
    body = page.split(f'id="{table_id}"', 1)[1].split("</table>", 1)[0]
    return re.findall(r'<th scope="row" data-v="([^"]*)"', body)


def test_index_ranks_methods_and_states_resolutions_and_intervals(site):
    page = (site / "html" / "index.html").read_text(encoding="utf-8")
    # the good submission is best, the noisy one worst, on average rank; the oracle is a reference row below
    assert _table_rows(page, "table-overview") == ["published:good", "published:bad", "gt"]
    overview = page.split('id="table-overview"', 1)[1].split("</table>", 1)[0]
    gt_row = re.search(r'data-v="gt">.*?</tr>', overview, re.S).group(0)
    assert re.findall(r'data-v="([-0-9.e]+)">', gt_row)[0:5] == ["0.0"] * 5  # the oracle's means, highres dots too
    assert overview.split('<tbody class="reference">', 1)[1].count('scope="row"') == 1  # gt, apart and unranked
    section = page.split('id="table-badpix_0.07"', 1)[1].split("</table>", 1)[0]
    assert section.count("#1</span>") == len(SCENES)  # the good submission ranks first on each scene
    assert '<span class="res">lowres</span>' in section.split("boxes", 1)[1].split("</th>", 1)[0]
    assert '<span class="res">highres</span>' in section.split("dots", 1)[1].split("</th>", 1)[0]
    assert "Mean<span class=\"res\">highres+lowres</span>" in section  # the mean says what it averages
    assert re.search(r'class="ci"[^>]*>\[\d+\.\d{3}, \d+\.\d{3}\]', section)  # bootstrap intervals
    # the mean column holds the mean of the per-scene values
    good = re.search(r'data-v="published:good">.*?</tr>', section, re.S).group(0)
    values = [float(v) for v in re.findall(r'data-v="([-0-9.e]+)"', good)]
    assert values[len(SCENES)] == pytest.approx(np.mean(values[:len(SCENES)]))


def test_scene_page_shows_every_methods_maps_at_one_scale(site):
    page = (site / "html" / "scene-boxes.html").read_text(encoding="utf-8")
    for m in ("gt", "published:good", "published:bad"):
        for kind in ("disp", "badpix", "error"):
            assert f'src="img/boxes/{safe_name(m)}.{kind}.png"' in page
    assert 'href="index.html"' in page and "centre view" in page and "ground truth" in page
    assert "pairwise_0.png" in page and "heatmap_median.png" in page


@pytest.mark.slow
def test_report_rebuilds_the_site_with_the_papers_labelled_columns(site, tmp_path):
    paper = write_paper(tmp_path / "paper")
    out = tmp_path / "rep"
    rc, stdout, err = _run(["report", str(site), "--out", str(out), "--html", "--paper", str(paper),
                            "--maps", str(site / "maps"), "--figure-format", "png,svg"])
    assert rc == 0, err
    page = (out / "html" / "index.html").read_text(encoding="utf-8")
    section = page.split('id="paper-badpix_0.07"', 1)[1].split("</table>", 1)[0]
    assert "SubFocal (paper)" in section
    assert ">8.500<" in section and ">0.750<" in section  # Table I of the tiny paper: boxes, dots
    assert 'class="res">highres</span>' in section  # the paper scored dots at high resolution
    assert "SubFocal (paper, Table II, 4 scenes)" in page
    assert "&lt;NA&gt;" not in page and ">nan" not in page  # numbers the paper does not give read '–'
    assert (out / "figures" / "toolkit" / "radar.svg").is_file()
    assert (out / "figures" / "toolkit" / "error_heatmaps.png").is_file()
    pair = f"pairwise_{safe_name('published:good')}_vs_{safe_name('published:bad')}.png"
    assert (out / "figures" / "toolkit" / pair).is_file()
    assert not list((out / "figures" / "toolkit").glob("pairwise_gt_*"))  # the oracle is compared with nothing
    assert "HTML report:" in stdout


def test_a_file_where_the_report_goes_is_refused_before_any_work(site, tmp_path, capsys):
    out = tmp_path / "run"
    (out / "html").parent.mkdir()
    (out / "html").write_text("not a folder")
    rc = main(["evaluate", "--data", str(site.parent / "data"), "--method", "gt", "--out", str(out), "--html",
               "--no-progress"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "exists and is not a folder (the HTML report goes there)" in err[0]
    assert not (out / "results.json").exists()


def test_a_site_from_results_alone_shows_the_numbers_and_says_why_there_are_no_maps(site, tmp_path):
    alone = tmp_path / "alone"
    alone.mkdir()
    data = json.loads((site / "results.json").read_text())
    data["meta"]["data_root"] = str(tmp_path / "moved")  # the data root is not here any more
    (alone / "results.json").write_text(json.dumps(data))
    rc, stdout, err = _run(["report", str(alone), "--out", str(tmp_path / "rep"), "--html"])
    assert rc == 0, err
    html = tmp_path / "rep" / "html"
    index = (html / "index.html").read_text(encoding="utf-8")
    assert "is not here: no maps are shown" in index and "No saved maps" in index
    scene = (html / "scene-boxes.html").read_text(encoding="utf-8")
    assert "only the numbers are shown" in scene and "#1</span>" in scene
    assert not list(html.glob("img/boxes/*"))


def test_a_copied_results_json_gives_a_site_with_the_scenes_and_says_there_are_no_maps(site, tmp_path):
    """Issue 20.7: results.json copied elsewhere (its data root still there, its maps not beside it): the
    report's site shows the scenes and the numbers and says why there are no maps; it used to fail in
    jinja2 after the tables were written."""
    there = tmp_path / "there"
    there.mkdir()
    shutil.copy(site / "results.json", there / "results.json")
    rc, stdout, err = _run(["report", str(there / "results.json"), "--out", str(tmp_path / "rep"), "--html"])
    assert rc == 0, err
    html = tmp_path / "rep" / "html"
    index = (html / "index.html").read_text(encoding="utf-8")
    assert "No saved maps: scene pages show the scenes and the numbers, no method" in index
    scene = (html / "scene-boxes.html").read_text(encoding="utf-8")
    assert 'src="img/boxes/centre.png"' in scene and 'src="img/boxes/gt.png"' in scene
    assert "disp.png" not in scene and "#1</span>" in scene  # no method's maps, the ranks
    assert (tmp_path / "rep" / "table_average.md").is_file()


def test_the_oracle_is_a_reference_row_never_ranked_nor_compared(site):
    """Issue 32.4: the ground-truth oracle is the line the others are measured against, not a competitor: it
    took rank 1 everywhere and was one side of the pairwise comparisons. It is recorded as a reference, shown in
    rows of its own without ranks, and left out of the ranks, the pairwise maps, the heatmaps and the radar."""
    assert json.loads((site / "results.json").read_text())["meta"]["references"] == ["gt"]
    html = site / "html"
    index = (html / "index.html").read_text(encoding="utf-8")
    for table in ("table-overview", "table-badpix_0.07", "table-mse_x100"):
        body = index.split(f'id="{table}"', 1)[1].split("</table>", 1)[0]
        ranked, reference = body.split('<tbody class="reference">', 1)
        assert 'data-v="gt"' not in ranked and 'data-v="gt"' in reference and ">reference</span>" in reference
        assert "#1</span>" not in reference and 'class="rank"' not in reference  # values, no ranks
    section = index.split('id="table-badpix_0.07"', 1)[1].split("</table>", 1)[0]
    good = re.search(r'data-v="published:good">.*?</tr>', section, re.S).group(0)
    assert good.count("#1</span>") == len(SCENES)  # the best competitor takes rank 1, not the oracle
    assert "2 methods and 1 reference (not ranked) on 2 scenes" in index
    scene = (html / "scene-boxes.html").read_text(encoding="utf-8")
    pairs = re.findall(r"A = ([^ ]+) \(blue.*?B = ([^ ]+) \(red", scene)
    assert pairs == [("published:good", "published:bad")]  # gt took part in two of three pairs
    assert "over 2 methods" in scene  # the heatmaps over the competitors
    table = scene.split('id="table-scene"', 1)[1].split("</table>", 1)[0]
    assert table.split('<tbody class="reference">', 1)[1].count('scope="row"') == 1
    oracle_page = (html / "method-gt.html").read_text(encoding="utf-8")
    assert "not ranked among the 2 methods" in oracle_page and "#1</span>" not in oracle_page
    assert "radar_gt.png" not in oracle_page


def test_leaderboard_ranks_leave_out_the_references():
    from lfbench.reports.leaderboard import metric_ranks, overall_ranks
    from lfbench.results import Record, Results

    records = [Record(m, s, "badpix_0.07", v, "lowres")
               for m, vals in {"gt": (0.0, 0.0), "a": (5.0, 3.0), "b": (4.0, 6.0)}.items()
               for s, v in zip(("s1", "s2"), vals, strict=True)]
    results = Results(records=records, meta={"references": ["gt"]})
    ranks = metric_ranks(results, "badpix_0.07").set_index(["method", "scene"])["rank"]
    assert ranks[("b", "s1")] == 1 and ranks[("a", "s1")] == 2 and ranks[("a", "s2")] == 1
    assert np.isnan(ranks[("gt", "s1")]) and np.isnan(ranks[("gt", "s2")])
    assert overall_ranks(results).to_dict() | {"gt": 0} == {"gt": 0, "a": 1.5, "b": 1.5}
    assert results.references == ["gt"] and results.competitors == ["a", "b"]
    # results written before references were recorded: the method made from the spec gt (under any label)
    old = Results(records=records, meta={"methods": {"gt": {"spec": "gt"}, "a": {"spec": "planesweep"}}})
    assert old.references == ["gt"]
    relabelled = Results(records=[Record("truth", "s1", "badpix_0.07", 0.0, "lowres")],
                         meta={"methods": {"truth": {"spec": "gt"}}})
    assert relabelled.references == ["truth"]


def test_scene_pages_draw_the_badpix_series_full_width_and_method_pages_have_colour_bars(site):
    """Issue 32.4: the per-scene BadPix(t) chart was one cell of a three-column grid (a thumbnail of an 8 inch
    wide figure); method pages had no colour bars for their disparity and error maps."""
    scene = (site / "html" / "scene-boxes.html").read_text(encoding="utf-8")
    wide = scene.split('<div class="wide-figure">', 1)[1].split("</div>", 1)[0]
    assert 'src="img/boxes/badpix_series.png"' in wide
    for grid in scene.split('<div class="grid3')[1:]:
        assert "badpix_series.png" not in grid.split("</div>", 1)[0]
    page = (site / "html" / f"method-{safe_name('published:good')}.html").read_text(encoding="utf-8")
    rows = page.split('<div class="method-row">')[1:]
    assert len(rows) == len(SCENES)
    def disparity_range(text: str) -> list[str]:
        return re.findall(r'<span class="(?:lo|hi)">(-?[0-9.]+)</span>', text)[:2]

    for name, row in zip(SCENES, rows, strict=True):
        assert f'href="scene-{name}.html"' in row.split("</h3>", 1)[0]
        legend = row.split('<div class="grid3 row-legend">', 1)[1]
        bars = re.findall(r'<img src="(img/colorbar_[^"]+)"', legend)
        assert len(bars) == 2 and (site / "html" / bars[0]).is_file()  # disparity and gt - pred
        assert "disparity (px)" in legend and "gt − pred (px)" in legend and "sw bad" in legend
        scene_legend = (site / "html" / f"scene-{name}.html").read_text(encoding="utf-8").split('class="legend"')[1]
        assert disparity_range(legend) == disparity_range(scene_legend)  # the scene's own scale


def test_scene_pages_without_saved_maps_have_no_empty_map_headings(site, tmp_path):
    """Issue 32.4: a report built without saved maps showed the maps' column headings (disparity, BadPix map,
    signed error) over nothing; now the scene is shown as a scene, with a line saying why there are no maps."""
    there = tmp_path / "there"
    there.mkdir()
    shutil.copy(site / "results.json", there / "results.json")
    rc, _, err = _run(["report", str(there), "--out", str(tmp_path / "rep"), "--html"])
    assert rc == 0, err
    html = tmp_path / "rep" / "html"
    scene = (html / "scene-boxes.html").read_text(encoding="utf-8")
    assert "col-heads" not in scene and "BadPix(0.07) map" not in scene and "<h2>Maps" not in scene
    assert 'id="no-method-maps"' in scene and 'src="img/boxes/gt.png"' in scene
    assert "sw bad" not in scene  # no BadPix key without BadPix maps
    method = (html / "method-gt.html").read_text(encoding="utf-8")
    assert 'id="no-method-maps"' in method and "col-heads" not in method


def _site_with_a_wide_section(site: Path, out: Path) -> Path:
    """The fixture's results with a further table as an ablation's "against the baselines": many number
    columns with long names, then long verdict texts."""
    import pandas as pd

    from lfbench.reports.html import SiteSection, build_site, site_inputs_from_dir

    columns = {f"{m}, synthetic (mean of 3), {w}": [12.5, 13.25] for m in ("BadPix(0.07)", "MSE x100")
               for w in ("cell", "cell 95% high", "Plane sweep", "Zero map")}
    verdict = ("does not beat: BadPix(0.07) on synthetic (mean of 3) (100.000 vs 53.086); MSE x100 on synthetic "
               "(mean of 3) (154.354 vs 150.206)")
    table = pd.DataFrame({"seeds": [3, 3], **columns, "vs Plane sweep": [verdict, "beats"],
                          "vs Zero map": [verdict, verdict]}, index=pd.Index(["interval=1", "interval=0.5"],
                                                                            name="variant"))
    inputs = site_inputs_from_dir(site)
    inputs.sections = [SiteSection("baselines", "Against the baselines", table, ["a caption"])]
    return build_site(inputs, out)


def test_text_cells_of_further_tables_keep_a_readable_width(site, tmp_path):
    index = _site_with_a_wide_section(site, tmp_path / "html").read_text(encoding="utf-8")
    table = index.split('id="table-baselines"', 1)[1].split("</table>", 1)[0]
    assert index.count('class="sortable section-table" id="table-baselines"') == 1
    assert table.count('<td class="text"') == 4  # the verdicts
    css = (tmp_path / "html" / "assets" / "site.css").read_text(encoding="utf-8")
    assert re.search(r"\.section-table td\.text \{[^}]*min-width: 24rem", css)


def test_ablation_tables_name_the_papers_tables_only_beside_the_paper(tmp_path):
    """Issue 32.4: with table = "none" and no paper's numbers the captions said "Tables I/II"."""
    from test_ablate import write_spec

    from lfbench.ablation import report as ablation_report
    from lfbench.ablation.spec import load_spec
    from lfbench.reports.paper import load_paper
    from lfbench.results import Record, Results

    spec = load_spec(write_spec(tmp_path / "spec", 'title = "tiny"\ntable = "none"\n[[grid]]\ninterval = [1]\n'))
    results = Results(records=[Record("interval=1", "dots", "badpix_0.07", 5.0, "lowres")])
    tables = ablation_report._tables_i_ii(spec, results, None)
    assert tables.caption[0] == ("tiny: every cell and method, per scene (table_per_scene) and averaged over the "
                                 "scenes (table_average)")
    assert not [line for line in tables.caption if "Tables I/II" in line]
    paper = load_paper(write_paper(tmp_path / "paper"))
    beside = ablation_report._tables_i_ii(spec, results, paper)
    assert beside.paper_caption[0] == "tiny: Tables I/II beside the paper's"
    assert "Tables I/II" not in beside.caption[0]


def test_report_refuses_unknown_figure_formats_before_writing(site, tmp_path, capsys):
    rc = main(["report", str(site), "--out", str(tmp_path / "x"), "--figure-format", "gif"])
    assert rc == 2
    assert "--figure-format: unknown format gif" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


# --------------------------------------------------------------------------- a real browser

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage", "--disable-quic",
                  "--no-first-run", "--disable-background-networking", "--disable-component-update",
                  "--disable-sync", "--window-size=1366,768")


def _browser_paths() -> tuple[str, str] | None:
    binary = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome") if shutil.which(n)),
                  None)
    driver = shutil.which("chromedriver")
    return (binary, driver) if binary and driver else None


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    webdriver = pytest.importorskip("selenium.webdriver", reason="selenium is not installed (pip install -e .[test])")
    from selenium.webdriver.chrome.service import Service

    paths = _browser_paths()
    if paths is None:
        pytest.skip("no headless Chromium here (apt-get install chromium chromium-driver; .ci/run does)")
    opts = webdriver.ChromeOptions()
    for flag in (*CHROMIUM_FLAGS, f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}"):
        opts.add_argument(flag)
    opts.binary_location = paths[0]
    opts.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        driver = webdriver.Chrome(service=Service(paths[1]), options=opts)
    except Exception as exc:  # noqa: BLE001 - any start-up failure means no usable browser here
        pytest.skip(f"headless Chromium does not start here: {str(exc).splitlines()[0]}")
    yield driver
    driver.quit()


def _errors(driver) -> list[str]:
    return [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


def _settle(driver, url_has: str | None = None, timeout_s: float = 60.0) -> None:
    """Wait until the page (whose address contains ``url_has`` where given) has loaded and every image has
    finished, loaded or broken: a navigation started by a click is asynchronous, and on a loaded machine the
    next step can otherwise read a page whose images are still on their way (CI saw all 11 of a method page's images
    incomplete, though the scene page before had loaded the same files)."""
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(driver, timeout_s).until(lambda d: (url_has is None or url_has in d.current_url)
                                           and d.execute_script("return document.readyState") == "complete"
                                           and d.execute_script(
                                               "return Array.from(document.images).every(i => i.complete)"))


def _images_loaded(driver) -> list[str]:
    """The src of every image that did not load (once the page has settled)."""
    _settle(driver)
    return driver.execute_script(
        "return Array.from(document.images).filter(i => !(i.complete && i.naturalWidth > 0)).map(i => i.src);")


def test_site_in_a_headless_browser(site, browser, tmp_path):
    from selenium.webdriver.common.by import By

    html = site / "html"
    browser.get((html / "index.html").as_uri())
    assert browser.title.startswith("lfbench")
    assert _images_loaded(browser) == []
    assert browser.execute_script("return document.images.length") >= 3
    assert _errors(browser) == []
    browser.save_screenshot(str(tmp_path / "index.png"))

    def order(table_id: str) -> list[str]:
        return [th.get_attribute("data-v")
                for th in browser.find_elements(By.CSS_SELECTOR, f"#{table_id} tbody tr th[scope=row]")]

    # sort the BadPix(0.07) table by the first scene's column: ascending, then descending
    table = "table-badpix_0\\.07"
    assert order(table) == ["published:good", "published:bad", "gt"]
    header = browser.find_elements(By.CSS_SELECTOR, f"#{table} thead th")[1]
    header.find_element(By.CSS_SELECTOR, "button").click()
    values = [float(td.get_attribute("data-v"))
              for td in browser.find_elements(By.CSS_SELECTOR, f"#{table} tbody:first-of-type tr td:nth-of-type(1)")]
    assert values == sorted(values) and order(table) == ["published:good", "published:bad", "gt"]
    assert header.get_attribute("aria-sort") == "ascending"
    header.find_element(By.CSS_SELECTOR, "button").click()
    assert order(table) == ["published:bad", "published:good", "gt"]  # the reference row stays apart
    assert header.get_attribute("aria-sort") == "descending"
    # sort by method name
    browser.find_elements(By.CSS_SELECTOR, f"#{table} thead th")[0].find_element(By.CSS_SELECTOR, "button").click()
    assert order(table) == ["published:bad", "published:good", "gt"]
    browser.save_screenshot(str(tmp_path / "index_sorted.png"))
    assert (tmp_path / "index.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"

    # a scene page: every map loads, and it links back to the index
    browser.find_element(By.CSS_SELECTOR, "a.card").click()
    _settle(browser, "/scene-")
    assert _images_loaded(browser) == []
    assert len(browser.find_elements(By.CSS_SELECTOR, ".method-row img")) == 3 * 3
    browser.save_screenshot(str(tmp_path / "scene.png"))
    browser.find_element(By.CSS_SELECTOR, "a.back").click()
    _settle(browser, "/index.html")  # the click's navigation has finished before the next one starts

    # a method page
    browser.get((html / f"method-{safe_name('published:good')}.html").as_uri())
    assert _images_loaded(browser) == []
    assert _errors(browser) == []


def test_pages_read_well_at_1400_by_1000(site, browser, tmp_path):
    """Issue 32.4, in the browser at 1400 x 1000: the per-scene BadPix(t) chart is drawn at a readable width,
    a method page's colour bars are shown, and the rows of a wide further table (an ablation's verdicts against
    the baselines) stay a few lines tall (they were ~400 px, their text one word per line)."""
    from selenium.webdriver.common.by import By

    browser.set_window_size(1400, 1000)
    html = site / "html"
    browser.get((html / "scene-boxes.html").as_uri())
    series = browser.find_element(By.CSS_SELECTOR, 'img[alt="BadPix series"]')
    assert series.size["width"] >= 800, series.size  # was about 330 px, a third of the grid
    browser.save_screenshot(str(tmp_path / "scene.png"))
    browser.get((html / f"method-{safe_name('published:good')}.html").as_uri())
    bars = browser.find_elements(By.CSS_SELECTOR, ".method-row .row-legend .cbar img")
    assert len(bars) == 2 * len(SCENES) and all(b.size["width"] >= 200 and b.size["height"] >= 8 for b in bars)
    assert _images_loaded(browser) == []
    wide = _site_with_a_wide_section(site, tmp_path / "wide")
    browser.get(wide.as_uri())
    heights = [row.size["height"] for row in browser.find_elements(By.CSS_SELECTOR, "#table-baselines tbody tr")]
    assert len(heights) == 2 and max(heights) <= 120, heights
    assert _errors(browser) == []
    browser.set_window_size(1366, 768)


def _urbanlf_shaped_site(out: Path) -> Path:
    """A site as UrbanLF-Syn results give it (issue 38): Table III's eight samples, methods named by long specs,
    and the paper's per-scene table beside ours (13 number columns with long ids), no maps."""
    import pandas as pd

    from lfbench.reports.html import SiteInputs, SiteSection, build_site
    from lfbench.results import Record, Results

    samples = [f"Image{n}" for n in (11, 27, 34, 50, 54, 68, 69, 70)]
    methods = ["planesweep:d_min=-0.5,d_max=1.6,interval=0.1", "planesweep:d_min=-0.5,d_max=2.0,interval=0.5,"
               "subpixel=none", "constant:value=0.5", "subfocal:width=16,weights=sha256:0123456789abcdef"]
    rng = np.random.default_rng(0)
    records = [Record(m, s, metric, float(rng.uniform(0, 100)), "lowres") for m in methods for s in samples
               for metric in ("badpix_0.07", "badpix_0.03", "badpix_0.01", "mse_x100")]
    results = Results(records, meta={"dataset": "urbanlf-syn", "scoring": {"border_px": 15}})
    columns = {f"Img{s[5:]}": rng.uniform(0, 100, 8) for s in samples}
    columns |= {"badpix_0.07": rng.uniform(0, 100, 8), "scenes": [8] * 8, "runtime_s_9x9x256x256": rng.uniform(0, 2, 8),
                "params_millions": rng.uniform(4, 6, 8), "runtime_s (this run, per scene)": rng.uniform(0, 9, 8)}
    table = pd.DataFrame(columns, index=pd.Index([*methods, "LFattNet (paper)", "DistgDisp (paper)",
                                                  "OACC-Net (paper)", "SubFocal (paper)"], name="method"))
    inputs = SiteInputs(results, sections=[SiteSection("table3", "table3: ours beside the paper", table, ["c"])])
    return build_site(inputs, out)


def test_urbanlf_leaderboard_and_table_iii_fit_at_1400(browser, tmp_path):
    """No table of an UrbanLF-Syn report scrolls sideways at 1400 px: long method specs wrap after their commas
    (never inside a number), column ids after their underscores, and number columns stay narrow."""
    from selenium.webdriver.common.by import By

    index = _urbanlf_shaped_site(tmp_path / "html")
    assert "planesweep:<wbr>d_min=-0.5,<wbr>d_max=1.6,<wbr>interval=0.1" in index.read_text(encoding="utf-8")
    browser.set_window_size(1400, 1000)
    browser.get(index.as_uri())
    _settle(browser)
    wraps = browser.find_elements(By.CSS_SELECTOR, ".table-wrap")
    assert len(wraps) == 6  # the overview, Table III and one table per metric
    widths = browser.execute_script(
        "return Array.from(document.querySelectorAll('.table-wrap')).map(w => [w.scrollWidth, w.clientWidth]);")
    assert all(scroll <= client for scroll, client in widths), widths
    assert browser.execute_script("return document.documentElement.scrollWidth <= window.innerWidth")
    browser.save_screenshot(str(tmp_path / "urbanlf.png"))
    assert _errors(browser) == []
    browser.set_window_size(1366, 768)
