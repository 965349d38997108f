"""Start-up stays light (issue 23.3): `lfbench --help`, `methods`, `regress` and `validate-submission`
import neither torch nor a plugin command's module (with the bundled plugins installed, which register
networks and a command), checked in a fresh interpreter through sys.modules. Not a timed test: the time
it saves is measured in the report (python -X importtime)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

PROBE = """
import json, sys
from lfbench.cli import main
try:
    code = main(sys.argv[1:])
except SystemExit as exc:
    code = exc.code
print(json.dumps({"code": code, "modules": sorted(m for m in sys.modules
                  if m.split(".")[0] in ("torch", "scipy", "pandas", "lfbench_methods", "numpy", "PIL", "lfbench"))}),
      file=sys.stderr)
"""


def _imports(*args: str, cwd: Path) -> tuple[int, list[str]]:
    proc = subprocess.run([sys.executable, "-c", PROBE, *args], capture_output=True, text=True, timeout=300,
                          cwd=cwd)
    report = json.loads(proc.stderr.strip().splitlines()[-1])
    return report["code"], report["modules"]


def _golden_as_results(tmp_path: Path) -> Path:
    records = json.loads((ROOT / "results" / "golden.json").read_text())
    path = tmp_path / "results.json"
    path.write_text(json.dumps({"records": [{k: r[k] for k in ("method", "scene", "metric", "value", "resolution")}
                                            for r in records]}))
    return path


def _submission(tmp_path: Path) -> Path:
    from helpers import write_submission

    return write_submission(tmp_path / "sub", {"boxes": __import__("numpy").zeros((512, 512), "float32")},
                            {"boxes": "1.0\n"})


@pytest.mark.parametrize("command", ["--help", "methods", "regress", "validate-submission"])
def test_light_commands_import_neither_torch_nor_plugin_commands(command, tmp_path):
    args = {"--help": ["--help"], "methods": ["methods"],
            "regress": ["regress", str(ROOT / "results" / "golden.json"), str(_golden_as_results(tmp_path))],
            "validate-submission": ["validate-submission", str(_submission(tmp_path)), "--scenes", "boxes"]}[command]
    code, modules = _imports(*args, cwd=tmp_path)
    assert code == 0, (command, code)
    assert not [m for m in modules if m.split(".")[0] == "torch"], f"lfbench {command} imported torch"
    assert "lfbench_methods.convert_keras" not in modules  # the plugin command convert-keras: not imported
    if command != "methods":  # listing methods imports the modules that register them (light ones)
        assert not [m for m in modules if m.startswith("lfbench_methods")], modules
    if command in ("--help", "regress"):
        assert not [m for m in modules if m.split(".")[0] == "scipy"], modules


def test_scoring_every_metric_imports_neither_scipy_nor_pandas_nor_the_site(tmp_path):
    """Issue 39.7: importing scipy.ndimage cost more CPU time than scoring a low-resolution scene, importing
    pandas more than writing every table, and the HTML report's module (jinja2) came with every evaluate;
    scoring computes the upsampling index and the Scharr filters itself (lfbench.scoring.filters), the tables
    are built from the records (lfbench.reports.tables.Table), and the site's module comes with --html."""
    import numpy as np
    from helpers import write_scene, write_submission

    mask = np.zeros((40, 40), dtype=bool)
    mask[5:30, 8:33] = True
    write_scene(tmp_path / "data", "boxes", size=40, views=False,  # MAE and bumpiness: the Scharr filters
                masks={"mask_planes_lowres": mask, "mask_smooth_surfaces_lowres": ~mask})
    write_scene(tmp_path / "data", "stripes", "stratified", size=40, views=False,  # the upsampling index
                gt_highres=np.ones((400, 400), np.float32))
    maps = {name: np.full((40, 40), 1.5, np.float32) for name in ("boxes", "stripes")}
    sub = write_submission(tmp_path / "sub", maps)
    code, modules = _imports("evaluate", "--data", str(tmp_path / "data"), "--method", f"published:path={sub}",
                             "--all-metrics", "--out", str(tmp_path / "out"), "--no-progress", cwd=tmp_path)
    assert code == 0
    assert "lfbench.scoring.region_metrics" in modules and "lfbench.scoring.filters" in modules  # scored them
    assert not [m for m in modules if m.split(".")[0] in ("scipy", "pandas")], modules
    assert "lfbench.reports.html" not in modules
    assert (tmp_path / "out" / "table_average.csv").is_file() and (tmp_path / "out" / "table_per_scene.md").is_file()
    records = (tmp_path / "out" / "results.csv").read_text()
    assert "mae_planes" in records and "bumpiness_planes" in records and ",highres" in records


def test_a_command_that_needs_torch_still_gets_it(tmp_path):
    """The light start-up does not hide a network from the commands that run one."""
    code, modules = _imports("info", "subfocal", cwd=tmp_path)
    assert code == 0 and "torch" in modules and "lfbench_methods.subfocal.network" in modules


@pytest.mark.parametrize("args", [["--help"], ["evaluate", "--help"], ["regress", "--help"], ["train", "--help"]])
def test_help_imports_neither_numpy_nor_other_commands(args, tmp_path):
    """Issue 32.5: `import lfbench` imported the whole public API (numpy, PIL, the method and metric registries)
    and `lfbench --help` imported every command's module for its one-line help (the bench and ablate modules
    brought the trainable networks' registry): about a second before any work. The public names are imported
    on first use, and the help lines are read from the command modules' sources."""
    code, modules = _imports(*args, cwd=tmp_path)
    assert code == 0
    assert not [m for m in modules if m.split(".")[0] in ("numpy", "PIL", "torch")], modules
    commands = {m.rsplit(".", 1)[1] for m in modules if m.startswith("lfbench.cli.")} - {"argtypes"}
    assert commands == ({args[0]} if args[0] != "--help" else set()), commands


def test_the_public_api_is_imported_on_first_use(tmp_path):
    probe = ("import sys, lfbench; before = 'numpy' in sys.modules; from lfbench import Method, read_pfm, get_metric; "
             "import lfbench.method.base as b; print(before, lfbench.Method is b.Method, callable(read_pfm), "
             "get_metric('badpix_0.07').id, sorted(set(lfbench.__all__) - set(dir(lfbench))))")
    out = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert out.stdout.split() == ["False", "True", "True", "badpix_0.07", "[]"], out.stderr
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        import lfbench

        lfbench.nope  # noqa: B018


def test_evaluating_a_submission_imports_no_statistics_it_does_not_use(tmp_path):
    """Issue 39.7: scipy.stats came with the report writers (through the bootstrap module) and cost more CPU than
    scoring one submission (1.4 s); `lfbench evaluate` without --ci or comparisons never calls it. It is
    imported where a test is computed (and still is: --ci works, test_stats)."""
    from helpers import write_scene, write_submission

    root = tmp_path / "data"
    write_scene(root, "tiny", size=40, views=False)
    sub = write_submission(tmp_path / "sub", {"tiny": __import__("numpy").full((40, 40), 1.25, "float32")})
    code, modules = _imports("-q", "evaluate", "--data", str(root), "--method", f"published:path={sub}",
                             "--out", str(tmp_path / "out"), "--no-progress", cwd=tmp_path)
    assert code == 0
    assert (tmp_path / "out" / "results.csv").is_file()
    assert "scipy.stats" not in modules, [m for m in modules if m.startswith("scipy.stats")][:5]
    assert not [m for m in modules if m.split(".")[0] == "torch"], "evaluating a submission imported torch"
