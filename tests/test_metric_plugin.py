"""A metric as a plugin (issue 30 item 6), built from the README's text: the module and the entry point of
"A metric of its own", installed as a distribution on PYTHONPATH. `lfbench evaluate --jobs 2 --ci` scores it
in worker processes with bootstrap intervals, the tables carry it and `lfbench regress` gates it; the
benchmark's own metrics come through the same entry-point group and keep their order."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from helpers import write_scene

ROOT = Path(__file__).resolve().parents[1]


def _readme_section() -> str:
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    return text.split("### A metric of its own", 1)[1].split("\n### ", 1)[0]


def _install_readme_plugin(site: Path) -> None:
    """The README's module and entry point as an installed distribution (a dist-info) under ``site``."""
    section = _readme_section()
    module = re.search(r"```python\n(# (\w+)\.py.*?)```", section, re.S)
    group, entry = re.search(r'```toml\n\[project\.entry-points\."([\w.]+)"\]\n(.*?)```', section, re.S).groups()
    site.mkdir(parents=True)
    (site / f"{module[2]}.py").write_text(module[1], encoding="utf-8")
    dist = site / "my_metrics-1.0.dist-info"
    dist.mkdir()
    (dist / "METADATA").write_text("Metadata-Version: 2.1\nName: my-metrics\nVersion: 1.0\n", encoding="utf-8")
    (dist / "entry_points.txt").write_text(f"[{group}]\n{entry.replace(chr(34), '')}", encoding="utf-8")


def _lfbench(*args, pythonpath: Path) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(pythonpath), os.environ.get("PYTHONPATH")]))}
    return subprocess.run([sys.executable, "-m", "lfbench", *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=pythonpath, timeout=600)


def test_readme_metric_plugin_is_scored_bootstrapped_tabled_and_gated(tmp_path):
    _install_readme_plugin(tmp_path / "site")
    write_scene(tmp_path / "data", "tiny", size=40)
    out = tmp_path / "out"
    # installed but not asked for: the dataset's protocol alone says what is scored (issue 38)
    base = ("evaluate", "--data", tmp_path / "data", "--method", "constant:value=0.25", "--no-progress")
    proc = _lfbench(*base, "--out", tmp_path / "plain", pythonpath=tmp_path / "site")
    assert proc.returncode == 0, proc.stderr
    records = json.loads((tmp_path / "plain" / "results.json").read_text())["records"]
    assert [r["metric"] for r in records] == ["badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100"]
    proc = _lfbench(*base, "--out", tmp_path / "bad", "--metrics", "epe,nope", pythonpath=tmp_path / "site")
    assert proc.returncode == 2 and not (tmp_path / "bad").exists()
    line = proc.stderr.strip().splitlines()[-1]
    assert line.startswith("lfbench evaluate: error: --metrics: Unknown metric 'nope'. Available: "), proc.stderr
    assert "epe" in line and "badpix_<t>" in line and "missed_dots" not in line  # the general metrics only
    proc = _lfbench(*base, "--out", out, "--metrics", "epe,badpix_0.07", "--jobs", "2", "--ci", "--ci-resamples",
                    "50", pythonpath=tmp_path / "site")
    assert proc.returncode == 0, proc.stderr
    records = json.loads((out / "results.json").read_text())["records"]
    metrics = [r["metric"] for r in records]
    assert metrics == ["badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100", "epe"]
    # the scene's gt is the plane at disparity 1: |0.25 - 1| everywhere inside the border
    assert next(r["value"] for r in records if r["metric"] == "epe") == 0.75
    ci = (out / "ci.csv").read_text().splitlines()
    row = next(line.split(",") for line in ci if ",tiny,epe," in line)
    assert float(row[4]) == float(row[5]) == 0.75  # equal errors: a zero-width interval at the value
    assert "EPE" in (out / "table_average.md").read_text()
    golden = tmp_path / "golden.json"
    assert _lfbench("regress", golden, out, "--update", pythonpath=tmp_path / "site").returncode == 0
    assert any(g["metric"] == "epe" for g in json.loads(golden.read_text()))
    proc = _lfbench("regress", golden, out, pythonpath=tmp_path / "site")
    assert proc.returncode == 0 and "0 regressions" in proc.stdout, proc.stdout + proc.stderr


def test_builtin_metrics_come_through_the_entry_point_group_first():
    """lfbench's own metrics are the group's entry point ``lfbench.scoring.builtin``, loaded before any plugin's
    (also when an install's metadata predates the group: it is added then)."""
    from lfbench.scoring.metrics import METRICS, list_metrics

    eps = METRICS.entry_points()
    assert eps[0].value == "lfbench.scoring.builtin" and eps[0].group == "lfbench.metrics"
    ids = [m.id for m in list_metrics()]
    assert ids[:5] == ["badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100"]
    assert len(ids) == len(set(ids)) == 23


def test_a_broken_or_misnamed_metric_plugin_is_reported_and_breaks_nothing(tmp_path, monkeypatch):
    """An entry point whose module fails to import, or that names a metric under another id, is recorded with
    its reason (shown when its name is asked for); the benchmark's metrics and the other plugins still load."""
    import pytest

    from lfbench.scoring.metrics import METRICS
    from lfbench.utils.errors import SpecError

    site = tmp_path / "site"
    _install_readme_plugin(site)
    with open(site / "my_metrics-1.0.dist-info" / "entry_points.txt", "a", encoding="utf-8") as f:
        f.write("\nbroken = my_metrics_does_not_exist:X\nmae = my_metrics:EPE\n")
    monkeypatch.syspath_prepend(str(site))
    registry = METRICS  # the process-wide registry, as it is now, loading the group again (undone afterwards)
    for attr in ("_objects", "_entries", "_aliases", "load_errors"):
        monkeypatch.setattr(registry, attr, dict(getattr(registry, attr)))
    monkeypatch.setattr(registry, "_loaded", False)
    monkeypatch.delitem(sys.modules, "my_metrics", raising=False)
    assert [m.id for m in registry.all()][-1] == "epe" and registry.get("badpix_0070").id == "badpix_0.07"
    assert registry.load_errors["broken"].startswith("ModuleNotFoundError: No module named 'my_metrics_does_not_exist'")
    assert registry.load_errors["mae"] == "metric 'epe' registered as 'mae': the name must be the metric's id"
    with pytest.raises(SpecError, match=r"^Unknown metric 'broken' \(plugin failed to load: ModuleNotFoundError"):
        registry.get("broken")
