"""`lfbench demo`: end to end on a tiny setting, data reuse, refusal to mix, method selection."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from lfbench.cli import main
from lfbench.method.registry import REGISTRY
from lfbench.runs.demo import MANIFEST, select_methods, split_specs

GENERAL = {"badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100"}
SCENES = {"synth_5_0", "synth_5_1"}


def _methods() -> list[str]:
    names = REGISTRY.names()
    return ["gt"] + (["planesweep"] if "planesweep" in names else [])


@pytest.fixture(scope="module")
def demo(tmp_path_factory) -> tuple[Path, str, str]:
    """One tiny demo run through the CLI: (folder, stdout, stderr)."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("demo") / "d"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        rc = main(["demo", "--out", str(out), "--seed", "5", "--size", "48", "--scenes", "2",
                   "--methods", ",".join(_methods()), "--no-progress"])
    assert rc == 0, stderr.getvalue()
    return out, stdout.getvalue(), stderr.getvalue()


def test_demo_writes_scored_results_tables_and_figures(demo):
    out, stdout, _ = demo
    data = json.loads((out / "results.json").read_text())
    keys = {(r["method"], r["scene"], r["metric"]) for r in data["records"]}
    assert keys == {(m, s, k) for m in _methods() for s in SCENES for k in GENERAL}
    assert all(r["resolution"] == "lowres" for r in data["records"])
    gt = {r["metric"]: r["value"] for r in data["records"] if r["method"] == "gt"}
    assert gt["badpix_0.07"] == 0.0 and gt["badpix_0.01"] == 0.0 and gt["mse_x100"] == 0.0
    assert {(r["method"], r["scene"]) for r in data["runs"]} == {(m, s) for m in _methods() for s in SCENES}
    assert data["meta"]["demo"]["seed"] == 5 and data["meta"]["demo"]["size"] == 48
    assert (out / "results.csv").read_text().splitlines()[0] == "method,scene,metric,value,resolution"
    for name in ("table_per_scene", "table_average"):
        for ext in ("md", "tex", "csv"):
            assert (out / f"{name}.{ext}").stat().st_size > 0
    for scene in SCENES:
        assert (out / "figures" / f"overview_{scene}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (out / "figures" / "badpix_series.png").is_file()
    assert "| gt " in stdout and "BadPix(0.07)" in stdout and str(out / "results.json") in stdout
    if "planesweep" in _methods():  # a real method: scored, and worse than the oracle
        ps = [r["value"] for r in data["records"] if r["method"] == "planesweep" and r["metric"] == "mse_x100"]
        assert all(v > 0 for v in ps)


def test_demo_saves_its_maps_and_an_html_report_ranking_its_methods(demo):
    import re

    out, stdout, _ = demo
    for m in _methods():
        assert {p.stem for p in (out / "maps" / m / "disp_maps").glob("*.pfm")} == SCENES
    index = (out / "html" / "index.html").read_text(encoding="utf-8")
    overview = index.split('id="table-overview"', 1)[1].split("</table>", 1)[0]
    ranked = re.findall(r'<th scope="row" data-v="([^"]*)"', overview)
    assert ranked[-1] == "gt" and sorted(ranked) == sorted(_methods())  # the oracle: a reference row, last
    assert 'data-v="gt"' in overview.split('<tbody class="reference">', 1)[1]
    for scene in SCENES:
        page = (out / "html" / f"scene-{scene}.html").read_text(encoding="utf-8")
        assert all(f"img/{scene}/{m}.badpix.png" in page for m in _methods())
    assert str(out / "html" / "index.html") in stdout


def test_rerun_reuses_matching_data_and_refuses_other_settings(demo, capsys):
    out, _, _ = demo
    manifest = out / "data" / MANIFEST
    before = manifest.stat().st_mtime_ns, sorted(p.name for p in (out / "data" / "synthetic").iterdir())
    capsys.readouterr()
    assert main(["demo", "--out", str(out), "--seed", "5", "--size", "48", "--scenes", "2", "--methods", "gt",
                 "--no-figures", "--no-progress"]) == 0
    assert "reusing the demo data" in capsys.readouterr().err
    assert (manifest.stat().st_mtime_ns, sorted(p.name for p in (out / "data" / "synthetic").iterdir())) == before
    for argv in (["--size", "64", "--seed", "5", "--scenes", "2"], ["--seed", "6", "--size", "48", "--scenes", "2"],
                 ["--scenes", "3", "--seed", "5", "--size", "48"]):
        assert main(["demo", "--out", str(out), *argv, "--methods", "gt", "--no-progress"]) == 2
        err = capsys.readouterr().err
        assert "never mixed" in err and len(err.strip().splitlines()) == 1
    assert sorted(p.name for p in (out / "data" / "synthetic").iterdir()) == before[1]


def test_demo_refuses_a_foreign_folder_and_bad_specs_before_any_work(tmp_path, capsys):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep me")
    assert main(["demo", "--out", str(tmp_path / "mine"), "--size", "48", "--scenes", "1"]) == 2
    assert "holds no lfbench demo" in capsys.readouterr().err
    assert sorted(p.name for p in (tmp_path / "mine").iterdir()) == ["notes.txt"]
    assert main(["demo", "--out", str(tmp_path / "new"), "--methods", "no_such_method"]) == 2
    assert "Unknown method" in capsys.readouterr().err
    assert not (tmp_path / "new").exists()


def test_split_specs_keeps_parameters_with_their_method():
    assert split_specs("gt, planesweep:interval=0.5,interpolation=nearest,published:path=/x") == [
        "gt", "planesweep:interval=0.5,interpolation=nearest", "published:path=/x"]
    assert split_specs("") == []


def test_default_selection_skips_methods_with_required_parameters(demo):
    from lfbench.data.hci import HCIDataset

    out, _, _ = demo
    scenes = list(HCIDataset.open(out / "data"))
    lines: list[str] = []
    methods, skipped = select_methods(None, scenes, lines.append)
    labels = [m.label for m in methods]
    assert "gt" in labels and "published" not in labels
    assert "needs parameter path" in skipped["published"]
    assert len(lines) == len(skipped) and all("\n" not in line for line in lines)
    for method in methods:  # everything selected can run on every scene
        assert all(method.available_for(s) is None for s in scenes)
