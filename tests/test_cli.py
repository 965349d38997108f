"""The CLI contract (evaluate, predict, methods, info) and every bad input: exit code 2, exactly one line
on stderr naming the file or problem, no traceback, nothing half-written. A few run as real processes."""

from __future__ import annotations

import csv
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import (
    assert_one_error_line,
    forget_module,
    install_fake_plugin,
    pfm_bytes,
    run_cli,
    write_dist_info,
    write_scene,
    write_submission,
    zip_folder,
)

from lfbench.cli import main
from lfbench.data.pfm import read_pfm, write_pfm

GENERAL_IDS = {"badpix_0.01", "badpix_0.03", "badpix_0.07", "mse_x100", "q25_x100"}
SIZE = 40


def assert_nothing_written(out: Path) -> None:
    leftovers = sorted(p.name for p in out.rglob("*")) if out.exists() else []
    assert leftovers == [], leftovers


def reference_scores(gt: np.ndarray, pred: np.ndarray, border: int = 15) -> dict[str, float]:
    g = gt[border:-border, border:-border].astype(np.float32).ravel()
    p = pred[border:-border, border:-border].astype(np.float32).ravel()
    err = np.abs(g - p)
    out = {f"badpix_{t:g}": 100.0 * np.count_nonzero(err > t) / err.size for t in (0.01, 0.03, 0.07)}
    out["mse_x100"] = float(np.mean(np.square(g - p))) * 100
    out["q25_x100"] = float(np.sort(err * 100)[int(0.25 * err.size)])
    return out


@pytest.fixture()
def data(tmp_path):
    """Three tiny scenes (two in 'training', one in 'additional') and a submission for two of them."""
    rng = np.random.default_rng(0)
    root = tmp_path / "data"
    gts = {}
    for name, cat in (("alpha", "training"), ("beta", "training"), ("gamma", "additional")):
        gts[name] = rng.uniform(-1, 1, (SIZE, SIZE)).astype(np.float32)
        write_scene(root, name, cat, size=SIZE, gt=gts[name], seed=len(gts))
    preds = {n: (gts[n] + rng.standard_normal((SIZE, SIZE)) * 0.05).astype(np.float32) for n in ("alpha", "beta")}
    sub = write_submission(tmp_path / "mysub", preds, {"alpha": "3.5\n", "beta": "0.25\n"})
    return {"root": root, "gts": gts, "preds": preds, "sub": sub, "out": tmp_path / "out"}


@pytest.fixture()
def plugin(tmp_path, monkeypatch):
    names = install_fake_plugin(tmp_path / "site", monkeypatch)
    yield names
    forget_module(names["module"])


# --------------------------------------------------------------------------- evaluate


def test_evaluate_contract(data, capsys):
    rc, out, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", "gt", "--method",
                           f"published:path={data['sub']}", "--scenes", "alpha,beta", "--out", data["out"],
                           "--no-progress")
    assert rc == 0, err
    with open(data["out"] / "results.csv", newline="") as f:
        rows = list(csv.reader(f))
    assert rows[0] == ["method", "scene", "metric", "value", "resolution"]
    records = [dict(zip(rows[0], r, strict=True)) for r in rows[1:]]
    assert {(r["method"], r["scene"]) for r in records} == {(m, s) for m in ("gt", "published:mysub")
                                                            for s in ("alpha", "beta")}
    for method in ("gt", "published:mysub"):
        for scene in ("alpha", "beta"):
            got = {r["metric"]: float(r["value"]) for r in records if (r["method"], r["scene"]) == (method, scene)}
            assert GENERAL_IDS <= set(got)
            ref = reference_scores(data["gts"][scene], data["gts"][scene] if method == "gt" else data["preds"][scene])
            for metric, value in ref.items():
                assert got[metric] == pytest.approx(value, rel=1e-6, abs=1e-12), (method, scene, metric)
    assert {r["resolution"] for r in records} == {"lowres"}

    doc = json.loads((data["out"] / "results.json").read_text())
    assert len(doc["records"]) == len(records)
    assert set(doc["records"][0]) == {"method", "scene", "metric", "value", "resolution"}
    runtimes = {(r["method"], r["scene"]): r["runtime_s"] for r in doc["runs"]}
    assert runtimes[("published:mysub", "alpha")] == 3.5 and runtimes[("published:mysub", "beta")] == 0.25
    assert runtimes[("gt", "alpha")] >= 0

    # the table is printed: one row per (scene, metric), one column per method
    assert "| scene" in out and "gt" in out and "published:mysub" in out
    assert sum(1 for line in out.splitlines() if line.startswith("| alpha")) >= 5
    assert "gamma" not in out
    assert not [p for p in data["out"].iterdir() if p.name.endswith(".tmp")]


def test_evaluate_all_scenes_skips_the_ones_without_a_map(data, capsys):
    rc, out, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", f"published:path={data['sub']}",
                           "--out", data["out"], "--no-progress")
    assert rc == 0
    assert "skipping published:mysub on gamma" in err
    doc = json.loads((data["out"] / "results.json").read_text())
    assert {r["scene"] for r in doc["records"]} == {"alpha", "beta"}


def test_evaluate_nonfinite_prediction_is_reported_and_counted_bad(data, capsys):
    pred = data["preds"]["alpha"].copy()
    pred[20, 20:23] = np.nan
    pred[21, 20] = np.inf
    write_pfm(data["sub"] / "disp_maps" / "alpha.pfm", pred)
    rc, out, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", f"published:path={data['sub']}",
                           "--scenes", "alpha", "--out", data["out"], "--no-progress")
    assert rc == 0
    assert "published:mysub on alpha: 4 non-finite pixels inside the evaluation mask (counted as bad pixels)" in err
    doc = json.loads((data["out"] / "results.json").read_text())
    values = {r["metric"]: r["value"] for r in doc["records"]}
    finite = np.where(np.isfinite(pred), pred, data["gts"]["alpha"] + 1.0)  # a non-finite pixel is a bad pixel
    assert values["badpix_0.07"] == pytest.approx(reference_scores(data["gts"]["alpha"], finite)["badpix_0.07"])
    assert doc["runs"][0]["nonfinite_pixels"] == 4
    # the toolkit's rule on request: NaN counted good
    rc, _, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", f"published:path={data['sub']}",
                         "--scenes", "alpha", "--out", data["out"], "--no-progress", "--toolkit-nonfinite")
    doc = json.loads((data["out"] / "results.json").read_text())
    values_tk = {r["metric"]: r["value"] for r in doc["records"]}
    assert values["badpix_0.07"] - values_tk["badpix_0.07"] == pytest.approx(100 * 3 / 100)
    assert "toolkit rule" in err


# --------------------------------------------------------------------------- predict


def test_predict_gt_for_a_scene_folder(data, tmp_path, capsys):
    scene = data["root"] / "training" / "alpha"
    rc, out, err = run_cli(capsys, "predict", "--method", "gt", "--input", scene, "--out", tmp_path / "x.pfm")
    assert rc == 0, err
    assert np.array_equal(read_pfm(tmp_path / "x.pfm"), data["gts"]["alpha"])
    assert "gt: wrote" in out and "40x40" in out
    rc, _, _ = run_cli(capsys, "predict", "--method", "gt", "--input", scene, "--out", tmp_path / "x.npy")
    assert rc == 0
    assert np.array_equal(np.load(tmp_path / "x.npy", allow_pickle=False), data["gts"]["alpha"])


def test_predict_views_npy_with_a_plugin_method(data, tmp_path, plugin, capsys):
    rng = np.random.default_rng(1)
    views = rng.uniform(0, 1, (12, 10, 81)).astype(np.float32)  # (H, W, 81), channel k = view k
    np.save(tmp_path / "views.npy", views)
    rc, out, err = run_cli(capsys, "predict", "--method", f"{plugin['centre']}:gain=2", "--input",
                           tmp_path / "views.npy", "--out", tmp_path / "c.pfm")
    assert rc == 0, err
    assert np.array_equal(read_pfm(tmp_path / "c.pfm"), 2 * views[:, :, 40])  # centre = view 40
    # any square grid: 7x7 views (49 channels), the centre is view 3 * 7 + 3 = 24 (issue 38)
    np.save(tmp_path / "views7.npy", views[:, :, :49])
    rc, out, err = run_cli(capsys, "predict", "--method", plugin["centre"], "--input", tmp_path / "views7.npy",
                           "--out", tmp_path / "c7.pfm")
    assert rc == 0, err
    assert np.array_equal(read_pfm(tmp_path / "c7.pfm"), views[:, :, 24])
    # the same method on a scene folder: the gray centre view
    rc, _, err = run_cli(capsys, "predict", "--method", plugin["centre"], "--input",
                         data["root"] / "training" / "beta", "--out", tmp_path / "b.npy")
    assert rc == 0, err
    from PIL import Image

    rgb = np.asarray(Image.open(data["root"] / "training" / "beta" / "input_Cam040.png"), np.float64)
    gray = (rgb @ [0.299, 0.587, 0.114]) / 255
    np.testing.assert_allclose(np.load(tmp_path / "b.npy"), gray, atol=1e-6)


def test_methods_and_info(capsys, plugin):
    rc, out, _ = run_cli(capsys, "methods")
    assert rc == 0
    assert "gt: Oracle" in out and "published: " in out and "path (path, required)" in out
    assert f"{plugin['centre']}: Returns the centre view" in out
    assert f"{plugin['broken']}: plugin failed to load: ModuleNotFoundError" in out
    rc, out, _ = run_cli(capsys, "methods", "--names")
    assert rc == 0 and {"gt", "published", plugin["centre"], plugin["offset"]} <= set(out.split())
    rc, out, _ = run_cli(capsys, "info", "published")
    assert rc == 0
    assert out.startswith("published: Precomputed results") and "path (path, required): the submission folder" in out


# --------------------------------------------------------------------------- bad input


def _evaluate_published(capsys, data, *extra):
    return run_cli(capsys, "evaluate", "--data", data["root"], "--method", f"published:path={data['sub']}",
                   "--scenes", "alpha,beta", "--out", data["out"], "--no-progress", *extra)


@pytest.mark.parametrize("content, fragment", [
    (pfm_bytes(np.zeros((SIZE, SIZE), np.float32))[:-10], "truncated PFM"),
    (b"\x89PNG\r\n\x1a\n not a pfm", "not a PFM file"),
    (b"", "not a PFM file: header ends early"),
    (pfm_bytes(np.zeros((39, 39), np.float32)), "prediction is 39x39, scene is 40x40"),
    (pfm_bytes(np.zeros((50, 40), np.float32)), "prediction is 40x50, scene is 40x40"),
    (pfm_bytes(np.zeros((SIZE, SIZE, 3), np.float32), ident=b"PF"), "disparity must be a 2-D map"),
])
def test_bad_prediction_file(data, capsys, content, fragment):
    (data["sub"] / "disp_maps" / "beta.pfm").write_bytes(content)  # alpha is fine and scored first
    rc, out, err = _evaluate_published(capsys, data)
    line = assert_one_error_line(rc, err, fragment)
    assert "beta" in line
    assert_nothing_written(data["out"])


def test_missing_views(data, tmp_path, plugin, capsys):
    scene = data["root"] / "training" / "alpha"
    (scene / "input_Cam017.png").unlink()
    rc, _, err = run_cli(capsys, "predict", "--method", plugin["centre"], "--input", scene, "--out",
                         tmp_path / "x.pfm")
    assert_one_error_line(rc, err, str(scene), "missing 1 of 81 views: input_Cam017.png")
    assert not (tmp_path / "x.pfm").exists()
    rc, _, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", plugin["centre"], "--scenes",
                         "alpha", "--out", data["out"], "--no-progress")
    assert_one_error_line(rc, err, "input_Cam017.png")
    assert_nothing_written(data["out"])


def test_missing_cfg(data, tmp_path, capsys):
    scene = data["root"] / "training" / "alpha"
    (scene / "parameters.cfg").unlink()
    rc, _, err = run_cli(capsys, "predict", "--method", "gt", "--input", scene, "--out", tmp_path / "x.pfm")
    assert_one_error_line(rc, err, str(scene), "no scenes found")  # the layout is detected as evaluate detects it
    assert not (tmp_path / "x.pfm").exists()
    rc, _, err = run_cli(capsys, "evaluate", "--data", scene, "--method", "gt", "--out", data["out"])
    assert_one_error_line(rc, err, str(scene), "no scenes found")
    assert_nothing_written(data["out"])


def test_cfg_without_a_required_key(data, capsys):
    cfg = data["root"] / "training" / "beta" / "parameters.cfg"
    cfg.write_text("\n".join(line for line in cfg.read_text().splitlines() if not line.startswith("baseline_mm")))
    rc, _, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", "gt", "--out", data["out"])
    assert_one_error_line(rc, err, str(cfg), "missing required key [extrinsics] baseline_mm")
    assert_nothing_written(data["out"])


@pytest.mark.parametrize("spec, fragment", [
    ("nope", "Unknown method 'nope'. Available: "),
    ("gt:foo=1", "method 'gt' has no parameter 'foo'"),
    ("published:path=/definitely/not/here", "not a submission folder"),
    ("published", "method 'published' needs parameter path"),
    ("gt:", None),  # valid: no parameters
    ("bad spec!", "bad method spec"),
])
def test_method_spec_errors(data, capsys, spec, fragment):
    rc, out, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", spec, "--scenes", "alpha",
                           "--out", data["out"], "--no-progress")
    if fragment is None:
        assert rc == 0
        return
    assert_one_error_line(rc, err, "lfbench evaluate: error:", fragment)
    assert_nothing_written(data["out"])


def test_empty_and_missing_data_root(tmp_path, capsys):
    (tmp_path / "empty").mkdir()
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "empty", "--method", "gt", "--out",
                         tmp_path / "out")
    assert_one_error_line(rc, err, str(tmp_path / "empty"), "no scenes found")
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path / "nope", "--method", "gt", "--out",
                         tmp_path / "out")
    assert_one_error_line(rc, err, str(tmp_path / "nope"), "data root not found")
    assert_nothing_written(tmp_path / "out")


def test_unknown_scene_selection(data, capsys):
    rc, _, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", "gt", "--scenes", "alpha,zeta",
                         "--out", data["out"])
    assert_one_error_line(rc, err, "no scene 'zeta'")
    assert_nothing_written(data["out"])


def test_zip_member_outside_its_folder(data, tmp_path, capsys):
    zpath = zip_folder(data["sub"], tmp_path / "sub.zip", extra=[("../../outside.pfm", b"x")])
    rc, out, err = run_cli(capsys, "validate-submission", zpath, "--scenes", "alpha,beta", "--size", "40")
    assert_one_error_line(rc, err, str(zpath), "1 problem", "'..' in the path")
    assert out.splitlines() == [f"{zpath}:../../outside.pfm: '..' in the path (escapes the submission folder)"]
    assert not (tmp_path.parent / "outside.pfm").exists()


def test_validate_nan_prediction(data, capsys):
    pred = data["preds"]["alpha"].copy()
    pred[0, 0] = np.nan
    write_pfm(data["sub"] / "disp_maps" / "alpha.pfm", pred)
    rc, out, err = run_cli(capsys, "validate-submission", data["sub"], "--scenes", "alpha,beta", "--size", "40")
    assert_one_error_line(rc, err, "alpha.pfm", "1 non-finite values (1 NaN, 0 inf)")


@pytest.mark.parametrize("make, fragment", [
    (lambda p: np.save(p, np.zeros((4, 4, 80), np.float32)), "A from 2 to 33, e.g. 81 for 9x9), got shape (4, 4, 80)"),
    (lambda p: np.save(p, np.full((4, 4, 81), np.nan, np.float32)), "views must be finite"),
    (lambda p: np.save(p, np.array([{"a": 1}], dtype=object), allow_pickle=True), "cannot read .npy"),
    (lambda p: p.write_bytes(b"garbage"), "cannot read .npy"),
])
def test_bad_views_npy(tmp_path, capsys, make, fragment):
    path = tmp_path / "views.npy"
    make(path)
    rc, _, err = run_cli(capsys, "predict", "--method", "gt", "--input", path, "--out", tmp_path / "o.pfm")
    assert_one_error_line(rc, err, str(path), fragment)
    assert not (tmp_path / "o.pfm").exists()


def test_predict_gt_on_views_without_ground_truth(tmp_path, capsys):
    np.save(tmp_path / "views.npy", np.zeros((4, 4, 81), np.float32))
    rc, _, err = run_cli(capsys, "predict", "--method", "gt", "--input", tmp_path / "views.npy", "--out",
                         tmp_path / "o.pfm")
    assert_one_error_line(rc, err, "gt cannot run on this input: the scene has no ground truth")
    assert not (tmp_path / "o.pfm").exists()


def test_predict_output_suffix_and_missing_input(tmp_path, capsys):
    rc, _, err = run_cli(capsys, "predict", "--method", "gt", "--input", tmp_path, "--out", tmp_path / "o.png")
    assert_one_error_line(rc, err, "output must end in .pfm or .npy")
    rc, _, err = run_cli(capsys, "predict", "--method", "gt", "--input", tmp_path / "nope.npy", "--out",
                         tmp_path / "o.pfm")
    assert_one_error_line(rc, err, "nope.npy", "input not found")


def test_usage_errors_are_one_line(capsys, tmp_path):
    rc, _, err = run_cli(capsys, "evaluate", "--data", tmp_path, "--method", "gt")
    assert_one_error_line(rc, err, "the following arguments are required: --out")
    rc, _, err = run_cli(capsys, "frobnicate")
    assert_one_error_line(rc, err, "invalid choice")
    rc, _, err = run_cli(capsys, "info", "nope")
    assert_one_error_line(rc, err, "Unknown method 'nope'")


# --------------------------------------------------------------------------- real processes


def _run(args: list[str], **env: str) -> subprocess.CompletedProcess:
    full_env = {**os.environ, **env}
    return subprocess.run(args, capture_output=True, text=True, env=full_env, timeout=120)


def _script() -> str:
    path = Path(sys.executable).parent / "lfbench"
    if not path.exists():
        pytest.skip("the lfbench console script is not installed beside this Python")
    return str(path)


def test_process_truncated_prediction(data):
    (data["sub"] / "disp_maps" / "alpha.pfm").write_bytes(pfm_bytes(np.zeros((SIZE, SIZE), np.float32))[:100])
    proc = _run([_script(), "evaluate", "--data", str(data["root"]), "--method", f"published:path={data['sub']}",
                 "--scenes", "alpha", "--out", str(data["out"])])
    assert_one_error_line(proc.returncode, proc.stderr, "alpha.pfm", "truncated PFM")
    assert_nothing_written(data["out"])


def test_process_empty_data_root(tmp_path):
    (tmp_path / "empty").mkdir()
    proc = _run([sys.executable, "-m", "lfbench", "evaluate", "--data", str(tmp_path / "empty"), "--method", "gt",
                 "--out", str(tmp_path / "out")])
    assert_one_error_line(proc.returncode, proc.stderr, "no scenes found")
    assert_nothing_written(tmp_path / "out")


def test_process_zip_escape_and_unknown_method(data, tmp_path):
    zpath = zip_folder(data["sub"], tmp_path / "s.zip", extra=[("/abs/evil.txt", b"x")])
    proc = _run([sys.executable, "-m", "lfbench", "validate-submission", str(zpath), "--scenes", "alpha,beta",
                 "--size", "40"])
    assert_one_error_line(proc.returncode, proc.stderr, "absolute path")
    proc = _run([_script(), "predict", "--method", "nope:x=1", "--input", str(data["root"] / "training" / "alpha"),
                 "--out", str(tmp_path / "o.pfm")])
    assert_one_error_line(proc.returncode, proc.stderr, "Unknown method 'nope'")


def test_process_plugin_discovered_through_entry_points(tmp_path):
    """A third-party distribution on PYTHONPATH adds a method that `lfbench predict` can run on VIEWS.npy."""
    from helpers import write_fake_plugin

    names = write_fake_plugin(tmp_path / "site", "proc")
    views = np.random.default_rng(2).uniform(0, 1, (6, 7, 81)).astype(np.float32)
    np.save(tmp_path / "views.npy", views)
    pythonpath = os.pathsep.join([str(tmp_path / "site"), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    proc = _run([sys.executable, "-m", "lfbench", "predict", "--method", f"{names['centre']}:gain=0.5", "--input",
                 str(tmp_path / "views.npy"), "--out", str(tmp_path / "c.npy")], PYTHONPATH=pythonpath)
    assert proc.returncode == 0, proc.stderr
    assert np.array_equal(np.load(tmp_path / "c.npy"), 0.5 * views[:, :, 40])


def test_evaluate_rates_uncertainty_maps(data, capsys):
    rc, out, err = run_cli(capsys, "evaluate", "--data", data["root"], "--method", "planesweep:interval=0.5",
                           "--method", "gt", "--scenes", "alpha", "--out", data["out"], "--no-progress",
                           "--uncertainty")
    assert rc == 0, err
    with open(data["out"] / "uncertainty.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert {(r["method"], r["scene"], r["measure"]) for r in rows} == {
        ("planesweep:interval=0.5", "alpha", m) for m in ("abs", "badpix_0.07")}
    for r in rows:
        assert float(r["ause"]) >= 0 and int(r["n_pixels"]) == (SIZE - 30) ** 2
    assert "note: gt predicts no uncertainty map" in err and "AUSE" in out  # notes are log messages (stderr)
    assert (data["out"] / "figures" / "sparsification_abs.png").is_file()


# --------------------------------------------------------------------------- plugin subcommands

COMMAND_MODULE = '''\
"""Echo the argument (a plugin command used by the tests)."""
HELP = "echo WORD times N"


def add_arguments(p):
    p.add_argument("word")
    p.add_argument("--times", type=int, default=1)


def run(args):
    print(" ".join([args.word] * args.times))
    return 3
'''


def test_plugin_commands_come_from_entry_points(tmp_path, monkeypatch, capsys):
    import uuid

    tag = uuid.uuid4().hex[:8]
    site = tmp_path / "site"
    site.mkdir()
    (site / f"lfbench_cmd_{tag}.py").write_text(COMMAND_MODULE, encoding="utf-8")
    (site / f"lfbench_cmd_{tag}_empty.py").write_text("HELP = 'no run'\n", encoding="utf-8")
    write_dist_info(site, f"lfbench-cmd-{tag}",
                    "[lfbench.commands]\n"
                    f"echo-{tag} = lfbench_cmd_{tag}\n"
                    f"evaluate = lfbench_cmd_{tag}\n"  # may not replace a built-in command
                    f"empty-{tag} = lfbench_cmd_{tag}_empty\n"  # no add_arguments / run
                    f"broken-{tag} = lfbench_cmd_{tag}_missing\n")
    monkeypatch.syspath_prepend(str(site))
    import sys

    try:
        # `lfbench --help` lists a plugin command with its HELP, read from the source: nothing is imported
        with pytest.raises(SystemExit) as exited:
            main(["--help"])
        out, err = capsys.readouterr()
        assert exited.value.code == 0 and f"echo-{tag}" in out and "echo WORD times N" in out
        assert f"lfbench_cmd_{tag}" not in sys.modules and f"lfbench_cmd_{tag}_empty" not in sys.modules
        assert f"plugin command 'broken-{tag}'" in err and "its HELP could not be read" in err
        # running one imports that command only
        assert main([f"echo-{tag}", "hi", "--times", "2"]) == 3
        out, err = capsys.readouterr()
        assert out == "hi hi\n" and f"lfbench_cmd_{tag}" in sys.modules
        assert f"lfbench_cmd_{tag}_empty" not in sys.modules
        assert "plugin command 'evaluate'" in err and "would replace a built-in command" in err
        assert main([f"empty-{tag}"]) == 2
        err = capsys.readouterr().err
        assert f"plugin command 'empty-{tag}' failed to load (TypeError" in err and "add_arguments, run" in err
        assert main([f"broken-{tag}"]) == 2
        assert f"plugin command 'broken-{tag}' failed to load (ModuleNotFoundError" in capsys.readouterr().err
        assert "lfbench.cli.evaluate" in main.__globals__["BUILTIN_COMMANDS"].values()  # the built-in stays
    finally:
        for name in (f"lfbench_cmd_{tag}", f"lfbench_cmd_{tag}_empty"):
            sys.modules.pop(name, None)


def test_convert_keras_is_a_plugin_command():
    from importlib import metadata

    eps = {ep.name: ep.value for ep in metadata.entry_points(group="lfbench.commands")}
    assert eps.get("convert-keras") == "lfbench_methods.convert_keras"
    assert "convert-keras" not in main.__globals__["BUILTIN_COMMANDS"]


def test_a_stop_on_sigint_is_reported_as_a_stop_not_an_error(tmp_path, monkeypatch, capsys):
    """Issue 22.10: a resumable stop (SIGINT/SIGTERM during lfbench train) exits 130 with one line that
    says it stopped and how to resume, not 'error:'."""
    import types

    import lfbench.training.config as config
    import lfbench.training.loop as loop
    from lfbench.training.signals import TrainingInterrupted

    def stop(cfg, out, **kwargs):
        raise TrainingInterrupted(f"stopped at stage 1 step 3; checkpoint written to {out}/checkpoint.pt; "
                                  "run the same command to resume")

    monkeypatch.setattr(config.TrainConfig, "from_toml", staticmethod(lambda path: types.SimpleNamespace(out=None)))
    monkeypatch.setattr(loop, "train", stop)
    rc, _, err = run_cli(capsys, "train", tmp_path / "c.toml", "--out", tmp_path / "run")
    assert rc == 130 and err.strip().splitlines() == [
        f"lfbench train: stopped at stage 1 step 3; checkpoint written to {tmp_path / 'run'}/checkpoint.pt; "
        "run the same command to resume"]
    assert "error" not in err
