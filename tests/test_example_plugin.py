"""The example plugin (examples/tiny_plugin: one class, @register_trainable only) installed the way a
user installs it, then listed, trained, evaluated, ablated and timed with lfbench's own commands (each in
a fresh process, as on the command line): the trainable-network seam end to end, without lfbench knowing
the plugin. The two-class style (a Method of its own beside the Trainable): test_network_method."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import torch
from helpers import example_copy, isolate_registries, run_cli

from lfbench.data.hci import HCIDataset

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def plugin(example_plugin, tmp_path_factory):
    """(example folder copy, environment whose PYTHONPATH holds the installed plugin, site folder)."""
    site, env = example_plugin
    src = example_copy(tmp_path_factory.mktemp("tiny_plugin") / "src")
    sys.path.insert(0, str(site))
    yield src, env, site
    sys.path.remove(str(site))
    for name in [m for m in sys.modules if m == "lfbench_tiny" or m.startswith("lfbench_tiny.")]:
        del sys.modules[name]


def lfbench(env: dict, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "lfbench", *map(str, args)], env=env, capture_output=True,
                          text=True, timeout=600)


def _ok(proc: subprocess.CompletedProcess) -> str:
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout


@pytest.fixture(scope="module")
def trained(plugin, tmp_path_factory):
    src, env, _ = plugin
    out = tmp_path_factory.mktemp("tiny_run") / "run"
    _ok(lfbench(env, "train", src / "train_tiny.toml", "--out", out, "--no-progress"))
    return out


def _tiny_net(config: dict):
    """TinyNet of the installed plugin (on sys.path through the fixture), imported with isolated registries
    so that this process's method and trainable registries stay as they were."""
    from helpers import isolate_registries

    with pytest.MonkeyPatch.context() as mp:
        isolate_registries(mp)
        from lfbench_tiny.plugin import TinyNet
    return TinyNet(**config)


def _in_this_process(monkeypatch) -> None:
    """Let ``run_cli`` find the installed plugin in this process (its site is on sys.path through the fixture):
    isolated registries that load its entry point afresh (its module imported again, so that it registers)."""
    for name in [m for m in sys.modules if m.split(".")[0] == "lfbench_tiny"]:
        monkeypatch.delitem(sys.modules, name)
    isolate_registries(monkeypatch)


def test_the_plugin_is_listed_with_its_parameters(plugin):
    _, env, _ = plugin
    out = _ok(lfbench(env, "methods"))
    assert "tinycnn: A tiny CNN over the stacked views (lfbench's example plugin)." in out
    assert "weights (path, default None): weights file of this network" in out
    # the network's own parameters, with their help (issue 22.2)
    assert "channels (int [1, 1024], default 8): channels of the hidden 3x3 convolutions" in out
    assert "interval (float [0.01, 8], default 1.0): step of the candidate disparities in px" in out
    info = _ok(lfbench(env, "info", "tinycnn"))
    assert info.count("channels of the hidden 3x3 convolutions") == 1  # each help line once
    assert "no weights: give tinycnn:weights=FILE.pt" in info


def test_lfbench_train_trains_the_plugin_network(plugin, trained):
    log = [json.loads(line) for line in (trained / "metrics.jsonl").read_text().splitlines()]
    stage1 = [e["loss"] for e in log if e["event"] == "train" and e["stage"] == 1]
    assert len(stage1) == 6  # 150 steps, one entry per 25
    assert stage1[-1] < 0.85 * stage1[0], stage1  # the L1 loss (px) falls by more than 15 %
    assert [e["stage_name"] for e in log if e["event"] == "train"][-1] == "uafl"  # a distribution loss ran too
    final = torch.load(trained / "final.pt", map_location="cpu", weights_only=True)
    assert final["method"] == "tinycnn"
    assert final["config"] == {"channels": 8, "layers": 2, "d_min": -4.0, "d_max": 4.0, "interval": 1.0,
                               "angular": 9}
    assert final["training"]["steps"] == 160 and final["training"]["config"]["method"] == "tinycnn"
    # the same command again: the run is complete, nothing is trained or rewritten
    src, env, _ = plugin
    before = (trained / "final.pt").read_bytes()
    again = lfbench(env, "train", src / "train_tiny.toml", "--out", trained, "--no-progress")
    assert again.returncode == 0 and "training already complete (160 steps)" in again.stdout + again.stderr
    assert (trained / "final.pt").read_bytes() == before


def test_evaluate_runs_the_trained_weights(plugin, trained, tmp_path):
    src, env, _ = plugin
    data = tmp_path / "data"
    _ok(lfbench(env, "synth", "--out", data, "--seed", "100", "--size", "64", "--scenes", "1", "--no-progress"))
    spec = f"tinycnn:weights={trained / 'final.pt'}"
    _ok(lfbench(env, "evaluate", "--data", data, "--method", spec, "--out", tmp_path / "eval"))
    saved = json.loads((tmp_path / "eval" / "results.json").read_text())
    label = f"tinycnn:weights=sha256:{hashlib.sha256((trained / 'final.pt').read_bytes()).hexdigest()[:12]}"
    assert saved["meta"]["methods"][label]["weights"]["path"] == str(trained / "final.pt")  # provenance
    mse = {r["scene"]: r["value"] for r in saved["records"] if r["method"] == label and r["metric"] == "mse_x100"}
    scene = HCIDataset.open(data).scenes[0]
    assert set(mse) == {scene.name}

    # Independent reference: the network rebuilt from final.pt by hand, scored inside the 15 px border.
    state = torch.load(trained / "final.pt", map_location="cpu", weights_only=True)
    net = _tiny_net(state["config"])
    net.load_state_dict(state["state_dict"])
    views = torch.from_numpy(scene.gray_views().reshape(1, 81, 64, 64).astype(np.float32))
    gt = scene.gt_disparity()[15:-15, 15:-15]
    with torch.no_grad():
        trained_pred = net.eval()(views)[0][0].numpy()[15:-15, 15:-15]
        torch.manual_seed(7)  # the config's seed: the weights training started from
        untrained_pred = _tiny_net(state["config"]).eval()(views)[0][0].numpy()[15:-15, 15:-15]
    reference = 100 * float(np.mean(np.square(gt - trained_pred, dtype=np.float32)))
    assert mse[scene.name] == pytest.approx(reference, rel=1e-4)
    assert np.abs(trained_pred - untrained_pred).max() > 0.05  # the trained weights are the ones used
    assert reference < 100 * float(np.mean(np.square(gt - untrained_pred)))  # and they predict better


def test_golden_records_of_a_relative_and_an_absolute_weights_path_compare_equal(plugin, trained, tmp_path, capsys,
                                                                                 monkeypatch, one_torch_thread):
    """Issue 22.5: the same weights named relative to the working folder and by an absolute path (as in CI
    and on a laptop) give records with the same keys: regress passes instead of 'MISSING' and 'NEW'. (In this
    process: the fresh processes of the other tests show the installed plugin found from the command line.)"""
    _in_this_process(monkeypatch)
    monkeypatch.chdir(tmp_path)
    data = tmp_path / "data"

    def ok(*args) -> str:
        rc, out, err = run_cli(capsys, *args)
        assert rc == 0, (args, err[-2000:])
        return out

    ok("synth", "--out", data, "--seed", "101", "--size", "48", "--scenes", "1", "--no-progress")
    shutil.copy(trained / "final.pt", tmp_path / "weights.pt")
    ok("evaluate", "--data", "data", "--method", "tinycnn:weights=weights.pt", "--out", "rel")
    ok("evaluate", "--data", data, "--method", f"tinycnn:weights={tmp_path / 'weights.pt'}", "--out", tmp_path / "abs")
    ok("regress", tmp_path / "golden.json", tmp_path / "rel" / "results.json", "--update")
    out = ok("regress", tmp_path / "golden.json", tmp_path / "abs" / "results.json", "--fail-on-new")
    assert "OK: 5 compared, 0 regressions" in out and "MISSING" not in out and "NEW" not in out
    # a user-given label names them too
    ok("evaluate", "--data", data, "--method", f"tinycnn:weights={tmp_path / 'weights.pt'}", "--label", "tiny-v1",
       "--out", tmp_path / "named")
    methods = {r["method"] for r in json.loads((tmp_path / "named" / "results.json").read_text())["records"]}
    assert methods == {"tiny-v1"}


def test_foreign_weights_and_bad_parameters_are_one_line(plugin, trained, tmp_path, capsys, monkeypatch):
    """In this process (bad input stops before any work; the fresh processes of the other tests show the
    installed plugin found from the command line)."""
    _in_this_process(monkeypatch)
    data = tmp_path / "data"
    rc, _, err = run_cli(capsys, "synth", "--out", data, "--seed", "102", "--size", "48", "--scenes", "1",
                         "--no-progress")
    assert rc == 0, err
    shipped = ROOT / "methods" / "weights" / "subfocal_small.pt"
    (tmp_path / "w.json").write_text('{"state_dict": {}}')
    for spec, message in ((f"tinycnn:weights={shipped}", "a subfocal checkpoint, not tinycnn (run it as subfocal:"),
                          (f"tinycnn:weights={tmp_path / 'w.json'}", "w.json: a JSON file, not a torch checkpoint"),
                          (f"tinycnn:weights={trained / 'checkpoint.pt'}", "a training checkpoint"),
                          (f"tinycnn:weights={trained / 'final.pt'},channels=4",
                           "channels=4 (checkpoint: 8) conflicts with the weights"),
                          (f"tinycnn:weights={trained / 'final.pt'},channels=0",
                           "tinycnn:channels: must be in [1, 1024]"),
                          (f"subfocal:weights={trained / 'final.pt'}", "a tinycnn checkpoint, not subfocal")):
        rc, _, err = run_cli(capsys, "evaluate", "--data", data, "--method", spec, "--out", tmp_path / "never")
        assert rc == 2 and len(err.strip().splitlines()) == 1, err
        assert message in err and "weights_only" not in err, err
        assert not (tmp_path / "never").exists()


def test_ablate_over_a_plugin_parameter(plugin, tmp_path):
    src, env, _ = plugin
    out = tmp_path / "ablate"
    _ok(lfbench(env, "ablate", src / "ablate_channels.toml", "--out", out, "--no-progress"))
    cells = pd.read_csv(out / "table_cells.csv").set_index("cell")
    assert list(cells.index) == ["channels=4", "channels=8"] and list(cells["channels"]) == [4, 8]
    budget = "ours (batch 4, patch 16, 20+5 steps, cpu)"  # no width: the network has none
    badpix, mse = f"BadPix 0.07 (%), {budget}", f"MSE x100, {budget}"
    for channels in (4, 8):
        cell = out / "cells" / f"channels={channels}"
        final = torch.load(cell / "final.pt", map_location="cpu", weights_only=True)
        assert final["method"] == "tinycnn" and final["config"]["channels"] == channels
        assert final["state_dict"]["body.0.weight"].shape == (channels, 81, 3, 3)
        marker = json.loads((cell / "cell.json").read_text())
        assert marker["values"] == {"channels": channels} and marker["steps"] == 25  # the budget's 20 + 5
        assert 0 <= cells.loc[f"channels={channels}", badpix] <= 100
        assert json.loads((cell / "timing.json").read_text())["test_s"] > 0
    # the cells differ, so each was trained with its own parameter
    assert cells.loc["channels=4", mse] != cells.loc["channels=8", mse]
    bad = src / "bad_axis.toml"
    bad.write_text((src / "ablate_channels.toml").read_text().replace("channels = [4, 8]", "width = [4, 8]"))
    proc = lfbench(env, "ablate", bad, "--out", tmp_path / "bad", "--list")
    assert proc.returncode == 2 and "grid[0].width: unknown axis; use channels, layers, d_min, d_max, interval, " \
                                   "angular, loss, beta, lr, seed" in proc.stderr


def test_bench_times_the_plugin_network(plugin, tmp_path, capsys, monkeypatch):
    _, env, _ = plugin
    _ok(lfbench(env, "bench", "inference", "--model", "tinycnn", "--size", "16", "--precision", "fp32",
                "--threads", "1", "--json", tmp_path / "inference.json"))
    (rec,) = json.loads((tmp_path / "inference.json").read_text())
    assert rec["model"] == "tinycnn" and rec["channels"] == 8 and rec["disparities"] == 9 and rec["size"] == 16
    # TinyCNN.flops: 2 x (81*8 + 8*8 + 8*9) x 9 multiply-adds per pixel
    assert rec["tflop"] * 1e12 == pytest.approx(2 * 9 * (81 * 8 + 8 * 8 + 8 * 9) * 16 * 16)
    assert rec["gflops_per_s"] == pytest.approx(rec["tflop"] * 1e3 / rec["seconds"])
    _ok(lfbench(env, "bench", "train", "--model", "tinycnn:channels=4", "--batch", "1", "--patch", "16",
                "--steps", "1", "--threads", "1", "--json", tmp_path / "train.json"))
    (rec,) = json.loads((tmp_path / "train.json").read_text())
    assert rec["model"] == "tinycnn" and rec["channels"] == 4 and rec["steps_per_s"] > 0
    out = _ok(lfbench(env, "bench", "train", "--model", "tinycnn", "--channels", "2", "4", "--batch", "1",
                      "--patch", "16", "--steps", "1", "--threads", "1"))  # its own parameter as a flag
    lines = [line for line in out.splitlines() if line.startswith("[train]")]
    assert len(lines) == 2 and "channels 2" in lines[0] and "channels 4" in lines[1]
    assert "path" not in out and "weight_grad" not in out  # SubFocal's training options are SubFocal's
    # refused in one line before any case process starts (issue 22.9): in this process, where the plugin is
    # installed too, so that no case process could have started unseen
    _in_this_process(monkeypatch)
    shipped = ROOT / "methods" / "weights" / "subfocal_small.pt"
    for args, message in ((["inference", "--model", "tinycnn", "--width", "3"], "unrecognized arguments: --width"),
                          (["inference", "--model", "tinycnn:channels=0"], "channels: must be in [1, 1024], got 0"),
                          (["inference", "--model", "tinycnn", "--channels", "0"], "--channels: must be in [1, 1024]"),
                          (["inference", "--model", "tinycnn", "--weights", str(shipped)],
                           "a subfocal checkpoint, not tinycnn"),
                          (["train", "--model", "tinycnn", "--path", "reference"], "unrecognized arguments: --path")):
        extra = ("--size", "16", "--threads", "1") if args[0] == "inference" else ()
        with monkeypatch.context() as mp:
            mp.setattr(subprocess, "Popen", _no_case_process)
            rc, stdout, stderr = run_cli(capsys, "bench", *args, *extra)
        assert rc == 2 and message in stderr, (args, stderr)
        assert len(stderr.strip().splitlines()) == 1 and "cases, each in a fresh process" not in stdout
    rc, help_text, _ = run_cli(capsys, "bench", "--help")
    assert rc == 0 and "\n  lfbench bench train --width 150 16 --batch 2\n" in help_text  # the examples stay lines


def _no_case_process(*args, **kwargs):
    raise AssertionError(f"a process was started: {args}")


def test_ddp_trains_the_plugin_network_in_two_processes(plugin, tmp_path):
    """torchrun with 2 CPU processes (gloo): both ranks end with the same parameters, the exported ones."""
    src, env, _ = plugin
    text = (src / "train_tiny.toml").read_text().replace("batch_size = 4", "batch_size = 2")
    text = text.replace("steps = 150", "steps = 3").replace("steps = 10", "steps = 2")
    config = tmp_path / "ddp.toml"
    config.write_text(text)
    out = tmp_path / "ddp"
    proc = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", "2",
                           "-m", "lfbench", "train", str(config), "--out", str(out), "--no-progress"],
                          env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    final = torch.load(out / "final.pt", map_location="cpu", weights_only=True)
    from lfbench.training.checkpoint import state_sha256

    names = [n for n, _ in _tiny_net(final["config"]).named_parameters()]
    digests = final["training"]["rank_parameters_sha256"]
    assert final["training"]["world_size"] == 2 and final["training"]["steps"] == 5
    assert len(digests) == 2 and digests[0] == digests[1] == state_sha256({n: final["state_dict"][n] for n in names})
